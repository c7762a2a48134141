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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model.rotations import cross3

RESIDUAL_POINTS = 200


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


def evaluation_grid(
    length: float, events: list[float], points: int = RESIDUAL_POINTS
) -> np.ndarray:
    """Return the midpoints of a grid of ``points`` intervals refined at every event.

    Midpoints of a grid of ``points`` intervals refined at every event arc length (never on
    one). Nodes closer than 1e-12 L merge: an event equal to a grid node up to rounding (0.3 and
    0.30000000000000004) would otherwise leave a midpoint on the event itself.
    """
    grid = np.unique(
        np.concatenate([np.linspace(0.0, length, points + 1), np.clip(events, 0.0, length)])
    )
    grid = grid[np.concatenate([[True], np.diff(grid) > 1e-12 * length])]
    return 0.5 * (grid[1:] + grid[:-1])


@dataclass(frozen=True)
class BalanceInputs:
    """What the balance needs on a grid s (``wrenches.balance_inputs`` makes it for a shape).

    x (K, 3), moment_c (K, 3): positions and constitutive moments at s [m, N·m]; weight (K,) =
    ∫_0^s D dσ [N] and weight_moment (K, 3) = ∫_0^s D x dσ; actions: every point action; gravity:
    unit direction; total_weight = ∫_0^L D dσ [N]; length L [m]; rf_min [N·m²]; rf: Rf at s
    (None: Rf_min everywhere).
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
    phi = cumulative(kappa, s)
    dx = cumulative(cross3(phi, tangent), s)
    metres = float(np.max(np.linalg.norm(dx, axis=1))) + d_f * length**3 / (3 * rf_min)
    return EquilibriumResidual(d_m, d_f, metres)


def cumulative(f: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Return ∫ f ds from 0 at every grid point by the trapezoid rule.

    ∫_{s_0}^{s_k} f ds by the trapezoid rule, starting at 0 (plus the first interval from s =
    0).
    """
    steps = 0.5 * (f[1:] + f[:-1]) * np.diff(s)[:, None]
    return np.concatenate([f[:1] * s[0], f[:1] * s[0] + np.cumsum(steps, axis=0)])
