"""bench/perf/speed_targets.py reads issue #14's figures back from the result files: its table reader, its
"met" verdicts, and that every committed result file still has the rows it reads.  No timing is asserted."""
from __future__ import annotations

import json
import shutil
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import RESULTS  # noqa: E402
from bench.perf import speed_targets as st  # noqa: E402

FILES = ("solver_speed.md", "solver_speed_planar.md", "paced_updates.md", "queries_compiled.md", "compile_cost.md",
         "node_latency_auto.md", "node_latency_auto_planar.md", "soak_no_queries.md", "soak_3_clients.md", "raw.json")


def test_tables_reads_each_markdown_table_apart():
    text = "\n".join(["# t", "", "| a | b |", "|---|---:|", "| x 1 | 2.5 |", "| y | 3 |", "text between",
                      "| c | d |", "| --- | --- |", "| z | 4 |"])
    found = st.tables(text)
    assert found == [[{"a": "x 1", "b": "2.5"}, {"a": "y", "b": "3"}], [{"c": "z", "d": "4"}]]
    assert st.row(text, "b", "y") == {"a": "y", "b": "3"}
    assert st.number("100.1 centrelines/s") == 100.1 and st.number("1.2e-3 m") == 1.2e-3
    with pytest.raises(LookupError):
        st.row(text, "b", "z")  # z is in the table without a b column


def test_every_committed_result_file_has_the_rows_the_table_reads():
    found = st.figures(RESULTS)
    assert len(found) == 6 + 2 * len(st.TOLERANCES) + 1 + 2 + 2 + 1
    for f in found:
        assert any(ch.isdigit() for ch in f.measured), f
        assert "?" not in f.source, f  # every file records its git revision


def _copy(tmp_path: Path) -> Path:
    for name in FILES:
        shutil.copy(RESULTS / name, tmp_path / name)
    return tmp_path


def _verdict(results: Path, start: str) -> bool:
    return next(f.met for f in st.figures(results) if f.figure.startswith(start))


def test_verdicts_follow_the_numbers(tmp_path):
    results = _copy(tmp_path)
    # queries: the 2-worker rate decides
    text = (results / "queries_compiled.md").read_text()
    rate = st.row(text, "queries/s", "query_many, 2 worker")["queries/s"]
    for value, met in (("2500", True), ("1999", False)):
        (results / "queries_compiled.md").write_text(text.replace(f"| {rate} |", f"| {value} |", 1))
        assert _verdict(results, "shape queries") is met
    # the stream beside query clients: p99 against 1.2 x the stream alone
    alone = (results / "soak_no_queries.md").read_text()
    busy = (results / "soak_3_clients.md").read_text()
    p99 = float(st.re.search(r"target → centreline p50 [\d.]+ ms, p99 ([\d.]+) ms", alone).group(1))
    for factor, met in ((1.19, True), (1.21, False)):
        (results / "soak_3_clients.md").write_text(st.re.sub(
            r"(target → centreline p50 [\d.]+ ms, p99 )[\d.]+( ms)", rf"\g<1>{p99 * factor:.4f}\g<2>", busy))
        assert _verdict(results, "three query clients") is met


def test_rod_comparison_counts_cases_either_method_reaches(tmp_path):
    results = _copy(tmp_path)

    def rows(case, ours, rod):
        method = "default-planar" if case in st.PLANAR_CASES else "default"
        return [{"method": m, "warm_ok": t is not None, "warm_s": t, "warm_err": 1e-4 if t else None,
                 "cold_ok": False, "cold_s": None, "cold_err": None} for m, t in ((method, ours), ("rod", rod))]

    cases = [("elastica_0.9", 1.0, 2.0), ("twist3d", 1.0, None), ("heavy_table", None, None)]
    raw = {"machine": {"git": "abc1234"}, "pareto": [{"case": c, "rows": rows(c, o, r)} for c, o, r in cases]}
    (results / "raw.json").write_text(json.dumps(raw))
    warm = next(f for f in st.rod_figures(results) if "warm, 0.001 L" in f.figure)
    assert warm.met and "faster on 2 of 2 cases" in warm.measured and "2.00×" in warm.measured
    raw["pareto"][2]["rows"][1].update(warm_ok=True, warm_s=3.0, warm_err=1e-4)  # only the rod reaches it
    (results / "raw.json").write_text(json.dumps(raw))
    warm = next(f for f in st.rod_figures(results) if "warm, 0.001 L" in f.figure)
    assert not warm.met and "faster on 2 of 3 cases" in warm.measured


SYNTHETIC = {
    "solver_speed.md": "git abc1234\n\n| derivatives | build s | warm median ms | warm p99 ms |\n|---|---|---|---|\n"
                       "| off | 0 | 2.00 | 20.0 |\n| compiled (first start) | 0 | 5.55 | 55.5 |\n"
                       "| compiled (later start, cached) | 0 | 0.25 | 0.90 |\n",
    "solver_speed_planar.md": "git abc1234\n\n| derivatives | warm median ms | warm p99 ms |\n|---|---|---|\n"
                              "| off | 1.00 | 9.0 |\n| compiled (first start) | 4.4 | 44 |\n"
                              "| compiled (later start, cached) | 0.50 | 1.50 |\n",
    "paced_updates.md": "git abc1234\n\n| model | sleep 0 ms | sleep 2 ms | sleep 9 ms | busy wait 4 ms |\n|---|---|---|---|---|\n"
                        "| planar, order 16 | 0.20 (0.3) | 0.25 (0.3) | 0.29 (0.4) | 7.7 (8) |\n"
                        "| 3D director, order 16 | 1.1 (2) | 1.2 (2) | 1.3 (2) | 9.9 (9) |\n",
    "queries_compiled.md": "git abc1234\n\n| way | cores used | queries/s |\n|---|---|---|\n"
                           "| one solver, in the caller's thread | 1 | 1000 |\n| query_many, 1 worker process | 1 | 1500 |\n"
                           "| query_many, 2 worker processes | 2 | 2100 |\n",
    "compile_cost.md": "git abc1234\n\n| model | unknowns | function |\n|---|---|---|\n| planar 8 | 11 | kkt_free |\n\n"
                       "| model | seconds | all compiled | first solve |\n|---|---|---|---|\n| planar 8 | 3.0 | True | ok |\n"
                       "| full 32 | 12.5 | True | ok |\n| full 8 | 4.0 | True | unverified |\n",
    "soak_no_queries.md": "git abc1234\nlatency target → centreline p50 5.0 ms, p99 10.0 ms, max 20 ms\n",
    "soak_3_clients.md": "git abc1234\nlatency target → centreline p50 6.0 ms, p99 11.5 ms, max 30 ms\n"
                         "Queries: 100 from 3 clients; latency p50 9 ms, p99 19 ms, max 40 ms.\n",
}


def _node(p50: float, p99: float) -> str:
    return ("git abc1234\n\n| measurement | p50 [ms] | p99 [ms] | max [ms] | rate |\n|---|---|---|---|---|\n"
            "| closed loop (300 targets, each waits) | 1.1 | 2.2 | 3 | r |\n"
            f"| open loop at 100 Hz (501 targets in 5 s) | {p50} | {p99} | 6 | r |\n\n"
            "| echo (executor at both ends) | p50 [ms] | p99 [ms] | max [ms] | rate |\n|---|---|---|---|---|\n"
            "| open loop at 100 Hz (501 targets), echo | 0.8 | 0.9 | 1 | r |\n")


def test_each_figure_comes_from_its_row_and_column(tmp_path):
    """Synthetic result files with a distinct value in every cell the table could confuse (the first
    start beside the cached one, p50 beside p99, the echo's rows below the node's)."""
    for name, text in SYNTHETIC.items():
        (tmp_path / name).write_text(text)
    (tmp_path / "node_latency_auto.md").write_text(_node(1.9, 4.9))
    (tmp_path / "node_latency_auto_planar.md").write_text(_node(2.1, 4.0))
    shutil.copy(RESULTS / "raw.json", tmp_path / "raw.json")
    got = {f.figure: (f.measured, f.met) for f in st.figures(tmp_path)}

    def one(start: str) -> tuple[str, bool]:
        (key,) = [k for k in got if k.startswith(start)]
        return got[key]

    assert one("warm update median, `default_cable`, 3D") == ("0.25 ms (0.12× interpreted)", True)
    assert one("warm update p99, 3D") == ("0.90 ms", True)
    assert one("warm update median, `default_cable`, planar") == ("0.50 ms (0.50× interpreted)", False)
    assert one("warm update p99, planar") == ("1.50 ms", False)
    assert one("warm update median after a 9 ms pause (as a stream spaces them), planar") == (
        "0.29 ms (back to back 0.20)", True)
    assert one("warm update median after a 9 ms pause (as a stream spaces them), 3D")[1] is False
    assert one("shape queries") == ("2100/s (2.10× one solver)", True)
    assert one("node target → centreline, 100 Hz, 3D") == ("p50 1.9 ms, p99 4.9 ms (closed loop 1.1 / 2.2)", True)
    assert one("node target → centreline, 100 Hz, planar")[1] is False
    assert one("three query clients") == ("11.5 ms against 10.0 ms alone (1.15×)", True)
    assert one("the same: query latency") == ("p50 9 ms, p99 19 ms", True)
    assert one("first start") == ("3.0–12.5 s (slowest: full 32); first solve not ok: full 8 unverified", False)


def test_a_file_this_run_did_not_write_is_not_met(tmp_path):
    results = _copy(tmp_path)
    found = st.figures(results)
    step = next(s for s in st.STEPS if s.out == "queries_compiled.md")
    marked = st.stale(found, [(step, 1.0, 0)], results, since=time.time() + 60)  # the file predates the run
    (queries,) = [f for f in marked if f.figure.startswith("shape queries")]
    assert not queries.met and "not re-measured" in queries.measured
    assert [f for f in marked if "not re-measured" in f.measured] == [queries]
    assert st.stale(found, [(step, 1.0, 0)], results, since=0.0) == found  # written by this run: unchanged


def test_the_machine_pace_is_read_from_the_echo_floor_and_the_interpreted_update(tmp_path):
    """The pace line quotes the echo round trip (the node's executor, closed loop) and the interpreted warm
    update of the files it reads, and is left out when a file lacks them."""
    results = _copy(tmp_path)
    echo = st.number(st.row((results / "node_latency_auto.md").read_text(), "p50 [ms]",
                            "closed loop (300 targets), Single")["p50 [ms]"])
    interpreted = st.number(st.row((results / "solver_speed.md").read_text(), "warm median ms", "off")["warm median ms"])
    line = st.machine_pace(results)
    assert f"p50 {echo:.2f} ms" in line and f"median {interpreted:.2f} ms" in line
    text = (results / "node_latency_auto.md").read_text()
    (results / "node_latency_auto.md").write_text(text.replace("SingleThreadedExecutor", "another executor"))
    assert st.machine_pace(results) == ""
    (results / "solver_speed.md").unlink()
    assert st.machine_pace(results) == ""
