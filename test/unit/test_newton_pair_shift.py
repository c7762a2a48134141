"""Warm Newton updates whose contact slides past its pair of node rows (update/active_set.py).

With the obstacle rows on the mesh nodes, a contact on a round obstacle sits between two rows i, j.
When it slides on past j, Newton's one-row changes go round a cycle: {i, j} gives λ_i < 0 (i pulls
the string onto the obstacle), {j} leaves row i just inside it, and {i, j} again.  The update then
fell back to IPOPT (0.1–0.3 s interpreted), at every second update of the main job's last seconds
on the post.  The multipliers say where the contact went: (λ_i s_i + λ_j s_j)/(λ_i + λ_j) lies
beyond j, so the pair moves on by one row (``shifted_pairs``).

* the rule itself: a pair whose resultant lies beyond one row gives the set shifted that way, and
  a pair with both multipliers positive gives nothing;
* the main job's cable on the post (the default cable, the demo's post, the element mesh auto
  reaches there), solved cold at one of the demo's targets and updated warm to a target 4 updates
  later: a Newton update (IPOPT before), equal to the same targets streamed one by one (small
  steps, the same branch; a cold solve lands on another, 0.23 m away).
"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from dlo_ros.model.problem import GripPose
from dlo_ros.node import demo
from dlo_ros.scene import load_scene, scene_from_dict, scene_to_dict
from dlo_ros.solver import ShapeSolver
from dlo_ros.solver.build.mesh import MeshSpec
from dlo_ros.solver.shape_solver import with_checked_poses
from dlo_ros.solver.update.active_set import shifted_pairs

#: the mesh auto streams on over the post in the main job (4 elements, 37 nodes)
POST_MESH = MeshSpec((0.44448166405796957, 0.46793503712740137, 0.5), (10, 8, 8, 14))
PERIOD = 0.02  # s: the demo driver's rate


def test_a_pair_whose_resultant_lies_past_it_moves_on_by_one_row():
    nlp = SimpleNamespace(obstacle_rows=[np.arange(10, 20)])
    proposed = np.zeros(25, dtype=bool)
    proposed[[2, 14, 15]] = True  # an equality row and the pair {14, 15}
    lam = np.zeros(25)
    lam[14], lam[15] = -1.2, 13.9  # resultant beyond row 15
    (moved,) = shifted_pairs(nlp, lam, proposed)
    assert np.flatnonzero(moved).tolist() == [2, 15, 16]
    lam[14], lam[15] = 13.9, -1.2  # resultant before row 14
    (moved,) = shifted_pairs(nlp, lam, proposed)
    assert np.flatnonzero(moved).tolist() == [2, 13, 14]
    lam[14], lam[15] = 2.0, 3.0  # both push: nothing to shift
    assert shifted_pairs(nlp, lam, proposed) == []
    lam[[14, 15]] = 0.0
    lam[18], lam[19] = -1.0, 2.0  # at the end of the obstacle's rows: no row beyond
    assert shifted_pairs(nlp, lam, proposed) == []


def demo_scene_and_targets():
    d = scene_to_dict(load_scene("default_cable"))
    d["obstacles"] = list(d.get("obstacles", [])) + [dict(demo.POST)]
    scene = scene_from_dict(d)
    targets = []
    for k in range(1, int(demo.duration() / PERIOD) + 1):
        (pl, ql), (pr, qr) = demo.targets_at(k * PERIOD)
        targets.append({"left": GripPose(pl, ql), "right": GripPose(pr, qr)})
    return scene, targets


def test_a_contact_sliding_past_its_rows_on_the_post_is_a_newton_update():
    scene, targets = demo_scene_and_targets()
    start, end = targets[424], targets[428]
    options = replace(scene.options, model="full", obstacle_points="nodes")
    solver = ShapeSolver(
        with_checked_poses(scene.problem, start), options, compile="off", mesh=POST_MESH
    )
    cold = solver.solve()
    assert cold.ok and cold.contact_forces, cold.message  # on the post
    warm = solver.solve(end)
    assert warm.ok and warm.warm_started, warm.message
    assert warm.ipopt_status == "Newton", warm.ipopt_status
    # the same branch reached another way: the four targets one by one, each a small step
    reference = ShapeSolver(
        with_checked_poses(scene.problem, start), options, compile="off", mesh=POST_MESH
    )
    assert reference.solve().ok
    for step in targets[425:429]:
        r = reference.solve(step)
        assert r.ok, r.message
    assert np.max(np.linalg.norm(warm.points - r.points, axis=1)) < 1e-6
