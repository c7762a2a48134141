"""A contact slot's row: the obstacle's reach at the string's closest approach near the slot.

A slot at arc length σ (``contact/obstacle_slots.py``) with the row v(σ) = h(x(σ)) + r ≤ 0 holds
the string at one material point.  On a curved obstacle that is not enough: a string pressed on a
post can slide along it (a very soft mode: the demo's cable moves about 1 m per m its contact
slides), and held at σ alone it slides until it cuts into the post beside the slot, where a row
of the mesh then takes part of the force (measured: 26 % of it at a row 1–9 mm away, whatever the
mesh, and the shape mm off).  The obstacle's constraint is on the closest approach, max_s v(s) ≤
0, whose curvature holds that mode; its second-order model about σ is

    v* = v + ½ v_s² / D,   v_s = ∇h·x',   v_ss = x'ᵀ ∇²h x' + ∇h·x'',
    D = max(−v_ss, |v_s| / Δ, ε),

with x', x'' the centreline's derivatives at σ (x' = T Pᵀ, x'' = T P'ᵀ: ``tangent_rows``).  At
the closest approach (v_s = 0) v* = v and its gradient is v's: the force acts at σ, as the plain
row's; off it, v* is the quadratic model's maximum, reached at σ + v_s / D, and the gradient's
∂v*/∂v_s ∇v_s term moves the force there to first order (``action_function``).  Δ =
``REACH`` · L bounds that shift; ε keeps D positive.  At a slot's fixed point (σ = s*, where the
rounds of ``update/slot_rounds.py`` put it) v_s = 0 and Δ plays no part; it decides how the
rounds get there.  With Δ = 2 mm a mesh too coarse to place the contact (the main job's cable
landing on its post, 2 elements) cut into the post 1–4 cm beside its slot and the rounds cycled
between the places, 100–800 ms per update; with 2 cm they settle.  Away from its minimum the
quadratic model is no bound: it can hold the string off the obstacle (a strip on a post with
its slot 1 cm off: 5e-5 m clear), so a slot that carries force counts as touching in the rounds
whatever its clearance, and at 4 cm the main job's landing came back unverified (residual 1–2 mm
at δ = 1 mm).  Where the clearance is not convex at σ (−v_ss ≤ |v_s|/Δ)
v* = v + ½ Δ |v_s| is only C⁰ at v_s = 0, and within |v_s| < εΔ its curvature is 1/ε: auto
slots a flat obstacle only at an isolated sag (``obstacle_slots.FLAT_DIP``), where −v_ss > 0.
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from ...model.obstacle_types import OBSTACLE_TYPES

#: D's floor [1/m]: a clearance flat to this curvature at its closest approach adds nothing
FLOOR = 1e-9


#: Δ / L: how far from its slot the row follows the closest approach (module docstring: 2e-3
#: left the rounds cycling on coarse meshes, 4e-2 left the main job's landing unverified)
REACH = 0.02


def shift_bound(length: float) -> float:
    """Return Δ [m]: how far the closest approach may be from its slot (REACH · L)."""
    return REACH * length


@functools.lru_cache(maxsize=None)
def envelope_function(kind: str, reach: float) -> ca.Function:
    """Build (X, X', X'', parameters, r) → [v*, ∇v* (9), ∇²v* (9 × 9)] for obstacle type ``kind``.

    ``reach`` is Δ [m] (module docstring); the derivatives are with respect to (X, X', X'')
    stacked.
    """
    x, d1, d2, po, radius = inputs = _inputs(kind)
    value = envelope_value(kind, x, d1, d2, po, radius, reach)
    u = ca.vertcat(x, d1, d2)
    hess, grad = ca.hessian(value, u)
    return ca.Function(f"dlo_slot_{kind}", list(inputs), [value, grad, ca.densify(hess)])


@functools.lru_cache(maxsize=None)
def value_function(kind: str, reach: float) -> ca.Function:
    """Build (X, X', X'', parameters, r) → v* alone (the rows' values, without derivatives)."""
    x, d1, d2, po, radius = inputs = _inputs(kind)
    value = envelope_value(kind, x, d1, d2, po, radius, reach)
    return ca.Function(f"dlo_slot_{kind}_value", list(inputs), [value])


def _inputs(kind: str) -> tuple:
    """Return the symbols (X, X', X'', the obstacle's parameters, r) of one slot (SX)."""
    x, d1, d2 = ca.SX.sym("x", 3), ca.SX.sym("dx", 3), ca.SX.sym("ddx", 3)
    return x, d1, d2, ca.SX.sym("po", OBSTACLE_TYPES[kind].size), ca.SX.sym("r")


def envelope_value(kind: str, x, d1, d2, po, radius, reach: float):
    """Return v* (module docstring) at x with x' = ``d1``, x'' = ``d2`` (CasADi SX)."""
    h_x, v_s, v_ss = _along(kind, x, d1, d2, po)
    return _reach(h_x + radius, v_s, v_ss, reach)


def _along(kind: str, x, d1, d2, po) -> tuple:
    """Return (h, v_s, v_ss) at x: h and its first two derivatives along the string (SX)."""
    y = ca.SX.sym("y", 3)
    h = OBSTACLE_TYPES[kind].h(y, po)
    hess, grad = ca.hessian(h, y)
    h_x, grad_x, hess_x = ca.Function("h", [y, po], [h, grad, hess])(x, po)
    v_ss = ca.dot(d1, ca.mtimes(hess_x, d1)) + ca.dot(grad_x, d2)
    return h_x, ca.dot(grad_x, d1), v_ss


def _reach(v, v_s, v_ss, reach: float):
    """Return v + ½ v_s² / D, D = max(−v_ss, |v_s| / Δ, ε) (module docstring), Δ = ``reach``."""
    curvature = ca.fmax(ca.fmax(-v_ss, ca.fabs(v_s) / reach), FLOOR)
    return v + 0.5 * v_s * v_s / curvature


@functools.lru_cache(maxsize=None)
def action_function(kind: str, reach: float) -> ca.Function:
    """Build (X, X', X'', parameters, r) → [δ, ∇_X v*]: where a slot's force acts and its line.

    δ = ∂v*/∂v_s: the row's gradient moves the force along the string by that much, to first
    order (v_s/D where D = −v_ss; Δ/2 where the shift is capped, D = |v_s|/Δ); it acts at σ + δ,
    x(σ) + δ x'(σ), and the row's multiplier λ gives the force −λ ∇_X v*, the whole of what the
    row exerts on the centreline (exactly the sum the KKT conditions balance).
    """
    x, d1, d2, po, radius = inputs = _inputs(kind)
    h_x, slope, bend = _along(kind, x, d1, d2, po)
    v_s, v_ss = ca.SX.sym("v_s"), ca.SX.sym("v_ss")
    shift = ca.gradient(_reach(0.0, v_s, v_ss, reach), v_s)
    shift = ca.substitute(shift, ca.vertcat(v_s, v_ss), ca.vertcat(slope, bend))
    value = _reach(h_x + radius, slope, bend, reach)
    return ca.Function(f"dlo_slot_action_{kind}", list(inputs), [shift, ca.gradient(value, x)])


def slot_curve(nlp, tangents, z, p, i: int) -> list:
    """Return [X, X', X''] (3 × K each, CasADi) at obstacle i's slots for the node tangents."""
    out = [ca.mtimes(tangents, nlp.slot_matrix(p, i, part).T) for part in "wtk"]
    out[0] += ca.repmat(z[0:3] * nlp.length, 1, nlp.obstacle_slots)
    return out


def slot_inputs(nlp, p, i: int) -> tuple:
    """Return obstacle i's parameters and the string's radius, one column per slot (CasADi)."""
    lay, K = nlp.params, nlp.obstacle_slots
    return ca.repmat(p[lay[f"obstacle:{i}"]], 1, K), ca.repmat(p[lay["radius"]][0], 1, K)


def slot_contact_points(nlp, kind: str, params, radius: float, z, p, i: int, touch) -> tuple:
    """Return where obstacle i's slots ``touch`` act: (s [m], x (K, 3) [m], ∇_X v* (K, 3)).

    s = σ + δ, x = x(σ) + δ x'(σ) and the force −λ ∇_X v* per slot (``action_function``).
    """
    model, touch = nlp.model, np.asarray(touch, dtype=int)
    if not touch.size:
        return np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))
    sigma = np.asarray(p[nlp.params[f"slots:{i}:s"]])[touch]
    rows = [nlp.slot_matrix(p, i, part)[touch] for part in "wtk"]
    x0 = model.positions_at_rows(z, np.zeros((1, rows[0].shape[1])))
    x, d1, d2 = (model.positions_at_rows(z, w) - x0 * (k > 0) for k, w in enumerate(rows))
    action = action_function(kind, shift_bound(nlp.length)).map(touch.size)
    shift, grad = (np.asarray(a) for a in action(x.T, d1.T, d2.T, params, radius))
    shift = shift.ravel()
    return np.clip(sigma + shift, 0.0, nlp.length), x + shift[:, None] * d1, grad.T
