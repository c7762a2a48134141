"""A saddle whose first escape step (SADDLE_STEP) climbs onto another branch: a shorter one.

The main job's manoeuvre (``dlo_ros.node.demo``: the default cable plus the post, the ends brought
together, the right end turned half a turn, the cable lowered onto the post) streamed on a fixed 3D
model: at update 409 Newton's warm answer is a weakly unstable saddle (λ_min ≈ −0.1).  Both ways
along its unstable mode, a first step of SADDLE_STEP rises before it falls and the descent ends on
a stable point *above* the saddle (refused: not downhill); IPOPT then took the update (0.2 s
interpreted).  A first step of SADDLE_RETRY_STEP descends to the stable point below it.  The
update must return that point on the Newton path, and it must be the one IPOPT finds from the same
start (an independent solve of the same update with the Newton rungs skipped).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dlo_ros.model.problem import GripPose
from dlo_ros.node import demo
from dlo_ros.scene import load_scene, scene_from_dict, scene_to_dict
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.update import ladder as LD

PERIOD = 0.02  # s: the demo driver's rate
SADDLE_UPDATE = 409


def demo_targets() -> list[dict]:
    return [
        {"left": GripPose(pl, ql), "right": GripPose(pr, qr)}
        for (pl, ql), (pr, qr) in (
            demo.targets_at(i * PERIOD) for i in range(1, SADDLE_UPDATE + 2)
        )
    ]


def streamed_to_the_saddle() -> tuple[ShapeSolver, list[dict]]:
    """A fixed 3D model (auto's on the post, one element) streamed up to the update before it."""
    d = scene_to_dict(load_scene("default_cable"))
    d["obstacles"] = list(d.get("obstacles", [])) + [dict(demo.POST)]
    scene = scene_from_dict(d)
    options = replace(
        scene.options, model="full", order=12, obstacle_slots=2, update_time_limit=0.0
    )
    solver = ShapeSolver(scene.problem, options, compile="off")
    assert solver.solve().ok
    targets = demo_targets()
    for poses in targets[:SADDLE_UPDATE]:
        assert solver.solve(poses).status in ("ok", "unverified")
    return solver, targets


def test_the_shorter_first_step_leaves_the_saddle_downhill(monkeypatch):
    solver, targets = streamed_to_the_saddle()
    # the same update solved by IPOPT from the same start (the Newton rungs skipped), as a query:
    # nothing committed
    with monkeypatch.context() as m:
        m.setattr(LD, "newton_rungs", lambda ctx, problem, start, p1: (None, 0))
        by_ipopt = solver.solve(targets[SADDLE_UPDATE], commit=False)
    assert by_ipopt.ok and by_ipopt.stable and by_ipopt.ipopt_status != "Newton", by_ipopt.message

    attempts, left = [], []
    original, leave = LD.leave_saddle, LD.leave_newton_saddle
    monkeypatch.setattr(
        LD,
        "leave_saddle",
        lambda *a, **k: attempts.append(k.get("first_step")) or original(*a, **k),
    )

    def leave_newton_saddle(*args):
        out = leave(*args)
        left.append(out[0] is not None)
        return out

    monkeypatch.setattr(LD, "leave_newton_saddle", leave_newton_saddle)
    warm = solver.solve(targets[SADDLE_UPDATE])
    assert left, "Newton did not land on a saddle: the scene no longer tests what it says"
    assert left[0], "the saddle was not left by the shifted Newton steps (IPOPT took the update)"
    assert warm.ok and warm.stable and warm.ipopt_status == "Newton", warm.message
    assert len(set(attempts)) == 2, (
        f"first steps tried: {attempts}: the first escape no longer fails, so this scene no "
        "longer tests the retry"
    )
    assert warm.energy["total"] == pytest.approx(by_ipopt.energy["total"], rel=1e-9)
    assert np.linalg.norm(warm.points - by_ipopt.points, axis=1).max() < 1e-6
