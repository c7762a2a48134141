"""A contact slot's row: the obstacle's reach at the closest approach (build/slot_envelope.py).

Against exact answers: the interpolant's derivative rows on polynomials, and the row's value
against the closest approach of a circle arc past a sphere (at s = 0 by construction), its error
falling as the cube of the slot's distance from it; the point where the row's force acts."""

from __future__ import annotations

import numpy as np
import pytest

from dlo_ros.model.element_basis import CompositeQuadrature
from dlo_ros.model.elements import ElementMesh
from dlo_ros.model.obstacle_types import OBSTACLE_TYPES
from dlo_ros.model.quadrature import ChebyshevQuadrature
from dlo_ros.solver.build.slot_envelope import action_function, envelope_function

CENTRE, RADIUS = np.array([0.0, 0.0, 0.0]), 0.08  # the sphere
R_ARC = 0.5  # the string: an arc of this radius bending away from the sphere, touching it at s = 0


def sphere_params() -> np.ndarray:
    return OBSTACLE_TYPES["sphere"].parse({"center": list(CENTRE), "radius": RADIUS}, "obstacle")


def arc(s: float, gap: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """x, x', x'' of an arc whose closest approach to the sphere is at s = 0, ``gap`` off it."""
    a = s / R_ARC
    x = np.array([R_ARC * np.sin(a), 0.0, RADIUS + gap + R_ARC * (1 - np.cos(a))])
    d1 = np.array([np.cos(a), 0.0, np.sin(a)])
    d2 = np.array([-np.sin(a), 0.0, np.cos(a)]) / R_ARC
    return x, d1, d2


@pytest.mark.parametrize(
    "quad",
    [
        ChebyshevQuadrature(14, 0.7),
        CompositeQuadrature(ElementMesh(1.0, [0.3, 0.55], 12, 8)),
        CompositeQuadrature(ElementMesh(1.0, [0.3, 0.55], 12, 0)),
    ],
    ids=["one polynomial", "elements", "elements, collocated"],
)
def test_the_interpolants_derivative_is_exact_on_polynomials(quad):
    s = np.linspace(0.0, quad.length, 23)
    f = lambda t: 1.0 + 2.0 * t - 3.0 * t**2 + 0.5 * t**3  # noqa: E731
    df = lambda t: 2.0 - 6.0 * t + 1.5 * t**2  # noqa: E731
    assert np.abs(quad.interpolation_matrix(s) @ f(quad.nodes) - f(s)).max() < 1e-12
    assert np.abs(quad.derivative_matrix(s) @ f(quad.nodes) - df(s)).max() < 1e-10


def test_the_row_is_the_reach_at_the_closest_approach():
    """v* at a slot σ off the closest approach: the true max of h + r within 1e-3 of the gap
    error at σ itself, and falling as σ³; at σ = 0 it is h + r and its gradient ∇h."""
    params, gap = sphere_params(), 2e-4
    fn = envelope_function("sphere", 2e-3)
    h = OBSTACLE_TYPES["sphere"].h_at
    true = h(arc(0.0, gap)[0], params)  # the max of h along the arc (at s = 0)
    errors = []
    for sigma in (4e-4, 2e-4, 1e-4):
        x, d1, d2 = arc(sigma, gap)
        value = float(fn(x, d1, d2, params, 0.0)[0])
        plain = h(x, params)
        assert abs(value - true) < 1e-3 * abs(plain - true), (sigma, value, true, plain)
        errors.append(abs(value - true))
    assert errors[1] < errors[0] / 6 and errors[2] < errors[1] / 6, errors
    x, d1, d2 = arc(0.0, gap)
    value, grad, _ = fn(x, d1, d2, params, 0.0)
    normal = (x - CENTRE) / np.linalg.norm(x - CENTRE)
    assert float(value) == pytest.approx(true, abs=1e-15)
    assert np.asarray(grad).ravel() == pytest.approx(np.concatenate([-normal, [0] * 6]), abs=1e-12)


def test_the_force_acts_at_the_closest_approach():
    """The action's shift from σ is the way to the closest approach (to first order); where that
    is capped at the reach Δ, half of it (∂v*/∂v_s)."""
    params = sphere_params()
    for sigma in (1e-4, -3e-4):
        x, d1, d2 = arc(sigma, 1e-4)
        shift, _ = action_function("sphere", 2e-3)(x, d1, d2, params, 0.0)
        assert float(shift) == pytest.approx(-sigma, rel=1e-2)
    # 5 cm away the model's shift is capped at Δ: v* = v + ½ Δ |v_s|, whose gradient moves the
    # force by Δ/2
    x, d1, d2 = arc(0.05, 1e-4)
    shift, _ = action_function("sphere", 2e-3)(x, d1, d2, params, 0.0)
    assert float(shift) == pytest.approx(-1e-3)
