"""Contact slots (dlo_ros.solver.contact.obstacle_slots, #14): an obstacle row at the string's closest approach.

A heavy cable clamped at both ends rests on a round post off its middle.  Its shape is compared with an
independent shooting solution of the planar elastica touching the post at one point
(``test/reference/post_contact.py``), streamed (the grips lowered onto the post) and solved cold: with the
two slots the centreline is within 0.1 mm of it at order 24, with the 41 samples alone it is
millimetres off (the contact can only sit at a sample).  The placement itself is checked on clearances
with a known minimum.
"""
from __future__ import annotations

import numpy as np
import pytest

from dlo_ros.model.problem import GripPose
from dlo_ros.scene import scene_from_dict
from dlo_ros.solver.contact import obstacle_slots as OSL
from dlo_ros.solver.shape_solver import ShapeSolver
from reference import post_contact

LENGTH, BEND, WEIGHT, RADIUS = 1.0, 0.02, 0.5, 0.005
POST = np.array([0.22, 0.2])  # x, z of the post's centre [m]
POST_RADIUS = 0.03
HEIGHT = 0.5  # both grips end at this height [m], 0.6 m apart
LEVEL = np.array([0.0, 0.0, 0.0, 1.0])


def post_scene(slots: int | None, order: int = 24, model: str = "planar"):
    solver = {"model": model, "order": order, "quadrature_nodes": order + 16}
    if slots is not None:
        solver["obstacle_slots"] = slots
    return scene_from_dict({
        "name": "post", "frame_id": "world",
        "string": {"length": LENGTH, "bend_stiffness": BEND, "twist_stiffness": 0.015,
                   "weight_per_length": WEIGHT, "radius": RADIUS},
        "gravity": {"direction": [0, 0, -1]},
        "grips": [{"name": "left", "s": 0.0, "mode": "clamp", "position": [0, 0, HEIGHT], "orientation": [0, 0, 0, 1]},
                  {"name": "right", "s": 1.0, "mode": "clamp", "position": [0.6, 0, HEIGHT], "orientation": [0, 0, 0, 1]}],
        "obstacles": [{"type": "sphere", "name": "post", "center": [POST[0], 0.0, POST[1]], "radius": POST_RADIUS}],
        "solver": solver})


def lowered(solver: ShapeSolver):
    """The grips lowered from 0.7 m to HEIGHT in 20 warm updates: the cable lands on the post."""
    for k in range(21):
        h = 0.7 - (0.7 - HEIGHT) * k / 20
        result = solver.solve({"left": GripPose(np.array([0.0, 0.0, h]), LEVEL),
                               "right": GripPose(np.array([0.6, 0.0, h]), LEVEL)})
        assert result.ok, (k, result.message)
    return result


def reference_for(result) -> post_contact.PostContact:
    """The shooting solution nearest ``result`` (its reactions and contact point as the guess)."""
    s = np.linspace(0.0, LENGTH, len(result.points))
    xz = result.points[:, [0, 2]]
    k = int(np.argmin(np.linalg.norm(xz - POST, axis=1)))
    force, torque = result.grips["left"].force, result.grips["left"].torque
    push = float(np.linalg.norm(result.contact_forces[0]))
    best = None
    for sign in (1.0, -1.0):
        ref = post_contact.solve(LENGTH, BEND, WEIGHT, [0.0, HEIGHT], 0.0, [0.6, HEIGHT], 0.0, POST, POST_RADIUS,
                                 RADIUS, [-force[0], -force[2], sign * torque[1], s[k], push])
        if ref.push > 0 and (best is None or ref.residual < best.residual):
            best = ref
        if best is not None and best.residual < 1e-10:  # (the other sign's guess ran 2,000
            break  # evaluations without converging: 50 s)
    assert best is not None and best.residual < 1e-10 and best.clearance > -1e-9, best
    return best


def deviation(result, ref: post_contact.PostContact) -> float:
    s = np.linspace(0.0, LENGTH, len(result.points))
    return float(np.max(np.linalg.norm(result.points[:, [0, 2]] - ref.at(s), axis=1)))


@pytest.mark.parametrize("slots", [2, 0], ids=["two slots", "samples only"])
def test_a_cable_on_a_post_matches_the_shooting_reference(slots):
    solver = ShapeSolver(post_scene(slots).problem, post_scene(slots).options, compile="off")
    streamed = lowered(solver)
    assert np.linalg.norm(streamed.contact_forces[0]) > 0.1 and abs(streamed.points[:, 1]).max() == 0.0
    ref = reference_for(streamed)
    if slots:
        assert deviation(streamed, ref) < 1e-4
        assert np.linalg.norm(streamed.contact_forces[0]) == pytest.approx(ref.push, rel=0.01)
    else:  # the contact sits at a sample: millimetres off
        assert deviation(streamed, ref) > 1e-3
    if slots:  # cold, at the final poses: IPOPT lands on the post, the slots are placed on its
        # answer until they stay, and it touches at one point like the reference
        again = ShapeSolver(solver.problem, solver.options, compile="off").solve()
        assert again.ok and not again.warm_started and np.linalg.norm(again.contact_forces[0]) > 0.1, again.message
        assert deviation(again, reference_for(again)) < 1e-4


def test_the_slot_follows_the_contact_of_a_stream():
    """While the cable rests on the post, each update's slot is where its string comes closest to the
    post (within the placement tolerance) and the sample nearest it is switched off."""
    sc = post_scene(2, order=16)
    solver = ShapeSolver(sc.problem, sc.options, compile="off")
    lowered(solver)
    nlp, params = solver.nlp, solver.parameters
    for k in range(10):
        x = 0.6 + 0.004 * k
        r = solver.solve({"right": GripPose(np.array([x, 0.0, HEIGHT - 0.002 * k]), LEVEL)})
        assert r.ok
        state = solver.snapshot()
        slots = params.slots(state.p, 0)
        assert slots.on[0] == 1.0
        s = np.linspace(slots.s[0] - 0.01, slots.s[0] + 0.01, 2001)
        clearance = -solver.problem.obstacles[0].h_many(solver.model.positions(state.z, s)) - RADIUS
        assert abs(s[np.argmin(clearance)] - slots.s[0]) <= OSL.TOLERANCE * LENGTH + 1e-5
        nearest = int(np.rint(slots.s[0] / (nlp.obstacle_s[1] - nlp.obstacle_s[0])))
        assert slots.samples_on[nearest] == 0.0 and slots.samples_on.sum() == len(nlp.obstacle_s) - 1


def test_minima_finds_a_minimum_between_samples_and_none_on_a_flat_contact():
    s = OSL.fine_grid(1.0, 41)
    star = 0.31370

    def bowl(x):
        return 10.0 * (np.asarray(x) - star) ** 2 - 1e-3

    found_s, found_c = OSL.minima(s, bowl(s), 0.025, 0.01, 1.0, bowl)
    assert found_s.size == 1 and abs(found_s[0] - star) < 1e-9 and found_c[0] == pytest.approx(-1e-3)

    def flat(x):  # a string lying on a table: sags between the samples by 1e-9 m
        return 1e-9 * np.cos(2 * np.pi * np.asarray(x) / 0.025)

    assert OSL.minima(s, flat(s), 0.025, 0.01, 1.0, flat)[0].size == 0


def test_on_a_flat_obstacle_minima_finds_an_isolated_touch_only():
    """A half-space: the sagging bottom of a cable touching it (clearance rising 10 (s − s*)²) gets
    a slot; the sag between two rows of a strip lying on it (3e-5 m deep), and a shape through it
    (a cold guess), get none."""
    s = OSL.fine_grid(1.0, 41)
    star = 0.4137

    def bottom(x):
        return 10.0 * (np.asarray(x) - star) ** 2

    found_s, found_c = OSL.minima(s, bottom(s), 0.025, 0.01, 1.0, bottom, flat=True)
    assert found_s.size == 1 and abs(found_s[0] - star) < 1e-9 and abs(found_c[0]) < 1e-12

    def lying(x):  # on the plane from 0.3 to 0.6, sagging 3e-5 m between rows 0.025 apart
        x = np.asarray(x)
        sag = -3e-5 * np.sin(np.pi * (x - 0.3) / 0.025) ** 2
        return np.where((x > 0.3) & (x < 0.6), sag, 10.0 * np.minimum(abs(x - 0.3), abs(x - 0.6)) ** 2)

    assert OSL.minima(s, lying(s), 0.025, 0.01, 1.0, lying, flat=True)[0].size == 0

    def through(x):
        return bottom(x) - 1e-3

    assert OSL.minima(s, through(s), 0.025, 0.01, 1.0, through, flat=True)[0].size == 0
    assert OSL.minima(s, through(s), 0.025, 0.01, 1.0, through)[0].size == 1  # curved: it does


def test_rows_close_to_a_slot_are_switched_off():
    samples = np.linspace(0.0, 1.0, 401)  # 2.5 mm apart
    on = OSL.rows_on(samples, np.array([0.5011]), 1.0)
    off = samples[on == 0]
    assert off.min() > 0.5011 - OSL.CLEAR and off.max() < 0.5011 + OSL.CLEAR and off.size == 2
    coarse = np.linspace(0.0, 1.0, 41)  # 25 mm apart: the nearest row still goes
    assert np.flatnonzero(OSL.rows_on(coarse, np.array([0.5111]), 1.0) == 0).tolist() == [20]


def test_a_slot_keeps_its_index_and_stays_put_within_the_tolerance():
    samples = np.linspace(0.0, 1.0, 41)
    first = OSL.assign((np.array([0.3, 0.71]), np.array([-1e-4, 0.0])), samples, 2, None, 1.0)
    assert first.on.tolist() == [1.0, 1.0] and first.s.tolist() == [0.3, 0.71]
    assert first.samples_on[12] == 0.0 and first.samples_on[28] == 0.0 and first.samples_on.sum() == 39
    # the deeper minimum now is the second one; each keeps its slot, the near one does not move
    nudged = OSL.assign((np.array([0.72, 0.3 + 0.5e-4]), np.array([-2e-4, 0.0])), samples, 2, first, 1.0)
    assert nudged.s.tolist() == [0.3, 0.72] and not nudged.kept
    same = OSL.assign((np.array([0.3 + 0.5e-4, 0.72]), np.array([0.0, 0.0])), samples, 2, nudged, 1.0)
    assert same.kept and same.s.tolist() == [0.3, 0.72]
    # a minimum gone: its slot empties, and the sample under it is on again
    gone = OSL.assign((np.array([0.3]), np.array([0.0])), samples, 2, same, 1.0)
    assert gone.on.tolist() == [1.0, 0.0] and gone.samples_on[29] == 1.0


def test_a_mapped_slot_takes_the_force_of_the_source_slot_nearest_it():
    """``carried_slot``: the nearest source slot within CARRIED·L (a mapped minimum 0.3 mm from
    its source, which the old window of TOLERANCE·L = 0.3 mm on a 1 m string missed), else none."""
    length, source = 1.0, np.array([0.2, 0.49759])
    assert OSL.carried_slot(source, 0.4979, length) == 1
    assert OSL.carried_slot(source, 0.2 - 0.9 * OSL.CARRIED, length) == 0
    assert OSL.carried_slot(source, 0.35, length) is None  # 15 cm from both: another contact
    assert OSL.carried_slot(np.zeros(0), 0.5, length) is None
    assert OSL.carried_slot(source, 0.4979, 2.0) == 1  # the window scales with L
    assert OSL.carried_slot(source, 0.2 + 1.1 * OSL.CARRIED, length) is None
