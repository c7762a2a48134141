"""One data-set row per sample: the certified answer of a shape solve, flattened for Parquet.

Every sample is stored, whatever its status (a failed or ``unverified`` answer with its message).
Columns (:data:`SCHEMA`; lists are flattened row-major, units SI):

* ``sample`` (its index in the plan), ``status``, ``message``, ``start`` ('held', 'cold' or
  'previous': the branch it was solved from, ``work.py``);
* ``targets``: the plan's grips' commanded poses, per grip [x, y, z, qx, qy, qz, qw] in the plan's
  grip order (the manifest's ``plan_grips``);
* ``bend_stiffness``, ``twist_stiffness``, ``weight_per_length``, ``stretch_stiffness``: the
  string's values the sample was solved with (drawn by the plan's ``string``, else the scene's;
  null where the scene's is a table, or an inextensible string's stretch);
* ``stable`` (null when the solver cannot tell), ``min_eigenvalue`` (of the reduced Hessian, null
  without one), ``equilibrium_residual_m`` (the strong-form residual that certifies it),
  ``constraint_violation``;
* ``tolerance_m``, ``estimated_error_m``, ``tolerance_met``: the model's discretisation check;
* ``energy_<part>`` [J] for ``bend``, ``twist``, ``stretch``, ``gravity``, ``external_work``,
  ``total`` (U − W; null where it has no meaning, ``msg_docs/model_and_solver.md``);
* ``grip_force``, ``grip_torque``: per scene grip (scene order) [N], [N·m];
* ``obstacle_force``: per scene obstacle (scene order) the total contact force [N] (0 without
  contact); ``contacts``: the JSON of the point and line contact loads and self-contacts
  (``dlo solve --json``'s ``contact_loads`` and ``self_contacts``);
* ``min_self_distance`` [m] (null: not checked or no two strands within reach),
  ``passes_through_itself``;
* ``s`` [m], ``points`` [m]: the centreline at the plan's resolution;
* ``unstable_min_eigenvalue``, ``unstable_energy_total`` [J], ``unstable_points`` [m]: the
  unstable equilibrium the solver met and left on its way to this one (the saddle beside it:
  ``ShapeResult.unstable_met``), null and empty when it met none;
* ``model``: the JSON of the model summary; ``solve_time_ms``, ``iterations``, ``derivatives``.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pyarrow as pa

from ..jsonio import json_safe
from ..model.problem import GripPose, Problem
from ..solver.results.result import ShapeResult
from .materials import KEYS as MATERIAL_KEYS
from .materials import uniform_value

ENERGY_PARTS = ("bend", "twist", "stretch", "gravity", "external_work", "total")

_floats = pa.list_(pa.float64())
SCHEMA = pa.schema(
    [
        ("sample", pa.int64()),
        ("status", pa.string()),
        ("message", pa.string()),
        ("start", pa.string()),
        ("targets", _floats),
        *[(key, pa.float64()) for key in MATERIAL_KEYS],
        ("stable", pa.bool_()),
        ("min_eigenvalue", pa.float64()),
        ("equilibrium_residual_m", pa.float64()),
        ("constraint_violation", pa.float64()),
        ("tolerance_m", pa.float64()),
        ("estimated_error_m", pa.float64()),
        ("tolerance_met", pa.bool_()),
        *[(f"energy_{part}", pa.float64()) for part in ENERGY_PARTS],
        ("grip_force", _floats),
        ("grip_torque", _floats),
        ("obstacle_force", _floats),
        ("contacts", pa.string()),
        ("min_self_distance", pa.float64()),
        ("passes_through_itself", pa.bool_()),
        ("s", _floats),
        ("points", _floats),
        ("unstable_min_eigenvalue", pa.float64()),
        ("unstable_energy_total", pa.float64()),
        ("unstable_points", _floats),
        ("model", pa.string()),
        ("solve_time_ms", pa.float64()),
        ("iterations", pa.int64()),
        ("derivatives", pa.string()),
    ]
)


def _number(value: Any) -> float | None:
    """Return a finite float, or None (null) for None, NaN and infinities."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def _flat(a: Any) -> list[float]:
    return [float(v) for v in np.asarray(a, dtype=float).ravel()]


def sample_row(
    index: int, targets: dict[str, GripPose], result: ShapeResult, problem: Problem, start: str
) -> dict[str, Any]:
    """Return the row of sample ``index`` (module docstring) from its answer ``result``.

    ``targets``: its commanded poses (the plan's grips, in the plan's order); ``problem``: the
    one it was solved with (its string values, grip and obstacle order).
    """
    model, met = result.model, result.unstable_met
    forces = np.zeros((len(problem.obstacles), 3))
    for i, f in result.contact_forces.items():
        if 0 <= int(i) < len(forces):
            forces[int(i)] = f
    wrenches = [result.grips.get(g.name) for g in problem.grips]
    return {
        "sample": int(index),
        "status": result.status,
        "message": result.message,
        "start": start,
        "targets": [v for pose in targets.values() for v in (*pose.position, *pose.orientation)],
        **{key: uniform_value(getattr(problem.string, key)) for key in MATERIAL_KEYS},
        "stable": result.stable,
        "min_eigenvalue": _number(result.min_eigenvalue),
        "equilibrium_residual_m": _number(result.equilibrium_residual_m),
        "constraint_violation": _number(result.constraint_violation),
        "tolerance_m": _number(model.tolerance_m) if model is not None else None,
        "estimated_error_m": _number(model.estimated_error_m) if model is not None else None,
        "tolerance_met": model.tolerance_met if model is not None else None,
        **{f"energy_{p}": _number(result.energy.get(p)) for p in ENERGY_PARTS},
        "grip_force": _flat([np.zeros(3) if w is None else w.force for w in wrenches]),
        "grip_torque": _flat([np.zeros(3) if w is None else w.torque for w in wrenches]),
        "obstacle_force": _flat(forces),
        "contacts": json.dumps(json_safe(result.contacts_dict()), allow_nan=False),
        "min_self_distance": _number(result.min_self_distance),
        "passes_through_itself": bool(result.passes_through_itself),
        "s": _flat(result.s),
        "points": _flat(result.points),
        "unstable_min_eigenvalue": _number(met.min_eigenvalue) if met else None,
        "unstable_energy_total": _number(met.energy.get("total")) if met else None,
        "unstable_points": _flat(met.points) if met else [],
        "model": json.dumps(json_safe(result.model_dict()), allow_nan=False),
        "solve_time_ms": _number(result.solve_time_ms),
        "iterations": int(result.iterations),
        "derivatives": result.derivatives,
    }


def rows_table(rows: list[dict[str, Any]]) -> pa.Table:
    """Return ``rows`` as an Arrow table of :data:`SCHEMA`."""
    return pa.Table.from_pylist(rows, schema=SCHEMA)
