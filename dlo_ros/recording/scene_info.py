"""What the writer needs of a scene, as plain data (the writer process never imports the model)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class SceneInfo:
    """What the writer needs of a scene, as plain data.

    What the writer needs of a scene (plain data: the writer process never imports the
    model).
    """

    name: str
    frame_id: str
    length: float
    grip_s: dict
    grip_order: tuple
    rf_table: tuple  # (s values, Rf values): Rf(s) piecewise linear, ends held
    force_scale: float  # m per N
    yaml_text: str
    obstacles: list  # (archetype, kwargs, label, colour RGB 0-255)
    centre: np.ndarray
    gravity: np.ndarray
    solver_kind: str
    radius: float
    grip_positions: np.ndarray
    model: str = ""  # the scene's solver.model ('auto', 'full', 'planar'; '' unknown)

    def bend_stiffness(self, s: np.ndarray) -> np.ndarray:
        xs, vs = self.rf_table
        return (
            np.interp(np.asarray(s, dtype=float), xs, vs)
            if len(xs) > 1
            else np.full(np.shape(s), vs[0])
        )


def scene_yaml(scene: Any) -> str:
    """Return the scene in the scene-file format (``dlo_ros.scene.scene_to_dict``) as YAML text."""
    # here, not at the top: the writer's process imports this module and must not import the
    # scene package (the model and solver: see scene_info below)
    import yaml  # not at the top: see above
    from ..scene import scene_to_dict  # not at the top: see above

    return yaml.safe_dump(
        scene_to_dict(scene), sort_keys=False, default_flow_style=None, width=120
    )


def scene_info(
    scene_or_problem: Any,
    frame_id: str | None = None,
    solver: Any = None,
    force_scale: float | None = None,
) -> SceneInfo:
    """Return the writer's view of a Scene (or a bare Problem: then no YAML, not re-solvable).

    Runs in the caller's process; the obstacles become (archetype, kwargs, label, colour).
    """
    # here, not at the top: the writer's process imports this module (through the package) and
    # must not import the model (CasADi): 0.11-0.17 s (python -X importtime -c 'import
    # dlo_ros.model', 3 runs); test_recording checks the writer's imports.
    from .obstacle_drawing import obstacle_shape

    problem = getattr(scene_or_problem, "problem", scene_or_problem)
    is_scene = problem is not scene_or_problem
    st = problem.string
    L = float(st.length)
    gpos = np.array([g.pose.position for g in problem.grips], dtype=float)
    gu = problem.gravity_unit
    centre = gpos.mean(axis=0) + 0.25 * L * gu
    if force_scale:
        scale = float(force_scale)
    else:
        weight = float(np.mean(st.weight_per_length(np.linspace(0, L, 201)))) * L
        loads = sum(float(np.linalg.norm(ld.force)) for ld in problem.loads)
        f_ref = max(weight, loads, 4 * math.pi**2 * st.bend_stiffness.maximum / L**2, 1e-12)
        scale = 0.15 * L / f_ref
    extent = 0.8 * L
    obstacles = []
    for ob in problem.obstacles:
        kind, kwargs = obstacle_shape(ob, centre, extent)
        obstacles.append((kind, kwargs, ob.name or ob.type, list(ob.primitive().colour)))
    kind = solver if isinstance(solver, str) else ("" if solver is None else type(solver).__name__)
    return SceneInfo(
        name=str(getattr(scene_or_problem, "name", "problem")),
        frame_id=str(frame_id or getattr(scene_or_problem, "frame_id", "world")),
        length=L,
        grip_s={g.name: float(g.s) for g in problem.grips},
        grip_order=tuple(g.name for g in problem.grips),
        rf_table=(tuple(st.bend_stiffness.s), tuple(st.bend_stiffness.values)),
        force_scale=scale,
        yaml_text=scene_yaml(scene_or_problem) if is_scene else "",
        obstacles=obstacles,
        centre=centre,
        gravity=gu,
        solver_kind=kind,
        radius=float(st.radius),
        grip_positions=gpos,
        model=str(getattr(getattr(scene_or_problem, "options", None), "model", "") or ""),
    )
