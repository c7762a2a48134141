"""Issue #14's figures in one command: run every speed benchmark, then set each target beside its measurement.

    bash scripts/dlo-env run python bench/perf/speed_targets.py               # about 8 min: every step, the table
    bash scripts/dlo-env run python bench/perf/speed_targets.py --skip-suite  # the same, the rod comparison as it is
    bash scripts/dlo-env run python bench/perf/speed_targets.py --table-only  # the table from the files as they are

The steps run one after another, never two at once (they share the machine's cores), each as its own
process with the command line ``bench/README.md`` gives for its result file (``STEPS``):

* ``solver_speed.py`` for the 3D model and for the planar model ``auto`` streams in-plane (warm update
  median and p99, compiled beside interpreted);
* ``paced_updates.py`` (the same update back to back and after a pause, which a 100 Hz stream pays);
* ``queries.py`` (queries per second: one solver, ``query_many`` on 1 and 2 worker processes);
* ``compile_cost.py`` (compile time per structure, start-up to full speed);
* ``node_latency.py`` for the 3D and the planar path (target → centreline across processes);
* ``soak.py`` without and with three query clients (the stream's p99 and the queries' latency);
* ``suite/run_all.py --methods default,default-planar,rod --only pareto`` (the default against the
  discretised rod at 1e-3 L and 1e-5 L, cold and warm; merged into ``raw.json``).  ``--skip-suite``
  reads ``raw.json`` as it is, e.g. after a full ``run_all.py``.

Then ``speed_targets.md``: one row per target of the issue with the measured value, whether it is met,
and the file (and git revision) it comes from.  The figures are read back from those files' own tables,
so the table says nothing the result files do not; a figure whose file this run did not write (its step
failed) is marked "not re-measured" and not met.  The warm update is given back to back (``solver_speed``)
and after the longest pause of ``paced_updates``, which is what a stream at a fixed rate pays here.  Times are wall-clock on a shared machine: the
ratios inside each file are what compares.
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # the repository
sys.path.insert(0, str(ROOT))  # run as a script: make `bench` importable

from bench.common import RESULTS, machine, write_report  # noqa: E402

#: the planar cases of the suite and its twisted 3D case (``bench.common`` cases); the default runs its
#: planar model on the planar ones, as ``solver.model: auto`` does
PLANAR_CASES = ("elastica_0.9", "elastica_0.8", "elastica_0.7", "elastica_0.6", "elastica_0.5", "elastica_0.4",
                "elastica_0.3", "asymmetric", "heavy_table", "point_loads")
TOLERANCES = (1e-3, 1e-5)  # centreline error / L the issue compares the default and the rod at


@dataclass(frozen=True)
class Step:
    """One benchmark run: the script and its arguments (``{out}``: the result file), and that file."""

    script: str
    args: tuple[str, ...]
    out: str

    def argv(self, results: Path) -> list[str]:
        out = results / self.out
        out = out.relative_to(ROOT) if out.is_relative_to(ROOT) else out  # the steps run in ROOT
        return [a.replace("{out}", str(out)) for a in self.args]


STEPS = (
    Step("bench/perf/solver_speed.py", ("--out", "{out}"), "solver_speed.md"),
    Step("bench/perf/solver_speed.py", ("--model", "planar", "--order", "16", "--out", "{out}"), "solver_speed_planar.md"),
    Step("bench/perf/paced_updates.py", ("--out", "{out}"), "paced_updates.md"),
    Step("bench/perf/queries.py", ("--queries", "1000", "--compile", "cached", "--out", "{out}"), "queries_compiled.md"),
    Step("bench/perf/compile_cost.py", ("--models", "planar:8", "planar:12", "full:8", "full:16", "full:32",
                                        "--flattened-up-to", "12", "--out", "{out}"), "compile_cost.md"),
    Step("bench/perf/node_latency.py", ("--mode", "native", "--model", "auto", "--n", "300", "--rate", "100",
                                        "--seconds", "5", "--out", "{out}"), "node_latency_auto.md"),
    Step("bench/perf/node_latency.py", ("--mode", "native", "--model", "auto", "--n", "300", "--rate", "100",
                                        "--seconds", "5", "--path", "planar", "--out", "{out}"),
         "node_latency_auto_planar.md"),
    Step("bench/perf/soak.py", ("--seconds", "90", "--param-every", "0", "--query-clients", "0", "--out", "{out}"),
         "soak_no_queries.md"),
    Step("bench/perf/soak.py", ("--seconds", "90", "--param-every", "0", "--query-clients", "3", "--query-rate", "5",
                                "--out", "{out}"), "soak_3_clients.md"),
)
SUITE = Step("bench/suite/run_all.py", ("--methods", "default,default-planar,rod", "--only", "pareto"), "raw.json")


# ---------------------------------------------------------------------------------------------------
# reading the result files back
def tables(text: str) -> list[list[dict[str, str]]]:
    """Every Markdown table in ``text`` as a list of rows, each a dict from header cell to cell."""
    found, header, rows = [], None, []
    for line in text.splitlines() + [""]:
        cells = [c.strip() for c in line.strip().strip("|").split("|")] if line.lstrip().startswith("|") else None
        if cells is None:
            if header is not None:
                found.append(rows)
            header, rows = None, []
        elif header is None:
            header = cells
        elif not all(set(c) <= set("-: ") for c in cells):
            rows.append(dict(zip(header, cells)))
    return found


def row(text: str, column: str, first: str) -> dict[str, str]:
    """The row of the first table with a ``column`` header whose first cell starts with ``first``."""
    for table in tables(text):
        for r in table:
            if column in r and next(iter(r.values())).startswith(first):
                return r
    raise LookupError(f"no table row starting {first!r} with a column {column!r}")


def number(cell: str) -> float:
    """The first number in a cell ('1.8', '991', '100.1 centrelines/s')."""
    m = re.search(r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?", cell)
    if m is None:
        raise ValueError(f"no number in {cell!r}")
    return float(m.group())


def git_of(text: str) -> str:
    m = re.search(r"\bgit ([0-9a-f]{7,40})", text)
    return m.group(1) if m else "?"


@dataclass(frozen=True)
class Figure:
    """One row of the table: what the issue measures, its target, what the result file says."""

    figure: str
    target: str
    measured: str
    met: bool
    source: str


def _read(results: Path, name: str) -> tuple[str, str]:
    text = (results / name).read_text()
    return text, f"{name} ({git_of(text)})"


def update_figures(results: Path) -> list[Figure]:
    out = []
    for name, label in (("solver_speed.md", "3D model"), ("solver_speed_planar.md", "planar model (auto, in-plane)")):
        text, src = _read(results, name)
        comp = row(text, "warm median ms", "compiled (later start")
        interp = row(text, "warm median ms", "off")
        med, p99 = number(comp["warm median ms"]), number(comp["warm p99 ms"])
        ratio = med / number(interp["warm median ms"])
        out.append(Figure(f"warm update median, `default_cable`, {label}", "≤ 0.3 ms",
                          f"{med:.2f} ms ({ratio:.2f}× interpreted)", med <= 0.3, src))
        out.append(Figure(f"warm update p99, {label}", "≤ 1 ms", f"{p99:.2f} ms", p99 <= 1.0, src))
    text, src = _read(results, "paced_updates.md")
    pause = max((c for c in tables(text)[0][0] if c.startswith("sleep ")), key=number)  # the longest pause
    for first, label in (("planar", "planar model"), ("3D", "3D model")):
        r = row(text, pause, first)
        out.append(Figure(f"warm update median after a {pause.removeprefix('sleep ')} pause (as a stream spaces "
                          f"them), {label}", "≤ 0.3 ms", f"{number(r[pause]):.2f} ms (back to back "
                          f"{number(r['sleep 0 ms']):.2f})", number(r[pause]) <= 0.3, src))
    return out


def fastest(rows: list[dict], method: str, mode: str, tol: float) -> float:
    """The fastest ``mode`` ('cold' / 'warm') time [s] of ``method``'s settings within ``tol`` L (inf: none)."""
    times = [r[f"{mode}_s"] for r in rows if r["method"] == method and r.get(f"{mode}_ok")
             and r.get(f"{mode}_err") is not None and np.isfinite(r[f"{mode}_err"]) and r[f"{mode}_err"] <= tol]
    return min(times, default=np.inf)


def rod_figures(results: Path) -> list[Figure]:
    """The default (its planar model on the planar cases, as ``auto`` streams them; the 3D model on the
    twisted case) against the discretised rod, per tolerance and mode: on how many of the cases that
    either reaches the default is faster, and the median of rod time / default time over the cases both reach."""
    raw = json.loads((results / "raw.json").read_text())
    runs = raw.get("method_runs", {})
    src = "raw.json (" + ", ".join(f"{m} {runs.get(m, raw['machine']).get('git', '?')}"
                                   for m in ("default", "default-planar", "rod")) + ")"
    out = []
    for tol in TOLERANCES:
        for mode in ("cold", "warm"):
            faster, cases, ratios = 0, 0, []
            for case in raw["pareto"]:
                ours = fastest(case["rows"], "default-planar" if case["case"] in PLANAR_CASES else "default", mode, tol)
                rod = fastest(case["rows"], "rod", mode, tol)
                if np.isinf(ours) and np.isinf(rod):
                    continue
                cases += 1
                faster += ours < rod
                if np.isfinite(ours) and np.isfinite(rod):
                    ratios.append(rod / ours)
            median = f", rod / default median {np.median(ratios):.2f}× over {len(ratios)} both reach" if ratios else ""
            out.append(Figure(f"default vs discretised rod + IPOPT, {mode}, {tol:g} L (both with interpreted "
                              f"derivatives, as the suite runs every method)", "faster",
                              f"faster on {faster} of {cases} cases{median}", cases > 0 and faster == cases, src))
    return out


def query_figures(results: Path) -> list[Figure]:
    text, src = _read(results, "queries_compiled.md")
    one = number(row(text, "queries/s", "one solver")["queries/s"])
    two = number(row(text, "queries/s", "query_many, 2 worker")["queries/s"])
    return [Figure("shape queries in-process, both cores (`query_many`, 2 workers)", "≥ 2000/s",
                   f"{two:.0f}/s ({two / one:.2f}× one solver)", two >= 2000, src)]


def node_figures(results: Path) -> list[Figure]:
    out = []
    for name, label in (("node_latency_auto.md", "3D path"), ("node_latency_auto_planar.md", "planar path")):
        text, src = _read(results, name)
        r = row(text, "p50 [ms]", "open loop at")
        closed = row(text, "p50 [ms]", "closed loop")
        p50, p99 = number(r["p50 [ms]"]), number(r["p99 [ms]"])
        out.append(Figure(f"node target → centreline, 100 Hz, {label}", "p50 ≤ 2 ms, p99 ≤ 5 ms",
                          f"p50 {p50:.1f} ms, p99 {p99:.1f} ms (closed loop {number(closed['p50 [ms]']):.1f} / "
                          f"{number(closed['p99 [ms]']):.1f})", p50 <= 2.0 and p99 <= 5.0, src))
    return out


def soak_figures(results: Path) -> list[Figure]:
    alone, src0 = _read(results, "soak_no_queries.md")
    busy, src3 = _read(results, "soak_3_clients.md")
    stream = re.compile(r"target → centreline p50 ([\d.]+) ms, p99 ([\d.]+) ms")
    query = re.compile(r"Queries:.*?latency p50 ([\d.]+) ms, p99 ([\d.]+) ms")
    p99_alone, p99_busy = float(stream.search(alone).group(2)), float(stream.search(busy).group(2))
    q50, q99 = (float(v) for v in query.search(busy).groups())
    return [Figure("three query clients beside the 100 Hz stream: stream p99", "≤ 1.2× the stream alone",
                   f"{p99_busy:.1f} ms against {p99_alone:.1f} ms alone ({p99_busy / p99_alone:.2f}×)",
                   p99_busy <= 1.2 * p99_alone, f"{src3}, {src0}"),
            Figure("the same: query latency", "p99 ≤ 20 ms", f"p50 {q50:.0f} ms, p99 {q99:.0f} ms", q99 <= 20.0, src3)]


def start_figures(results: Path) -> list[Figure]:
    text, src = _read(results, "compile_cost.md")
    table = next(t for t in tables(text) if t and "seconds" in t[0])
    secs = {r["model"]: number(r["seconds"]) for r in table}
    worst = max(secs, key=secs.get)
    not_ok = [f"{r['model']} {r['first solve']}" for r in table if r.get("first solve", "ok") != "ok"]
    return [Figure("first start of a new scene structure to full speed", "≤ 10 s",
                   f"{min(secs.values()):.1f}–{secs[worst]:.1f} s (slowest: {worst})"
                   + (f"; first solve not ok: {', '.join(not_ok)}" if not_ok else ""), secs[worst] <= 10.0, src)]


def figures(results: Path) -> list[Figure]:
    return (update_figures(results) + rod_figures(results) + query_figures(results) + node_figures(results)
            + soak_figures(results) + start_figures(results))


# ---------------------------------------------------------------------------------------------------
def stale(found: list[Figure], done: list[tuple[Step, float, int]], results: Path, since: float) -> list[Figure]:
    """``found`` with every figure whose file this run did not write (its step failed, or the file is older
    than the run) marked not met and 'not re-measured'."""
    old = {s.out: code for s, _, code in done if code != 0 or (results / s.out).stat().st_mtime < since}
    marked = []
    for f in found:
        code = next((c for name, c in old.items() if f.source.startswith(name) or f", {name}" in f.source), None)
        marked.append(f if code is None else
                      replace(f, measured=f"{f.measured} — not re-measured (step exited {code})", met=False))
    return marked


def run_steps(steps, results: Path) -> list[tuple[Step, float, int]]:
    done = []
    for step in steps:
        print(f"=== {step.script} {' '.join(step.argv(results))}", flush=True)
        t0 = time.perf_counter()
        code = subprocess.run([sys.executable, str(ROOT / step.script), *step.argv(results)], cwd=ROOT).returncode
        done.append((step, time.perf_counter() - t0, code))
        if code != 0:
            print(f"{step.script} exited {code}", file=sys.stderr)
    return done


def machine_pace(results: Path) -> str:
    """The machine's own pace in the run that wrote the result files, from two figures no target depends
    on: a DDS round trip through an echo node that does not solve (``node_latency_auto.md``'s floor) and
    an interpreted warm update (``solver_speed.md``).  Runs on different days compare by these."""
    try:
        echo = row(_read(results, "node_latency_auto.md")[0], "p50 [ms]", "closed loop (300 targets), Single")
        interp = row(_read(results, "solver_speed.md")[0], "warm median ms", "off")
    except (OSError, LookupError, ValueError):  # a file missing or of another layout: no line
        return ""
    return (f"The machine's pace in this run (no target depends on it): a DDS round trip through an echo node "
            f"that does not solve, closed loop, p50 {number(echo['p50 [ms]']):.2f} ms (node_latency_auto.md); an "
            f"interpreted warm update, median {number(interp['warm median ms']):.2f} ms (solver_speed.md).  Runs on "
            f"other days compare by these.")


def report(found: list[Figure], done: list[tuple[Step, float, int]], info: dict, pace: str = "") -> list[str]:
    load = ", ".join(f"{v:.2f}" for v in info.get("load_average", ()))
    lines = ["# Issue #14's targets beside their measurements", "",
             f"Machine: {info.get('cpu', '?')}, {info.get('cpus', '?')} cores (shared; load average {load} at the end), "
             f"Python {info.get('python', '?')}; git {info.get('git', '?')}; written {time.strftime('%Y-%m-%d %H:%M')}.", "",
             "Every figure is read from the result file named beside it (with the git revision that file records); "
             "`bench/README.md` says which command writes it.  Absolute times drift ±20 % on this shared machine; "
             "the ratios in each file come from one run." + (f"  {pace}" if pace else ""), "",
             "| figure | target | measured | met | from |", "|---|---|---|---|---|"]
    lines += [f"| {f.figure} | {f.target} | {f.measured} | {'yes' if f.met else 'no'} | {f.source} |" for f in found]
    if done:
        lines += ["", "Steps of this run:", "", "| step | minutes | exit |", "|---|---:|---:|"]
        lines += [f"| `{s.script} {' '.join(s.args).replace('{out}', f'bench/results/{s.out}')}` | {dt / 60:.1f} | {code} |"
                  for s, dt, code in done]
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--table-only", action="store_true", help="no benchmark: the table from the result files as they are")
    ap.add_argument("--skip-suite", action="store_true", help="read raw.json as it is (no run_all.py --methods)")
    ap.add_argument("--out", default=str(RESULTS / "speed_targets.md"), help="the table")
    args = ap.parse_args()
    results = RESULTS
    done, since = [], time.time()
    if not args.table_only:
        steps = STEPS if args.skip_suite else STEPS + (SUITE,)
        done = run_steps(steps, results)
    found = stale(figures(results), done, results, since)
    write_report(report(found, done, machine(), machine_pace(results)), args.out, "bench/perf/speed_targets.py",
                 sys.argv[1:])
    if any(code for _, _, code in done):
        sys.exit(1)


if __name__ == "__main__":
    main()
