"""bench/perf/speed_targets.py reads issue #14's figures back from the result files: its table reader, its
"met" verdicts, and that every committed result file still has the rows it reads.  No timing is asserted."""
from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import RESULTS  # noqa: E402
from bench.perf import speed_targets as st  # noqa: E402

FILES = ("solver_speed.md", "solver_speed_planar.md", "queries_compiled.md", "compile_cost.md",
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
    assert len(found) == 4 + 2 * len(st.TOLERANCES) + 1 + 2 + 2 + 1
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
    warm = next(f for f in st.rod_figures(results) if f.figure.endswith("warm, 0.001 L"))
    assert warm.met and "faster on 2 of 2 cases" in warm.measured and "2.00×" in warm.measured
    raw["pareto"][2]["rows"][1].update(warm_ok=True, warm_s=3.0, warm_err=1e-4)  # only the rod reaches it
    (results / "raw.json").write_text(json.dumps(raw))
    warm = next(f for f in st.rod_figures(results) if f.figure.endswith("warm, 0.001 L"))
    assert not warm.met and "faster on 2 of 3 cases" in warm.measured
