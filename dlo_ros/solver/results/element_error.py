"""A per-element a-posteriori error estimate of a spectral-element solution (issue #37).

Two ingredients, both read from the solution itself (no second solve):

* **the strong-form residual, per element.**  ``residual.py`` turns the moment imbalance
  δm = m_c − m_bal into an equivalent centreline error by integrating it twice from s = 0:
  φ(s) = ∫_0^s δm/Rf dσ, δx(s) = ∫_0^s φ × t dσ.  Both integrals are linear in δm, so δx is the
  sum of the displacements δx_e caused by each element's own imbalance (δm restricted to
  element e).  ``per_element_m`` is η_e = max_s |δx_e(s)|, the centreline error element e
  contributes anywhere along the string; max_s |δx| ≤ Σ η_e.
* **the decay of each element's spectral coefficients.**  The nodal values of a field on
  element e are the polynomial Σ_k a_k P_k(τ) (Legendre, τ ∈ [−1, 1]); ``smoothness`` is the
  geometric rate ρ_e fitted to |a_k| over the upper half of k (a_k ≈ C ρ^k).  A smooth field's
  coefficients fall geometrically (ρ < 1, the faster the smaller ρ); a kink inside the element
  (a contact or a point load not at a breakpoint: a jump in a derivative of the tangent) makes
  them fall only algebraically, ρ near 1 on any element size.  ``split`` marks the elements with
  ρ > ``SMOOTH_RATE`` = 0.6 (Mavriplis' criterion, a_k ≈ C e^{−σk}, with σ < 0.51 instead of
  his σ < 1: a twisted 3D solution decays at ρ ≈ 0.52 on one element): h-refine (split)
  those, p-refine (more nodes) the rest.  The fields are taken generically: nodal values
  on ``model.mesh`` (tangent or quaternion components of the director model, φ of a planar
  one), ``coefficient_decay``.

The global ``estimate_m`` bounds max_s |x(s) − x_exact(s)|: the residual's displacement
max_s |δx(s)| (plus the cantilever deflection |Σ F| L³/(3 Rf_min) of a force imbalance), times
``SAFETY`` (``KINK_SAFETY`` when an element holds a kink), and never below ``FLOOR`` · L.  The
residual integrated from s = 0 reproduces the true error of a smooth, resolved solution to within
a factor 0.95–1.5 (its pointwise δm oscillates about zero where only the basis is at fault); the
factor covers the rest, and the error a contact's position carries, which the integration from
s = 0 sees only in part.  The floor is the accuracy a converged solve can be held to (IPOPT's and
the Newton updates' tolerances): an exact solution (a mid-moment cantilever, a straight string)
reports FLOOR · L, not zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.polynomial import legendre as Leg

from ...model.elements import ElementMesh, element_mesh_of
from ...model.problem import Problem
from ..state import SolverState
from .outputs import ShapeOutputs
from .residual import FLOOR, GAUSS_POINTS, moment_imbalance
from .wrenches import balance_inputs

#: the estimate is the residual's centreline error times this (module docstring)
SAFETY = 2.0
#: the safety factor when an element holds a kink (``split``): a contact inside an element
#: moves where the post pushes, an error the residual integrated from s = 0 sees only in part
#: (0.35–0.55 of the true error on the post of test_element_error.py)
KINK_SAFETY = 4.0
#: fitted coefficient rate above which an element holds a kink (split it).  Measured: smooth
#: solutions 0.1–0.56 at every order 6–32 (a clamp–clamp 3D twist the highest), an element
#: holding a contact 0.61 (12 nodes) rising to 0.88 (32 nodes): algebraic decay tends to 1
SMOOTH_RATE = 0.6
#: coefficients below this fraction of an element's largest are below a solve's accuracy
NOISE = 1e-8
#: points of the residual's grid (GAUSS_POINTS per interval): per global node, and at least:
#: δm oscillates with the basis's degree (a trapezoid rule over 8 per node overstated the
#: centreline error of a clamp–clamp 3D solve at order 24 six-fold)
POINTS_PER_NODE, MIN_POINTS = 48, 1600


@dataclass(frozen=True)
class ElementErrors:
    """The error estimate of one solution on its element mesh (module docstring).

    per_element_m (E,) [m]: η_e, the centreline error element e's imbalance causes; smoothness
    (E,): the fitted geometric rate ρ_e of its Legendre coefficients (0: resolved to rounding);
    tail (E,): the size of its last coefficient relative to its largest; estimate_m [m]: the
    global bound of max_s |x(s) − x_exact(s)|; residual_m [m]: the residual's centreline error
    before the safety factor and floor; breakpoints (E + 1,) [m] and counts (E,): the mesh.
    """

    per_element_m: np.ndarray
    smoothness: np.ndarray
    tail: np.ndarray
    estimate_m: float
    residual_m: float
    breakpoints: np.ndarray
    counts: tuple[int, ...]

    @property
    def split(self) -> np.ndarray:
        """Elements whose coefficients decay too slowly for a smooth field (h-refine these)."""
        return self.smoothness > SMOOTH_RATE

    @property
    def worst(self) -> int:
        """The element that contributes the largest error."""
        return int(np.argmax(self.per_element_m))


def legendre_coefficients(mesh: ElementMesh, values: np.ndarray) -> list[np.ndarray]:
    """Return each element's Legendre coefficients (n_e, c) of nodal values (N, c) on mesh."""
    values = np.asarray(values, dtype=float).reshape(mesh.count, -1)
    out = []
    for e, el in enumerate(mesh.elements):
        rows = values[mesh.first[e] : mesh.first[e] + el.count]
        # LGL nodes are unisolvent for degree n − 1: the interpolant's coefficients
        out.append(np.linalg.solve(Leg.legvander(el.tau, el.count - 1), rows))
    return out


def coefficient_decay(mesh: ElementMesh, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return per element the fitted rate ρ and the relative last coefficient of nodal values.

    values (N, c): any field's nodal values on mesh (components as columns).  |a_k| is the norm
    of the k-th coefficient over the components; ρ is exp of the least-squares slope of
    log |a_k| over k ≥ n/2 (at least the last three), leaving out coefficients below
    ``NOISE`` · max |a|.  ρ = 0 when none is left (the field is resolved to rounding).
    """
    rates, tails = [], []
    for coef in legendre_coefficients(mesh, values):
        a = np.linalg.norm(coef, axis=1)
        scale = float(a.max())
        n = a.size
        k = np.arange(min(n // 2, n - 3), n) if n >= 3 else np.arange(n)
        k = k[k >= 1]
        keep = k[a[k] > NOISE * scale] if scale > 0 else k[:0]
        tails.append(float(a[-1] / scale) if scale > 0 else 0.0)
        if keep.size < 2:
            rates.append(0.0)
            continue
        slope = np.polyfit(keep, np.log(a[keep]), 1)[0]
        rates.append(float(np.exp(slope)))
    return np.array(rates), np.array(tails)


def nodal_fields(model, z: np.ndarray) -> np.ndarray:
    """Return the nodal values (N, c) of an element model's rotation fields.

    The director model's quaternion or tangent components; a Ritz model of basis 'elements': its
    angle fields' coefficients, which are their nodal values (φ, and θ, ψ when unknowns).
    """
    if hasattr(model, "node_values"):
        return np.asarray(model.node_values(z))
    names = [n for n in ("phi", "theta", "psi") if model.coefficients(z, n) is not None]
    return np.stack([np.asarray(model.coefficients(z, n)) for n in names], axis=1)


def element_errors(
    outputs: ShapeOutputs,
    problem: Problem,
    state: SolverState,
    current: Problem | None = None,
    contacts: tuple[float, ...] = (),
) -> ElementErrors:
    """Return the error estimate of the element-model solution ``state`` solving ``problem``.

    outputs: the solver's ``ShapeOutputs`` (its NLP: a ``DirectorModel``, or a ``RitzModel`` of
    basis 'elements', on an ``ElementMesh``); current: the scene whose grips anchor the wrenches'
    frames (default ``problem``); contacts: arc lengths [m] of known contact points (a kink of
    the curvature): one strictly inside an element flags it as ``split`` does (``KINK_SAFETY``),
    also where its coefficients still decay fast (a point force on a coarse shape).
    """
    nlp = outputs.nlp
    model = nlp.model
    mesh = element_mesh_of(model)
    if mesh is None:
        raise ValueError(
            "element_errors: the model has no element mesh (the director model and basis "
            "'elements' have)"
        )
    grips, actions, lam_si = outputs.point_actions(problem, current or problem, state)
    intervals = max(MIN_POINTS, POINTS_PER_NODE * mesh.count) // GAUSS_POINTS
    balance = balance_inputs(nlp, problem, state.z, grips, actions, lam_si, points=intervals)
    grid = balance.grid
    assert grid is not None  # balance_inputs gives its grid
    s, x, length, rf_min = balance.s, balance.x, balance.length, balance.rf_min
    rf = balance.rf if balance.rf is not None else np.full(len(s), rf_min)
    delta, force = moment_imbalance(balance)
    kappa = delta / rf[:, None]
    tangent = np.gradient(x, s, axis=0)
    which = mesh.element_of(s)
    total = np.zeros((len(s) + grid.knots.size, 3))
    per = np.zeros(mesh.element_count)
    for e in range(mesh.element_count):
        dx = grid.deflection(np.where((which == e)[:, None], kappa, 0.0), tangent)
        per[e] = float(np.max(np.linalg.norm(dx, axis=1)))
        total += dx
    lever = float(np.linalg.norm(force)) * length**3 / (3 * rf_min)
    residual = float(np.max(np.linalg.norm(total, axis=1))) + lever
    rates, tails = coefficient_decay(mesh, nodal_fields(model, state.z))
    inside = [s for s in contacts if np.min(np.abs(mesh.breakpoints - s)) > 1e-9 * length]
    safety = KINK_SAFETY if np.any(rates > SMOOTH_RATE) or inside else SAFETY
    return ElementErrors(
        per_element_m=per,
        smoothness=rates,
        tail=tails,
        estimate_m=max(safety * residual, FLOOR * length),
        residual_m=residual,
        breakpoints=mesh.breakpoints.copy(),
        counts=tuple(mesh.counts),
    )
