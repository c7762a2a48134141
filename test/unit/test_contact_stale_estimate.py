"""A streamed answer whose contacts are not the checked shape's reports no error estimate.

The main job's cable landing on its post (``dlo_ros.node.demo``, targets 395–425 of its
manoeuvre, checks inline): before, the updates after the landing kept reporting the estimate of
the last shape checked before it (1.4e-4 m, tolerance met) for 13 updates, while an exact
sphere-contact reference (test/reference/sphere_contact.py, a helper's measurement this session)
put the landed shapes 0.04–0.11 m away.  Now an update that presses on other obstacles than the
checked shape, or with a total force on one of them changed by more than
``reach.CONTACT_FORCE_FACTOR``, is unchecked (``estimated_error_m`` None, ``tolerance_met``
None) until the check it starts takes effect.
"""

from __future__ import annotations

from dataclasses import replace

from test_post_last_pose import problem_at, scene, targets

from dlo_ros.solver import make_solver
from dlo_ros.solver.auto.reach import CONTACT_FORCE_FACTOR, pressed_obstacles

FIRST, LAST = 395, 425  # the demo's targets: the cable lands on the post at 409


def test_the_estimate_reported_is_of_a_shape_with_the_same_contacts():
    auto = make_solver(
        problem_at(FIRST), replace(scene().options, update_time_limit=0.0), compile="off", checks="sync"
    )
    try:
        first = auto.solve()
        assert first.ok and first.model.checked and not pressed_obstacles(first)
        forces, reported, landed = {}, {}, None
        for k in range(FIRST + 1, LAST + 1):
            result = auto.solve(targets(k))
            assert result.status == "ok", (k, result.message)
            forces[k] = pressed_obstacles(result)
            model = result.model.as_dict()
            if forces[k] and landed is None:
                landed = k
            if model["estimated_error_m"] is not None:
                reported[k] = k - model["checked_updates_ago"]
            else:
                assert model["tolerance_met"] is None and model["checked"] is False, (k, model)
    finally:
        auto.close()
    assert landed is not None and landed not in reported  # the first update on the post
    # every estimate reported is of a shape pressing on the same obstacles, forces within the factor
    for k, of in reported.items():
        now, then = forces[k], forces.get(of, {})
        assert now.keys() == then.keys(), (k, of, now, then)
        assert all(now[i] <= CONTACT_FORCE_FACTOR * then[i] and then[i] <= CONTACT_FORCE_FACTOR * now[i]
                   for i in now), (k, of, now, then)
    assert any(forces[k] for k in reported)  # checks of landed shapes were reported too
