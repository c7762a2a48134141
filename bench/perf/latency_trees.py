"""The node's latency on several checkouts in one window: node_latency.py on each, alternating.

For a change to the node's plumbing (issue #38: the target subscriptions on their own small node and
thread) the figure that matters is node_latency.py's, and on a shared 2-core machine it drifts by
tens of percent between windows.  This runs ``bench/perf/node_latency.py`` of each checkout in turn,
round after round (the order rotates each round, so a change of load hits every side alike), with
this interpreter and the checkout first on PYTHONPATH (no venv per checkout: the packages are the
same, only the code differs), and reports every run's figures, their medians and the ratios to the
first checkout.

    python bench/perf/latency_trees.py LABEL=DIR [LABEL=DIR ...] [--rounds 3] [--out FILE.md]
                                       [-- NODE_LATENCY_ARGS ...]

e.g. ``git worktree add /tmp/base <rev>`` for the first (the reference).  The node_latency
arguments default to ``--mode native --model auto --n 300 --rate 100 --seconds 5``.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import statistics
import subprocess
import sys
from pathlib import Path

DEFAULT_ARGS = ["--mode", "native", "--model", "auto", "--n", "300", "--rate", "100",
                "--seconds", "5"]
#: (figure, section heading prefix, row prefix, cell index): what each run contributes
FIGURES = (
    ("closed loop p50 [ms]", "## `compile:=", "closed loop (", 1),
    ("closed loop p99 [ms]", "## `compile:=", "closed loop (", 2),
    ("open loop p50 [ms]", "## `compile:=", "open loop at ", 1),
    ("open loop p99 [ms]", "## `compile:=", "open loop at ", 2),
    ("in-process solve p50 [ms]", "## `compile:=", "in-process", 1),
    ("echo floor closed loop p50 [ms]", "## The floor", "closed loop (", 1),
)


def cells(text: str, heading: str, row_start: str) -> list[str]:
    """Return the cells of the first table row starting with ``row_start`` under ``heading``."""
    section = text.split(heading, 1)[1]
    for line in section.splitlines():
        if line.startswith("| " + row_start):
            return [c.strip() for c in line.strip().strip("|").split("|")]
    raise KeyError(f"{heading} / {row_start}")


def rate(text: str, row_start: str) -> float:
    """Return the leading number of the last cell of the node's row starting with ``row_start``."""
    return float(cells(text, "## `compile:=", row_start)[-1].split()[0])


def figures(text: str) -> dict[str, float]:
    """Return one run's figures (FIGURES, and the flood's centrelines/s)."""
    out = {name: float(cells(text, h, row)[i]) for name, h, row, i in FIGURES}
    out["flood centrelines/s"] = rate(text, "flood")
    return out


def run(label: str, tree: Path, extra: list[str], out: Path) -> dict[str, float]:
    """Run ``tree``'s node_latency.py with ``extra``; return its figures."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        p for p in (str(tree), os.environ.get("PYTHONPATH", "")) if p))
    log = out.with_suffix(".log")
    with open(log, "wb") as f:
        done = subprocess.run([sys.executable, str(tree / "bench/perf/node_latency.py"), *extra,
                               "--out", str(out)], cwd=tree, env=env, stdout=f,
                              stderr=subprocess.STDOUT, timeout=1800)
    if done.returncode != 0:
        tail = log.read_text(errors="replace").splitlines()[-15:]
        raise RuntimeError(f"{label}: node_latency.py failed ({done.returncode}):\n" + "\n".join(tail))
    return figures(out.read_text(encoding="utf-8"))


def git_rev(tree: Path) -> str:
    """Return the short hash of ``tree``'s HEAD, with '+' when its work tree has changes."""
    rev = subprocess.check_output(["git", "rev-parse", "--short", "HEAD"], cwd=tree, text=True)
    dirty = subprocess.run(["git", "diff", "--quiet", "HEAD"], cwd=tree).returncode != 0
    return rev.strip() + ("+" if dirty else "")


def main() -> int:
    """Run the rounds and write the report."""
    argv = sys.argv[1:]
    extra = DEFAULT_ARGS
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1:]
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("trees", nargs="+", help="LABEL=DIR; the first is the reference of the ratios")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path("bench/results/latency_trees.md"))
    args = ap.parse_args(argv)
    trees = {label: Path(d).resolve() for label, d in (t.split("=", 1) for t in args.trees)}
    labels = list(trees)
    runs: dict[str, list[dict[str, float]]] = {label: [] for label in labels}
    loads: dict[str, list[float]] = {label: [] for label in labels}
    scratch = Path(os.environ.get("TMPDIR", "/tmp"))
    started = datetime.datetime.now()
    for r in range(args.rounds):
        order = labels[r % len(labels):] + labels[:r % len(labels)]
        for label in order:
            loads[label].append(os.getloadavg()[0])
            runs[label].append(run(label, trees[label], extra, scratch / f"lt_{label}_{r}.md"))
            print(f"round {r + 1}/{args.rounds}: {label} {runs[label][-1]}", flush=True)
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo")
                if line.startswith("model name")), "?")
    ref = labels[0]
    lines = [
        "# The node's latency on several checkouts, alternating",
        "",
        f"Measured {started:%Y-%m-%d %H:%M}–{datetime.datetime.now():%H:%M}: {cpu}, "
        f"{os.cpu_count()} CPUs shared with other work, Python {platform.python_version()}, "
        "ROS 2 Jazzy PyPI wheels, Fast DDS, discovery on localhost. "
        + "; ".join(f"{label} = {trees[label]} at git {git_rev(trees[label])}" for label in labels)
        + ".",
        "",
        f"Command: `python bench/perf/latency_trees.py "
        + " ".join(f"{label}=DIR" for label in labels)
        + f" --rounds {args.rounds} -- {' '.join(extra)}` (each run: `bench/perf/node_latency.py "
        f"{' '.join(extra)}` of that checkout; {args.rounds} rounds, the order rotating).",
        "",
        "Medians over the rounds, and the ratio to " + f"`{ref}` (below 1: lower, i.e. faster):",
        "",
        "| figure | " + " | ".join(labels) + " | "
        + " | ".join(f"{label} / {ref}" for label in labels[1:]) + " |",
        "| --- | " + " | ".join("---:" for _ in labels + labels[1:]) + " |",
    ]
    for key in runs[ref][0]:
        med = {label: statistics.median(x[key] for x in runs[label]) for label in labels}
        lines.append(f"| {key} | " + " | ".join(f"{med[label]:.2f}" for label in labels) + " | "
                     + " | ".join(f"{med[label] / med[ref]:.2f}" for label in labels[1:]) + " |")
    lines += ["", "Every run (round: figures; load average at its start):", ""]
    keys = list(runs[ref][0])
    lines += ["| checkout | round | load | " + " | ".join(keys) + " |",
              "| --- | ---: | ---: | " + " | ".join("---:" for _ in keys) + " |"]
    for label in labels:
        for r, x in enumerate(runs[label]):
            lines.append(f"| {label} | {r + 1} | {loads[label][r]:.1f} | "
                         + " | ".join(f"{x[k]:.2f}" for k in keys) + " |")
    lines.append("")
    args.out.write_text("\n".join(lines), encoding="utf-8")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
