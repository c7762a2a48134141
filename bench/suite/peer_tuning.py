"""How the dynamic peers' settings were chosen (and where their time steps blow up).

On the chord-0.6L elastica with N = 20 segments, each knob is swept with the others at their defaults:
time-step factor ``cfl`` (PyElastica dt = cfl·(L/N)/√(EA/m'); MuJoCo's cable dt = cfl·2/ω_max with ω_max
the one-segment bending frequency; MuJoCo 4's rod dt = cfl/(N ω₁)), damping ratio ``zeta`` (ν = ζ·2ω₁ for
PyElastica's velocity damper; the joints' damping for MuJoCo's cable; every vertex's for its rod), the rod radius (PyElastica: EA/EI = 4/r², the stretch error and the axial
wave speed), and the rest tolerance ``settle``.  Reported: time to rest, simulated time, steps, error.
The fastest setting that keeps the error at the discretisation floor (≈ 2.5e-2 L at N = 20, first order
in L/N because both clamp a whole end segment) is what bench/methods/peers.py uses.
"""
from __future__ import annotations

import numpy as np

from bench.common import elastica_case, max_error
from bench.suite.references import elastica_points

KNOBS = {
    "pyelastica": {"cfl": [0.25, 0.5, 0.9, 1.5, 3.0], "zeta": [0.25, 0.5, 1.0, 2.0, 4.0],
                   "radius": [0.005, 0.002, 0.001], "settle": [1e-3, 1e-4, 1e-5]},
    "mujoco": {"cfl": [0.25, 0.5, 0.9, 1.5, 3.0], "zeta": [0.25, 0.5, 1.0, 2.0, 4.0],
               "settle": [1e-3, 1e-4, 1e-5]},
    "mujoco-rod": {"cfl": [0.4, 0.75, 1.5, 3.0, 6.0, 12.0], "zeta": [0.5, 1.0, 2.0, 4.0], "settle": [1e-3, 1e-4, 1e-5]},
}


def run(quick: bool, bar=None) -> list[dict]:
    from bench.methods.peers import make_peer

    case = elastica_case(0.6)
    ref = elastica_points(0.6)
    rows = []
    for method, knobs in KNOBS.items():
        for knob, values in knobs.items():
            if bar is not None:
                bar.set_postfix_str(f"peer tuning: {method} {knob}")
            for v in values:
                kw = {"settle": 1e-4, "max_time": 10.0 if quick else 20.0}
                kw[knob] = v
                try:
                    runner = make_peer(method, 20, case, **kw)
                    o = runner.cold(case.problem)
                    rows.append({"method": method, "knob": knob, "value": v, "ok": o.ok, "time_s": o.time_s,
                                 "err": max_error(o.points, ref, True) if o.points is not None else np.nan,
                                 "steps": o.extra.get("steps"), "sim_time": o.extra.get("sim_time"),
                                 "dt": o.extra.get("dt"), "msg": o.message})
                except ImportError as exc:
                    rows.append({"method": method, "knob": knob, "value": v, "ok": False, "msg": f"not installed: {exc}"})
                except Exception as exc:  # a blow-up that raises is a result too
                    rows.append({"method": method, "knob": knob, "value": v, "ok": False, "msg": f"{type(exc).__name__}: {exc}"[:120]})
            if bar is not None:
                bar.update(1)
    return rows


def count() -> int:
    return sum(len(k) for k in KNOBS.values())


def table(rows: list[dict]) -> str:
    from .report import fmt

    out = ["| peer | knob | value | settled | time to rest [s] | simulated [s] | steps | dt [s] | error/L | note |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['method']} | {r['knob']} | {r['value']:g} | {fmt(r.get('ok'))} | {fmt(r.get('time_s'), '.3g')} | "
                   f"{fmt(r.get('sim_time'), '.3g')} | {fmt(r.get('steps'))} | {fmt(r.get('dt'), '.2g')} | "
                   f"{fmt(r.get('err'), '.2g')} | {str(r.get('msg', ''))[:70]} |")
    return "\n".join(out) + "\n"
