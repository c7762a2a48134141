"""The cold refinement loop (dlo_ros.solver.adapt.loop, #37) on a cable over a post.

A heavy cable clamped at both ends, 0.6 m apart, rests on a horizontal bar (a capsule across the
working plane, so the planar shooting reference ``test/reference/post_contact.py`` is the 3D
answer too; a sphere lets the 'full' model roll off sideways).  The contact is a point force:
the curvature has a kink there, inside the first mesh's one element, so p-refinement converges
only algebraically.

TEST-ONLY estimator: the error is measured against the independent shooting reference, e_k =
∫_{element k} |t − t_ref| ds (their sum bounds the centreline's deviation: both ends are clamped
at the same points), the decay from the solution's coefficients (``adapt.smoothness``) and the
contact point as the kink (``contact_kinks``).  The real estimator
(``solver/results/element_error.py``) replaces it when it lands.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.polynomial import legendre as Leg
from scipy.interpolate import CubicSpline

from dlo_ros.model.problem import GripPose
from dlo_ros.scene import scene_from_dict
from dlo_ros.solver.adapt.loop import refine_until
from dlo_ros.solver.adapt.rule import ElementEstimates, RefinementRule
from dlo_ros.solver.adapt.smoothness import contact_kinks
from dlo_ros.model.elements import ElementMesh
from dlo_ros.solver.build.mesh import MeshSpec
from dlo_ros.solver.results.element_error import coefficient_decay
from dlo_ros.solver.shape_solver import ShapeSolver
from reference import post_contact
from support.post import shooting_reference

LENGTH, BEND, WEIGHT, RADIUS = 1.0, 0.02, 0.5, 0.005
POST, POST_RADIUS, HEIGHT = np.array([0.22, 0.2]), 0.03, 0.5
DELTA = 1e-5 * LENGTH


def bar_scene(order: int = 16):
    grip = {"mode": "clamp", "orientation": [0, 0, 0, 1]}
    return scene_from_dict(
        {
            "name": "bar",
            "frame_id": "world",
            "string": {
                "length": LENGTH,
                "bend_stiffness": BEND,
                "twist_stiffness": 0.015,
                "weight_per_length": WEIGHT,
                "radius": RADIUS,
            },
            "gravity": {"direction": [0, 0, -1]},
            "grips": [
                {"name": "left", "s": 0.0, "position": [0, 0, HEIGHT], **grip},
                {"name": "right", "s": LENGTH, "position": [0.6, 0, HEIGHT], **grip},
            ],
            "obstacles": [
                {
                    "type": "capsule",
                    "name": "bar",
                    "a": [POST[0], -0.5, POST[1]],
                    "b": [POST[0], 0.5, POST[1]],
                    "radius": POST_RADIUS,
                }
            ],
            "solver": {"model": "full", "order": order, "obstacle_slots": 2},
        }
    )


@pytest.fixture(scope="module")
def reference():
    """The shooting solution, from the guess of a cold order-24 solve (its reactions, contact)."""
    sc = bar_scene(24)
    solver = ShapeSolver(sc.problem, sc.options, compile="off")
    result = solver.solve()
    assert result.ok, result.message
    force, torque = result.grips["left"].force, result.grips["left"].torque
    guess = [-force[0], -force[2], torque[1], contact_kinks(solver)[0], 0.6]
    ref = shooting_reference(guess)
    assert ref.residual < 1e-10 and ref.clearance > -1e-9 and ref.push > 0, ref
    return ref


def tangent_error(ref: post_contact.PostContact):
    """TEST-ONLY: e_k = ∫ |t − t_ref| ds over each element (40 Gauss points each)."""
    dx, dz = (CubicSpline(ref.s, ref.points[:, k]).derivative() for k in (0, 1))
    gauss, weights = Leg.leggauss(40)

    def estimator(solver: ShapeSolver, _result) -> ElementEstimates:
        mesh, z = solver.model.mesh, solver.committed_state.z
        errors = []
        for lo, hi in zip(mesh.breakpoints[:-1], mesh.breakpoints[1:]):
            s = lo + 0.5 * (hi - lo) * (gauss + 1)
            want = np.stack([dx(s), 0 * s, dz(s)], axis=1)
            gap = np.linalg.norm(solver.model.tangents_at(z, s) - want, axis=1)
            errors.append(0.5 * (hi - lo) * float(weights @ gap))
        rates = coefficient_decay(mesh, solver.model.node_values(z))[0]
        return ElementEstimates(np.array(errors), rates, contact_kinks(solver))

    return estimator


def deviation(result, ref) -> float:
    return float(np.max(np.linalg.norm(result.points[:, [0, 2]] - ref.at(result.s), axis=1)))


def test_coefficient_decay_tells_smooth_from_kinked():
    mesh = ElementMesh(2.0, [], 15)  # one element: s = τ + 1

    def decay(values):
        return float(coefficient_decay(mesh, values[:, None])[0][0])

    tau = mesh.elements[0].tau
    smooth = np.exp(0.8 * tau)
    kinked = (tau - 0.1) * np.abs(tau - 0.1)  # a jump of t'' (a point force)
    assert decay(smooth) < 0.3 < 0.6 < decay(kinked)
    assert decay(tau**2) == 0.0  # resolved to rounding


def test_the_loop_splits_at_the_contact_and_beats_uniform_p_refinement(reference):
    sc = bar_scene(16)
    rule = RefinementRule(DELTA, min_size=0.01, max_nodes=32, max_unknowns=100)
    estimator = tangent_error(reference)
    out = refine_until(sc.problem, sc.options, estimator, rule, max_rounds=6)
    print([(r.spec, r.unknowns, r.iterations, r.warm_started, r.estimate) for r in out.rounds])
    assert out.converged and out.result.ok, out.reason
    assert deviation(out.result, reference) <= DELTA
    first, *later = out.rounds
    assert first.spec.breakpoints == () and not first.warm_started
    assert later and all(r.warm_started for r in later)
    # split once, at the contact point of the first (coarse) solve
    last = out.rounds[-1]
    assert len(last.spec.breakpoints) == 1
    assert abs(last.spec.breakpoints[0] - reference.s_contact) < 1e-3 * LENGTH
    # streamed on the refined mesh: the right grip 5 mm in and back, warm.  The shape returns
    # only to within what the contact slot's placement tolerance (3e-4 L: a slot stays while its
    # minimum moves less) allows: 2.6e-5 m measured, not 1e-5 L
    solver, level = out.solver, GripPose.checked([0.6, 0, HEIGHT], [0, 0, 0, 1], "right")
    moved = solver.solve({"right": GripPose.checked([0.595, 0, HEIGHT], [0, 0, 0, 1], "right")})
    back = solver.solve({"right": level})
    assert moved.ok and back.ok and moved.warm_started and back.warm_started
    assert np.abs(moved.points - out.result.points).max() > 1e-4
    assert deviation(back, reference) <= 5 * DELTA
    # uniform p-refinement with as many unknowns does not reach the tolerance
    uniform = ShapeSolver(
        sc.problem, sc.options, compile="off", mesh=MeshSpec((), (last.unknowns,))
    )
    flat = uniform.solve()
    assert flat.ok
    assert estimator(uniform, flat).errors.sum() > DELTA
    assert deviation(flat, reference) > DELTA
