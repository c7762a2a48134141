"""The equilibrium residual of a returned shape: the strong-form balance it must satisfy.

Every energy minimum satisfies this balance; the residual measures how far a shape is from it.

For the part [0, s] of the string, the moment that the part beyond s exerts on it, about x(s), is

    m_bal(s) = −Σ_{a: s_a < s} [(x_a − x(s)) × F_a + T_a] − ∫_0^s (x(σ) − x(s)) × D(σ) ĝ dσ

over every point action a before s: grip reactions (F_g, T_g, from the multipliers), point loads
(F_k, M_k) and obstacle contact forces.  The constitutive law gives the same moment from the shape,

    m_c(s) = R diag(Rt, Rf, Rl) Ω      (R = [t d1 d2], Ω the body Darboux vector, Rl = Rf but for
    a strip's string.lateral_bend_stiffness; Rf t × t' without twist),

and the whole string must balance: Σ_a F_a + ∫_0^L D ĝ dσ = 0.  A shape that is an equilibrium has
m_c = m_bal everywhere.  The residual is reported as an equivalent centreline error in metres: the
imbalance δm = m_c − m_bal read as a curvature error δm/Rf, integrated twice along the shape from s
= 0 (a rotation error φ(s) = ∫_0^s δm/Rf dσ, a displacement δx(s) = ∫_0^s φ × t dσ), plus the
deflection a force imbalance ΔF would cause at the tip of a cantilever:

    e = max_s |δx(s)| + |Σ F| L³ / (3 Rf_min).

Pointwise δm oscillates about zero where only the discretisation is at fault and so integrates to
about the centreline error itself; a shape off its equilibrium (a wrong branch, a kink the basis
cannot follow, a load applied wrongly) accumulates.  ``moment`` keeps the pointwise max |δm|.  It
is evaluated on a grid of ``RESIDUAL_POINTS`` intervals refined at the grips, point loads, relative
positions' ends and mesh breakpoints (``wrenches.static_events``), strictly between them; contact
forces carry no moment, so m_bal does not jump where they act.  The weight's integrals use the
model's own quadrature.

The two integrals are taken by ``GAUSS_POINTS``-point Gauss–Legendre rules on each interval between
knots (``ResidualGrid``): a uniform grid, the events above and, where a caller gives them, the
obstacle rows (``wrenches.row_kinks``).  A contact force at a row puts a kink in δm there: on a
string lying along an obstacle δm is a sawtooth between the rows whose integrals nearly cancel,
which a rule blind to the rows aliased (the paper's Fig. 3 strip on its floor, element rows every
2 cm: 4.6e-5 m on 200 midpoints, 9.9e-7 m on 20,000 or with the rows as knots).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
from scipy.sparse import coo_matrix

from ...model.rotations import cross3

#: the smallest error [fraction of L] a converged solve can be verified to: the error estimate
#: (``element_error.py``) reports no less, and a result asked for less is 'unverified'
FLOOR = 1e-10
#: intervals of the residual's uniform base grid (each split further at the events and rows)
RESIDUAL_POINTS = 64
#: Gauss–Legendre points per interval between knots
GAUSS_POINTS = 3


@dataclass(frozen=True)
class PointAction:
    """A force [N] and moment [N·m] acting on the string at arc length s (world frame)."""

    s: float
    position: np.ndarray
    force: np.ndarray
    moment: np.ndarray


@dataclass(frozen=True)
class EquilibriumResidual:
    """The largest moment and force imbalances and the equivalent centreline error.

    Largest moment imbalance [N·m], force imbalance [N] and the equivalent centreline error
    [m].
    """

    moment: float
    force: float
    metres: float


@dataclass(frozen=True)
class ResidualGrid:
    """Gauss–Legendre points on the intervals between ``knots`` [m], and integrals on them.

    ``s``: GAUSS_POINTS points strictly inside each interval (never on a knot, where B′ may be
    one-sided), interval by interval.  ``cumulative`` integrates values given at ``s``.
    """

    knots: np.ndarray

    @property
    def s(self) -> np.ndarray:
        """Return the points [m], GAUSS_POINTS per interval, ascending."""
        xg = _gauss()[0]
        return (self.knots[:-1, None] + np.diff(self.knots)[:, None] * xg[None, :]).ravel()

    def operators(self) -> tuple[coo_matrix, coo_matrix, coo_matrix]:
        """Return (P, Q, E): f P the intervals' integrals, f Q + F E the integrals to the points.

        For values f (3 × K) at ``s``: f P (3 × n) the integrals over the n intervals; with F
        (3 × n) the integrals from 0 to each interval's start, F E + f Q (3 × K) those to each
        point (the Lagrange interpolant of the interval's points integrated).  Sparse: Q is
        block diagonal.
        """
        xg, wg, local = _gauss()
        h = np.diff(self.knots)
        n, q = h.size, xg.size
        point = np.arange(n * q).reshape(n, q)  # the points of interval k: point[k]
        interval = np.repeat(np.arange(n), q)
        P = coo_matrix(((h[:, None] * wg[None, :]).ravel(), (point.ravel(), interval)), (n * q, n))
        # Q[k q + j, k q + i] = h_k L_ij: the point j's value in the integral to point i
        rows = np.broadcast_to(point[:, None, :], (n, q, q)).ravel()
        cols = np.broadcast_to(point[:, :, None], (n, q, q)).ravel()
        values = (h[:, None, None] * local[None, :, :]).ravel()
        Q = coo_matrix((values, (rows, cols)), (n * q, n * q))
        E = coo_matrix((np.ones(n * q), (interval, point.ravel())), (n, n * q))
        return P, Q, E

    def cumulative(self, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return ∫_0^s f dσ at the points (K, 3) and at the knots (n + 1, 3); f (K, 3) at s."""
        xg, wg, local = _gauss()
        h = np.diff(self.knots)
        q = xg.size
        parts = f.reshape(h.size, q, -1)
        sums = h[:, None] * np.einsum("j,kjc->kc", wg, parts)
        at_knots = np.concatenate([np.zeros((1, f.shape[1])), np.cumsum(sums, axis=0)])
        inner = at_knots[:-1, None, :] + h[:, None, None] * np.einsum("ij,kjc->kic", local, parts)
        return inner.reshape(f.shape), at_knots

    def deflection(self, kappa: np.ndarray, tangent: np.ndarray) -> np.ndarray:
        """Return δx = ∫_0^s (∫_0^σ κ) × t dσ [m] at the points, then at the knots (K + n + 1, 3).

        ``kappa`` (K, 3) [1/m] and ``tangent`` (K, 3) at the points (module docstring).
        """
        phi = self.cumulative(kappa)[0]
        return np.vstack(self.cumulative(cross3(phi, tangent)))


@cache
def _gauss() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return GAUSS_POINTS points ξ and weights on [0, 1], and L_ij = ∫_0^ξ_i ℓ_j (ℓ: Lagrange)."""
    nodes, weights = np.polynomial.legendre.leggauss(GAUSS_POINTS)
    xg, wg = 0.5 * (nodes + 1.0), 0.5 * weights
    coefficients = np.linalg.inv(np.vander(xg, GAUSS_POINTS, increasing=True))  # ℓ_j's, by column
    powers = np.arange(1, GAUSS_POINTS + 1)
    local = (xg[:, None] ** powers[None, :] / powers[None, :]) @ coefficients
    return xg, wg, local


def evaluation_grid(
    length: float, events: list[float], points: int = RESIDUAL_POINTS, kinks=()
) -> ResidualGrid:
    """Return the residual's grid: ``points`` uniform intervals split at every event and kink.

    Knots closer than 1e-12 L merge: an event equal to a grid node up to rounding (0.3 and
    0.30000000000000004) would otherwise leave a sliver interval.
    """
    knots = np.unique(
        np.concatenate(
            [
                np.linspace(0.0, length, points + 1),
                np.clip(np.asarray(events, dtype=float), 0.0, length),
                np.clip(np.asarray(kinks, dtype=float), 0.0, length),
            ]
        )
    )
    knots = knots[np.concatenate([[True], np.diff(knots) > 1e-12 * length])]
    knots[-1] = length  # a knot within rounding of the end stands for it
    return ResidualGrid(knots)


@dataclass(frozen=True)
class BalanceInputs:
    """What the balance needs on a grid s (``wrenches.balance_inputs`` makes it for a shape).

    x (K, 3), moment_c (K, 3): positions and constitutive moments at s [m, N·m]; weight (K,) =
    ∫_0^s D dσ [N] and weight_moment (K, 3) = ∫_0^s D x dσ; actions: every point action; gravity:
    unit direction; total_weight = ∫_0^L D dσ [N]; length L [m]; rf_min [N·m²]; rf: Rf at s
    (None: Rf_min everywhere); grid: the ``ResidualGrid`` whose points s are (None: the
    trapezoid rule on s, for a grid given point by point).
    """

    s: np.ndarray
    x: np.ndarray
    moment_c: np.ndarray
    weight: np.ndarray
    weight_moment: np.ndarray
    actions: list[PointAction]
    gravity: np.ndarray
    total_weight: float
    length: float
    rf_min: float
    rf: np.ndarray | None = None
    grid: ResidualGrid | None = None


def moment_imbalance(b: BalanceInputs) -> tuple[np.ndarray, np.ndarray]:
    """Return δm = m_c − m_bal (K, 3) [N·m] on grid s and the net force Σ F [N] (3,).

    The module docstring defines m_bal.
    """
    s, x, actions = b.s, b.x, b.actions
    g = np.asarray(b.gravity, dtype=float)
    # ∫_0^s (x(σ) − x(s)) × D ĝ dσ = (∫ D x) × ĝ − x(s) × ĝ ∫ D
    m_bal = -(cross3(b.weight_moment, g) - cross3(x, g) * b.weight[:, None])
    total = b.total_weight * g
    if actions:
        # Σ_{a: s_a < s} (x_a − x(s)) × F_a + T_a = C(s) − x(s) × F(s), with C and F running sums
        # over the actions sorted by s (C_a = x_a × F_a + T_a): one pass instead of one masked
        # product per action
        order = sorted(range(len(actions)), key=lambda k: actions[k].s)
        s_a = np.array([actions[k].s for k in order])
        pos = np.array([actions[k].position for k in order], dtype=float)
        force = np.array([actions[k].force for k in order], dtype=float)
        moment = np.array([actions[k].moment for k in order], dtype=float)
        c = np.vstack([np.zeros((1, 3)), np.cumsum(cross3(pos, force) + moment, axis=0)])
        f = np.vstack([np.zeros((1, 3)), np.cumsum(force, axis=0)])
        before = np.searchsorted(
            s_a, s, side="left"
        )  # how many actions lie strictly before each s
        m_bal -= c[before] - cross3(x, f[before])
        total = total + f[-1]
    return b.moment_c - m_bal, total


def equilibrium_residual(b: BalanceInputs) -> EquilibriumResidual:
    """Return the residual on grid ``b.s`` (module docstring)."""
    delta, total = moment_imbalance(b)
    s, length, rf_min = b.s, b.length, b.rf_min
    d_m = float(np.max(np.linalg.norm(delta, axis=1))) if len(s) else 0.0
    d_f = float(np.linalg.norm(total))
    if len(s) < 2:
        return EquilibriumResidual(d_m, d_f, d_f * length**3 / (3 * rf_min))
    kappa = delta / (b.rf if b.rf is not None else np.full(len(s), rf_min))[:, None]
    tangent = np.gradient(b.x, s, axis=0)
    if b.grid is None:
        phi = cumulative(kappa, s)
        worst = np.max(np.linalg.norm(cumulative(cross3(phi, tangent), s), axis=1))
    else:
        worst = np.max(np.linalg.norm(b.grid.deflection(kappa, tangent), axis=1))
    metres = float(worst) + d_f * length**3 / (3 * rf_min)
    return EquilibriumResidual(d_m, d_f, metres)


def cumulative(f: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Return ∫ f ds from 0 at every grid point by the trapezoid rule.

    ∫_{s_0}^{s_k} f ds by the trapezoid rule, starting at 0 (plus the first interval from s =
    0).
    """
    steps = 0.5 * (f[1:] + f[:-1]) * np.diff(s)[:, None]
    return np.concatenate([f[:1] * s[0], f[:1] * s[0] + np.cumsum(steps, axis=0)])
