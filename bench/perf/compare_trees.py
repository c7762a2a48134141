"""Speed of two checkouts side by side: solver_speed.py and node_latency.py, alternating.

A behaviour-preserving change (a refactor) must not cost speed. This runs both benchmarks on a
BEFORE and an AFTER checkout of the repository, alternating which goes first each round so that a
change of machine load hits both sides alike, and reports each figure's median over the rounds and
the ratio after / before (1.00: unchanged; the noise on a shared 2-core machine is about ±20 %).
Each checkout runs with its own venv (``scripts/dlo-env``), with the benchmarks' default arguments.

    python bench/perf/compare_trees.py BEFORE_DIR AFTER_DIR [--rounds 3] [--out FILE.md]

e.g. ``git worktree add /tmp/before <rev>`` for BEFORE_DIR and the current checkout for AFTER_DIR.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import time
from pathlib import Path


def run(tree: Path, script: str, out: Path) -> str:
    """Run ``bench/perf/<script>`` in ``tree`` with its venv; return the report it wrote."""
    subprocess.run(
        ["bash", "scripts/dlo-env", "run", "python", f"bench/perf/{script}", "--out", str(out)],
        cwd=tree,
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        timeout=1800,
    )
    return out.read_text(encoding="utf-8")


def cells(text: str, row_start: str) -> list[str]:
    """Return the cells of the first markdown table row starting with ``row_start``."""
    for line in text.splitlines():
        if line.startswith("| " + row_start):
            return [c.strip() for c in line.strip().strip("|").split("|")]
    raise KeyError(row_start)


def speed_figures(text: str) -> dict[str, float]:
    """Return solver_speed.py's cold and warm times [ms], interpreted and compiled (cached)."""
    out = {}
    for label, row in (("compile off", "off"), ("compiled", "compiled (later start, cached)")):
        c = cells(text, row)
        out[f"solver_speed, {label}: cold ms"] = float(c[3])
        out[f"solver_speed, {label}: warm median ms"] = float(c[4])
        out[f"solver_speed, {label}: warm p90 ms"] = float(c[5])
    return out


def latency_figures(text: str) -> dict[str, float]:
    """Return node_latency.py's closed- and open-loop latencies [ms] and its in-process solve."""
    out = {}
    for mode in ("off", "blocking"):
        section = text.split(f"## `compile:={mode}`", 1)[1].split("\n## ", 1)[0]
        closed = cells(section, "closed loop (300 targets")
        out[f"node_latency, compile:={mode}: closed-loop p50 ms"] = float(closed[1])
        out[f"node_latency, compile:={mode}: closed-loop p99 ms"] = float(closed[2])
        out[f"node_latency, compile:={mode}: open-loop p50 ms"] = float(
            cells(section, "open loop at 100 Hz")[1]
        )
        out[f"node_latency, compile:={mode}: in-process solve p50 ms"] = float(
            cells(section, "in-process")[1]
        )
    return out


def git_rev(tree: Path) -> str:
    """Return the short hash of ``tree``'s HEAD."""
    return subprocess.check_output(
        ["git", "rev-parse", "--short", "HEAD"], cwd=tree, text=True
    ).strip()


def main() -> None:
    """Run the rounds and write the report."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path("bench/results/compare_trees.md"))
    args = ap.parse_args()
    sides = {"before": args.before.resolve(), "after": args.after.resolve()}
    rows: dict[str, list[dict[str, float]]] = {"before": [], "after": []}
    scratch = Path(os.environ.get("TMPDIR", "/tmp"))
    for r in range(args.rounds):
        order = ("before", "after") if r % 2 == 0 else ("after", "before")
        for side in order:
            tree = sides[side]
            figures = speed_figures(run(tree, "solver_speed.py", scratch / f"ct_speed_{side}.md"))
            figures |= latency_figures(run(tree, "node_latency.py", scratch / f"ct_lat_{side}.md"))
            rows[side].append(figures)
            print(f"round {r + 1}/{args.rounds}: {side} done", flush=True)
    lines = [
        "# Speed of two checkouts side by side",
        "",
        f"Measured {time.strftime('%Y-%m-%d %H:%M')} on {platform.machine()}, "
        f"{os.cpu_count()} cores (shared), Python {platform.python_version()}; "
        f"before = git {git_rev(sides['before'])}, after = git {git_rev(sides['after'])}. "
        f"{args.rounds} rounds alternating which side runs first; each cell is the median of the "
        "rounds of that figure of `bench/perf/solver_speed.py` and `bench/perf/node_latency.py` "
        "(default arguments). after / before = 1.00: unchanged; the noise here is about ±20 %.",
        "",
        "| figure | before | after | after / before |",
        "|---|---:|---:|---:|",
    ]
    for key in rows["before"][0]:
        b = statistics.median(x[key] for x in rows["before"])
        a = statistics.median(x[key] for x in rows["after"])
        lines.append(f"| {key} | {b:.2f} | {a:.2f} | {a / b:.2f} |")
    lines += [
        "",
        f"Command: `python bench/perf/compare_trees.py BEFORE AFTER --rounds {args.rounds} "
        f"--out {args.out}`",
        "",
    ]
    args.out.write_text("\n".join(lines), encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
