"""Speed vs accuracy (Pareto) runs: every method and setting on every case, cold and warm."""
from __future__ import annotations

import statistics
import time
import traceback

import numpy as np

from dlo_ros.model.problem import GripPose

from bench.common import Case, asym_case, elastica_case, heavy_case, loads_case, max_error, twist_case
from bench.methods.runners import METHOD_LABELS, ORDERS, PEERS, SEGMENTS, make_runner
from bench.suite.references import reference, reference_for


def cases(quick: bool, methods=None) -> list[Case]:
    """The cases; with ``methods`` (a set of method names) only those on which one of them runs."""
    chords = (0.9, 0.6, 0.3) if quick else (0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3)
    every = [elastica_case(c) for c in chords] + [asym_case(), heavy_case(), loads_case(), twist_case()]
    return [c for c in every if settings(c, quick, methods)]


def settings(case: Case, quick: bool, methods=None) -> list[tuple[str, object]]:
    orders = (4, 8, 12, 16) if quick else ORDERS
    segs = (10, 40, 160) if quick else SEGMENTS
    peers = (10, 20, 40) if quick else (10, 20, 40, 80)
    out = [("paper", 10)]
    out += [("fourier", n) for n in orders]
    if case.planar:
        out += [("fourier-3d", n) for n in orders]
    out += [("default", n) for n in orders]
    if case.planar:
        out += [("default-planar", n) for n in orders]
    out += [("rod", n) for n in segs]
    out += [("pyelastica", n) for n in peers]
    if case.planar:
        out += [("mujoco", n) for n in peers]
        # implicit in the rod's forces: N = 320 costs less than the cable's N = 40 (bench/methods/peers.py)
        out += [("mujoco-rod", n) for n in (peers if quick else peers + (160, 320))]
    return [(m, n) for m, n in out if methods is None or m in methods]


def pre_target(case: Case):
    """The neighbouring target a warm solve starts from: the right grip 0.01 L further out along x."""
    right = case.problem.grip("right")
    pos = right.pose.position + np.array([0.01 * case.L, 0.0, 0.0])
    return case.problem.with_grip_poses({"right": GripPose(pos, right.pose.orientation)})


def run_case(case: Case, quick: bool, log=print, bar=None, methods=None) -> dict:
    t0 = time.perf_counter()
    ref = reference(case, quick)
    ref_time = time.perf_counter() - t0
    if ref.get("sag") == 1.0 and case.problem.string.weight_per_length.is_zero:
        # the lowest branch buckles up: point every method's cold guess there (gravity only steers the guesses
        # of a weightless case).  Which branch a method finds by itself is the stability map's question.
        from dataclasses import replace

        case = replace(case, problem=replace(case.problem, gravity=np.array([0.0, 0.0, 1.0])))
    rows = []
    for method, setting in settings(case, quick, methods):
        if bar is not None:
            bar.set_postfix_str(f"{case.name}: {method} {setting}")
        row = {"case": case.name, "method": method, "setting": setting}
        try:
            kw = {}
            if method in PEERS:
                kw = {"settle": 1e-4, "max_time": 20.0 if quick else 60.0}
            if method == "paper":
                kw = {"time_limit": 30.0 if quick else 60.0}
            runner = make_runner(method, setting, case, **kw)
            row["build_s"] = runner.build_time_s
            ref_pts = reference_for(method, ref)
            repeats = 1 if method == "paper" or method in PEERS else 3
            cold = [runner.cold(case.problem) for _ in range(repeats)]
            c = cold[-1]
            row.update(cold_ok=c.ok, cold_s=statistics.median(o.time_s for o in cold), cold_iter=c.iterations,
                       cold_stable=c.stable, cold_err=max_error(c.points, ref_pts, case.align_about_chord, mirror=case.planar) if c.ok else np.nan,
                       cold_msg=c.message, cold_energy=c.energy, dE=c.energy - ref.get("energy", np.nan))
            warm = []
            for _ in range(repeats):
                pre = runner.cold(pre_target(case))
                if not pre.ok:
                    break
                warm.append(runner.warm(case.problem))
            if warm:
                w = warm[-1]
                row.update(warm_ok=w.ok, warm_s=statistics.median(o.time_s for o in warm), warm_iter=w.iterations,
                           warm_stable=w.stable,
                           warm_err=max_error(w.points, ref_pts, case.align_about_chord, mirror=case.planar) if w.ok else np.nan,
                           warm_msg=w.message)
            else:
                row.update(warm_ok=False, warm_s=np.nan, warm_err=np.nan, warm_msg="pre-target solve failed")
            if method in PEERS:
                row["peer"] = {k: (float(v) if isinstance(v, (int, float, np.floating)) else v) for k, v in c.extra.items()}
        except ImportError as exc:
            row.update(error=f"not installed: {exc}")
        except Exception as exc:  # a method that crashes is a result, not a benchmark failure
            row.update(error=f"{type(exc).__name__}: {exc}")
            log(traceback.format_exc())
        rows.append(row)
        if bar is not None:
            bar.update(1)
    return {"case": case.name, "title": case.title, "reference": {k: v for k, v in ref.items() if k not in ("rod", "ritz")},
            "reference_time_s": ref_time, "rows": rows, "align": case.align_about_chord}


def count(quick: bool, methods=None) -> int:
    return sum(len(settings(c, quick, methods)) for c in cases(quick, methods))


__all__ = ["cases", "settings", "run_case", "count", "METHOD_LABELS", "ORDERS", "SEGMENTS"]
