"""The stability map: sweeps where methods fail.

compression  chord 0.95L → 0.1L, clamped–clamped, no weight, Rt = Rf; a cold solve at every point.
             Reference: the closed-form elastica where it is stable in 3D (checked with the quaternion rod,
             N = 100); where it is not (chord ≤ 0.3L here), the rod's lower stable non-planar shape.
rotation     chord 0.6L, right end turned τ = 0 → 4π about its tangent (3D); every method follows the
             sweep by continuation (warm from the previous τ; the dynamic peers relax from a polyline
             twisted by τ).  Reference: quaternion rod N = 120 in steps of π/16.
weight       ρ = D L³/Rf from 0 to 5000, chord 0.7L, horizontal clamps, a table at z = −0.25L; cold
             solves.  Reference: the lowest-energy stable equilibrium among planar-rod (N = 200) solves
             from four starts (sag down, sag up, two asymmetric) and continuation from both ends of the sweep.
jump         from the converged chord-0.7L elastica, one jump of the right grip by δ = 0.01L … 0.5L
             up-and-inward (direction (−1, 0, 1)/√2); a single warm solve.  Reference: the quaternion rod
             (N = 100) following the jump in 50 steps (the string moves continuously), then leaving the end
             state along its negative-curvature mode if it is unstable out of plane.

A cell's verdict: right = max error to the reference < TOL·L (after the best rotation about the chord in
the weightless sweeps, where that rotation is neutral); a wrong cell whose energy is lower than the
reference's is marked separately (the method found an equilibrium outside the reference's search).
"""
from __future__ import annotations

import time
import traceback

import numpy as np

from dlo_ros.model.problem import GripPose

from bench.common import Case, elastica_case, heavy_case, make_problem, max_error, table, twist_case
from bench.methods.planar import PlanarRod
from bench.methods.rod3d import Rod3D
from bench.methods.runners import PEERS, make_runner, twisted_problem
from bench.suite.references import elastica_points

TOL = 0.05

PLANAR_METHODS = [("paper", 10), ("fourier", 10), ("fourier", 16), ("fourier-3d", 16), ("fourier-3d-z", 16), ("default", 16), ("default-planar", 16),
                  ("rod", 80), ("pyelastica", 20), ("mujoco", 20), ("mujoco-rod", 20)]
TWIST_METHODS = [("paper", 10), ("fourier", 10), ("fourier", 16), ("default", 16), ("rod", 40), ("pyelastica", 20)]


def values(sweep: str, quick: bool) -> list[float]:
    if sweep == "compression":
        return [0.95, 0.8, 0.6, 0.4, 0.3, 0.2, 0.1] if quick else list(np.round(np.arange(0.95, 0.09, -0.05), 2))
    if sweep == "rotation":
        step = np.pi / 4 if quick else np.pi / 8
        return list(np.arange(0, 4 * np.pi + 1e-9, step))
    if sweep == "weight":
        return [0, 500, 1000, 2000, 3000, 5000] if quick else [0, 250, 500, 1000, 1500, 2000, 2500, 3000, 4000, 5000]
    if sweep == "jump":
        return [0.01, 0.05, 0.1, 0.2, 0.3, 0.5] if quick else [0.01, 0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5]
    raise ValueError(sweep)


def jump_problem(base: Case, delta: float):
    right = base.problem.grip("right")
    pos = right.pose.position + delta * np.array([-1.0, 0.0, 1.0]) / np.sqrt(2)
    return base.problem.with_grip_poses({"right": GripPose(pos, right.pose.orientation)})


def weight_problem(rho: float):
    return make_problem(chord=0.7, rt=0.0, d=rho, obstacles=(table(-0.25),))


# ---------------------------------------------------------------------------------------------------
def references(sweep: str, vals, quick: bool) -> list[dict]:
    if sweep == "compression":
        # the planar elastica, unless the quaternion rod (3D, Rt = Rf) finds it unstable out of plane: then the
        # rod leaves it along the negative-curvature mode and the lower stable 3D shape is the reference
        from dlo_ros.model.elastica import clamped_clamped_elastica

        refs = []
        for c in vals:
            case = elastica_case(c)
            rod = Rod3D(case.problem, 60 if quick else 100)
            o, sol = rod.cold(case.problem)
            el = clamped_clamped_elastica(1.0, 1.0, c)
            ref = {"points": elastica_points(c), "stable": bool(o.stable), "energy": el.energy, "kind": "elastica"}
            if o.ok and o.stable is False:
                sol2, moved = rod.nlp.escape_saddle(sol, sol.p)
                if moved:
                    o2, _ = rod._finish(sol2, sol.p)
                    ref = {"points": o2.points, "stable": bool(o2.stable), "energy": o2.energy,
                           "kind": "3D rod (planar elastica unstable)", "planar_energy": el.energy}
            refs.append(ref)
        return refs
    if sweep == "rotation":
        case = twist_case(0.0)
        m = Rod3D(case.problem, 60 if quick else 120)
        out, sol = m.cold(case.problem)
        refs, tau, step = [], 0.0, np.pi / 16
        for v in vals:
            while tau < v - 1e-9:
                tau = min(v, tau + step)
                out, sol = m.warm(twisted_problem(case, tau), sol)
            refs.append({"points": out.points, "stable": out.stable, "energy": out.energy, "ok": out.ok})
        return refs
    if sweep == "weight":
        N = 100 if quick else 200
        base = weight_problem(1.0)
        m = PlanarRod(base, N)
        cands = [[] for _ in vals]
        for i, rho in enumerate(vals):
            for sag in (-1.0, 1.0):
                o, _ = m.cold(base, rho, sag)
                cands[i].append(o)
            p = m.params(base, rho)
            for skew in (-1.0, 1.0):  # asymmetric starts: the buckle shifted toward one end
                u = (np.arange(N) + 0.5) / N
                z0 = -1.2 * np.sin(2 * np.pi * u) + skew * 0.8 * np.sin(np.pi * u) * (1 - 2 * u)
                cands[i].append(m._finish(m.nlp.solve(z0, p), p)[0])
        for order in (vals, vals[::-1]):  # continuation both ways
            sol = None
            for rho in order:
                i = vals.index(rho)
                o, sol = m.cold(base, rho) if sol is None else m.warm(base, sol, rho)
                cands[i].append(o)
                if not o.ok:
                    sol = None
        refs = []
        for c in cands:
            good = [o for o in c if o.ok and o.stable]
            best = min(good, key=lambda o: o.energy)
            refs.append({"points": best.points, "stable": True, "energy": best.energy,
                         "energies": sorted({round(o.energy, 6) for o in good})})
        return refs
    if sweep == "jump":
        # the quaternion rod (3D, Rt = Rf) follows the jump in 50 steps; if the end state is unstable out of
        # plane it leaves it along the negative-curvature mode (as the string would)
        base = elastica_case(0.7)
        m = Rod3D(base.problem, 60 if quick else 100)
        refs = []
        for d in vals:
            o, sol = m.cold(base.problem, check=False)
            for k in range(1, 51):
                o, sol = m.warm(jump_problem(base, d * k / 50), sol, check=(k == 50))
            kind = "rod path"
            if o.ok and o.stable is False:
                sol2, moved = m.nlp.escape_saddle(sol, sol.p)
                if moved:
                    o, _ = m._finish(sol2, sol.p)
                    kind = "rod path, then off the unstable planar state"
            refs.append({"points": o.points, "stable": o.stable, "energy": o.energy, "ok": o.ok, "kind": kind})
        return refs
    raise ValueError(sweep)


def verdict(ok, err, stable, energy=np.nan, ref_energy=np.nan) -> float:
    """3 right & stable (or no verdict), 2 right but called unstable, 1.25 a different equilibrium of LOWER
    energy than the reference (outside the reference's search, e.g. out of its plane), 1 wrong equilibrium
    called stable, 0.5 wrong and unstable (a saddle), 0 failed."""
    if not ok or not np.isfinite(err):
        return 0.0
    if err < TOL:
        return 2.0 if stable is False else 3.0
    if np.isfinite(energy) and np.isfinite(ref_energy) and energy < ref_energy - 2e-3 * abs(ref_energy) - 1e-9:
        return 1.25
    return 0.5 if stable is False else 1.0


def sweep_methods(sweep: str, methods=None) -> list[tuple[str, int]]:
    """The method rows of a sweep; with ``methods`` (a set of method names) only theirs."""
    rows = TWIST_METHODS if sweep == "rotation" else PLANAR_METHODS
    return [(m, n) for m, n in rows if methods is None or m in methods]


def run_sweep(sweep: str, quick: bool, bar=None, log=print, methods=None) -> dict:
    vals = values(sweep, quick)
    t0 = time.perf_counter()
    refs = references(sweep, vals, quick)
    ref_time = time.perf_counter() - t0
    cells: dict[str, list[dict]] = {}
    for method, setting in sweep_methods(sweep, methods):
        key = f"{method} {setting}"
        cells[key] = []
        if bar is not None:
            bar.set_postfix_str(f"{sweep}: {key}")
        try:
            cells[key] = _run_method(sweep, method, setting, vals, refs, quick)
        except ImportError as exc:
            cells[key] = [{"ok": False, "err": np.nan, "cat": 0.0, "msg": f"not installed: {exc}"} for _ in vals]
        except Exception as exc:
            log(traceback.format_exc())
            cells[key] = [{"ok": False, "err": np.nan, "cat": 0.0, "msg": f"{type(exc).__name__}: {exc}"} for _ in vals]
        if bar is not None:
            bar.update(1)
    return {"sweep": sweep, "values": [float(v) for v in vals], "cells": cells, "reference_time_s": ref_time,
            "reference_stable": [r.get("stable") for r in refs], "reference_kind": [r.get("kind", "") for r in refs],
            "reference_energies": [r.get("energies", r.get("energy")) for r in refs]}


def _cell(out, ref, align, mirror=True) -> dict:
    err = max_error(out.points, ref["points"], align, mirror=mirror) if out.ok and out.points is not None else np.nan
    e_ref = ref.get("energy", np.nan)
    e_ref = np.nan if e_ref is None else e_ref
    return {"ok": bool(out.ok), "err": err, "stable": out.stable, "iters": int(out.iterations),
            "time": float(out.time_s), "energy": float(out.energy), "ref_energy": float(e_ref),
            "cat": verdict(out.ok, err, out.stable, out.energy, e_ref), "msg": str(out.message)[:120]}


def _run_method(sweep, method, setting, vals, refs, quick) -> list[dict]:
    peer = method in PEERS
    peer_kw = {"settle": 1e-4, "max_time": 10.0 if quick else 30.0}
    nm_kw = {"time_limit": 15.0 if quick else 20.0}
    kw = peer_kw if peer else nm_kw if method == "paper" else {}
    out_cells = []
    if sweep == "compression":
        for c, ref in zip(vals, refs):
            case = elastica_case(c)
            runner = make_runner(method, setting, case, **kw)
            out_cells.append(_cell(runner.cold(case.problem), ref, True))
        return out_cells
    if sweep == "weight":
        base = Case("weight", "", weight_problem(1.0), reference_kind="converged", chord=0.7)
        runner = None
        for rho, ref in zip(vals, refs):
            pr = weight_problem(rho)
            if method in ("fourier", "rod", "paper") or peer:
                # bench models bake D in with a scale parameter; peers read D from the problem
                case = Case("weight", "", pr if peer or rho == 0 else weight_problem(1.0), chord=0.7)
                if peer:
                    runner = make_runner(method, setting, case, **kw)
                    o = runner.cold(pr)
                else:
                    if runner is None:
                        runner = make_runner(method, setting, base, **kw)
                    runner.weight_scale = rho
                    o = runner.cold(weight_problem(1.0))
            else:
                if runner is None:
                    runner = make_runner(method, setting, Case("weight", "", weight_problem(1.0), chord=0.7), **kw)
                o = runner.cold(pr)
            out_cells.append(_cell(o, ref, False))
        return out_cells
    if sweep == "jump":
        base = elastica_case(0.7)
        runner = make_runner(method, setting, base, **kw)
        for d, ref in zip(vals, refs):
            b = runner.cold(base.problem)
            if not b.ok:
                out_cells.append({"ok": False, "err": np.nan, "cat": 0.0, "msg": "base solve failed"})
                continue
            out_cells.append(_cell(runner.warm(jump_problem(base, d)), ref, True))
        return out_cells
    if sweep == "rotation":
        case0 = twist_case(0.0)
        if peer:
            for tau, ref in zip(vals, refs):
                case = twist_case(tau)
                runner = make_runner(method, setting, case, **kw)
                out_cells.append(_cell(runner.cold(case.problem), ref, True, mirror=False))
            return out_cells
        runner = make_runner(method, setting, case0, **kw)
        o = runner.cold(case0.problem)
        broken = not o.ok
        out_cells.append(_cell(o, refs[0], True, mirror=False))
        for tau, ref in zip(vals[1:], refs[1:]):
            if broken:  # a continuation cannot restart: the turn count is lost
                out_cells.append({"ok": False, "err": np.nan, "cat": 0.0, "msg": "continuation broken earlier"})
                continue
            o = runner.warm(twisted_problem(case0, tau))
            broken = not o.ok
            out_cells.append(_cell(o, ref, True, mirror=False))
        return out_cells
    raise ValueError(sweep)


SWEEPS = ("compression", "rotation", "weight", "jump")


def count(quick: bool, methods=None) -> int:
    return sum(len(sweep_methods(s, methods)) for s in SWEEPS)
