"""Grip reactions and the equilibrium residual of a solution.

A grip's reaction (the wrench the gripper exerts ON the string, world frame, about the grip point):

* force F = −Σ_rows λ_position a_row (the position rows' multipliers in SI along their axes);
* torque T from the orientation rows' multipliers μ: director models T = −Σ_r μ_r ∂g_r/∂θ with
  ∂(t·a)/∂θ = t × a; the planar model T = μ_φ n; Euler models solve J_aᵀ T = −μ_a for the held
  angles a (J_a = ∂ω/∂ȧ), with T·ζ = 0 when the twist is free, and at the Euler pole (where φ and ψ
  turn about one axis) T = ∓M at an end clamp, M = Q diag(Rf, Rf, Rt) ω the internal moment.

``equilibrium`` evaluates the strong-form residual of ``residual.py`` from the shape, the
constitutive moment and these reactions.  ``frames_of(z, s)`` is the solver's material-frame
function (``frames.frames`` bound to its NLP and scene), for the torque at an Euler pole.
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np

from ...model.problem import Grip, Problem, StringProperties
from ...model.rotations import cross3, quat_to_matrix
from ..build.frames import euler_angles_at, node_frame
from ..build.nlp import StringNLP
from .residual import (
    RESIDUAL_POINTS,
    BalanceInputs,
    PointAction,
    ResidualGrid,
    evaluation_grid,
)
from .result import GripWrench

FramesOf = Callable[[np.ndarray, np.ndarray], np.ndarray]


def wrench(
    nlp: StringNLP,
    string: StringProperties,
    frames_of: FramesOf,
    grip: Grip,
    z: np.ndarray,
    lam_si: np.ndarray,
) -> GripWrench:
    """Return the reaction at ``grip`` of solution z with the SI multipliers ``lam_si``.

    The reaction at ``grip`` of solution z with the SI multipliers ``lam_si`` (see the module
    docstring).
    """
    rows = nlp.grip_rows[grip.name]
    force = -nlp.grip_axes[grip.name].T @ lam_si[rows["position"]]
    torque: np.ndarray = np.zeros(3)
    if rows["angles"] and nlp.director:
        # T = ∂U/∂θ = −Σ_r λ_r ∂g_r/∂θ with ∂(t·a)/∂θ = t × a and ∂(d1·b)/∂θ = d1 × b
        t, d1 = node_frame(nlp, z, grip.s)
        torque = director_torque(
            t, d1, quat_to_matrix(grip.pose.orientation), lam_si[rows["angles"]]
        )
    elif rows["angles"] and nlp.planar:
        # only φ is held: the reaction torque is along the plane normal, n·T = μ_φ
        torque = lam_si[rows["angles"][0]] * nlp.r0[:, 2]
    elif rows["angles"]:
        phi, theta, _ = euler_angles_at(nlp, z, grip.s)
        r0 = nlp.r0
        j_phi = -r0[:, 2]
        sp, cp, st, ct = math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta)
        j_theta = -(r0 @ np.array([sp, cp, 0.0]))  # −R0 Rz(−φ) e_y
        tangent = r0 @ np.array([-st * cp, st * sp, ct])  # R0 Rz(−φ) Ry(−θ) e_z
        mu = lam_si[rows["angles"]]
        a_rows = [j_phi, j_theta]
        rhs = [-mu[0], -mu[1]]
        if len(mu) == 3:
            a_rows.append(-tangent)
            rhs.append(-mu[2])
        else:
            a_rows.append(tangent)
            rhs.append(0.0)
        a = np.array(a_rows)
        solved = solve_unit_rows(a, rhs)
        if solved is not None:
            torque = solved
        elif grip.s in (0.0, string.length):
            # Euler pole (θ = 0 or π): φ and ψ rotate about the same axis, so the multipliers
            # cannot give the torque; use the internal moment the clamp balances instead
            torque = end_moment(nlp, string, frames_of, z, grip.s)
        else:
            torque = np.linalg.lstsq(a, np.array(rhs), rcond=None)[0]
    return GripWrench(force=force, torque=torque)


def director_torque(
    t: np.ndarray, d1: np.ndarray | None, target: np.ndarray, lam: np.ndarray
) -> np.ndarray:
    """Return the torque T [N·m] of a director model's grip from its orientation rows.

    T = −(λ0 t × a1 + λ1 t × a2 [+ λ2 d1 × a2]) [N·m]: the torque of a director model's grip
    from its orientation rows' SI multipliers ``lam`` (2 or 3), the node's frame (t, d1) and the
    grip's target frame ``target`` = [a0 a1 a2] (columns).  Bilinear in ((t, d1), λ), so its
    derivative is ``director_torque(dt, dd1, target, λ) + director_torque(t, d1, target, dλ)``
    (``sensitivity.py``).
    """
    a1, a2 = target[:, 1], target[:, 2]
    torque = -(lam[0] * cross3(t, a1) + lam[1] * cross3(t, a2))
    if len(lam) == 3:
        assert d1 is not None  # a third orientation row (the twist) comes with d1
        torque -= lam[2] * cross3(d1, a2)
    return torque


def end_moment(
    nlp: StringNLP, string: StringProperties, frames_of: FramesOf, z: np.ndarray, s_end: float
) -> np.ndarray:
    """Return the torque [N·m] a clamp at an end of the string exerts.

    Torque [N·m] a clamp at an end exerts: −M(0) at s = 0, +M(L) at s = L, where M = Q diag(Rf,
    Rf, Rt) ω is the internal moment and ω = axial(Qᵀ Q') the Darboux vector (Q' by a second-order
    one-sided difference; Q(s) is smooth even where the Euler angles are not).
    """
    h = 1e-4 * string.length
    sign = 1.0 if s_end > 0 else -1.0
    s = np.array([s_end, s_end - sign * h, s_end - 2 * sign * h])
    q = frames_of(z, s)
    dq = sign * (3 * q[0] - 4 * q[1] + q[2]) / (2 * h)
    skew = q[0].T @ dq
    omega = 0.5 * np.array(
        [skew[2, 1] - skew[1, 2], skew[0, 2] - skew[2, 0], skew[1, 0] - skew[0, 1]]
    )
    rt = float(string.twist_stiffness(np.array([s_end]))[0]) if nlp.model.layout.twist else 0.0
    rf = float(string.bend_stiffness(np.array([s_end]))[0])
    moment = q[0] @ (np.array([rf, rf, rt]) * omega)
    return sign * moment


def solve_unit_rows(a: np.ndarray, rhs: list[float]) -> np.ndarray | None:
    """Solve a x = rhs for a 3×3 ``a`` of unit rows by Cramer's rule (None when singular).

    x with a x = rhs for a 3×3 ``a`` of unit rows by Cramer's rule, x = Σ_k rhs_k (a_{k+1} ×
    a_{k+2}) / det;
    None when |det| ≤ 1e-8 (unit rows: nearly dependent).  Plain floats: numpy's cross and solve
    cost more than the arithmetic on 3-vectors.
    """
    (a0, a1, a2), (b0, b1, b2) = a.tolist(), rhs

    def cross(u, v):
        return (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])

    c0, c1, c2 = cross(a1, a2), cross(a2, a0), cross(a0, a1)
    det = a0[0] * c0[0] + a0[1] * c0[1] + a0[2] * c0[2]
    if abs(det) <= 1e-8:
        return None
    return np.array([(b0 * c0[k] + b1 * c1[k] + b2 * c2[k]) / det for k in range(3)])


def static_events(nlp: StringNLP, problem: Problem) -> list[float]:
    """Return the arc lengths [m] the residual's grid is refined at.

    The arc lengths [m] the residual's grid is refined at: grips, point loads, the relative
    positions' ends and (element models) the mesh breakpoints.  Fixed by the NLP's structure, so
    that the grid is too (``output_function.py`` evaluates on it).  Contact forces (obstacles,
    self-contact) carry no moment: the balance moment only bends where they act, it does not jump,
    so the grid need not follow them.
    """
    events = [g.s for g in problem.grips] + [ld.s for ld in problem.loads]
    events += problem.relative_ends()
    if nlp.model.mesh is not None:  # element models: B' is one-sided at the breakpoints
        events += list(nlp.model.mesh.breakpoints)
    return events


def row_kinks(nlp: StringNLP) -> np.ndarray:
    """Return the obstacle rows' arc lengths [m]: the residual's grid is split at them.

    A row's contact force kinks the balance moment there; the rows sit at fixed s (samples or
    the mesh's nodes), so the grid stays fixed by the NLP's structure.  Contact slots move with
    the parameters and are not among them.
    """
    return np.unique(nlp.obstacle_s) if nlp.obstacle_rows else np.zeros(0)


def residual_grid(nlp: StringNLP, problem: Problem, points: int = RESIDUAL_POINTS) -> ResidualGrid:
    """Return the residual's grid of ``nlp`` (``residual.evaluation_grid``): both paths use it."""
    events = static_events(nlp, problem)
    return evaluation_grid(problem.string.length, events, points, row_kinks(nlp))


def relative_forces(nlp: StringNLP, lam_si: np.ndarray) -> list[np.ndarray]:
    """Return, per relative position, the force [N] its rows exert on the string at s_b.

    Per relative position, the force [N] its rows exert on the string at s_b, F_b = −Σ_r λ_r c_r
    (the position rows' rule, ``wrench``); the string takes −F_b at s_a.
    """
    return [-nlp.relative_axes.T @ lam_si[rows] for rows in nlp.relative_rows]


def balance_inputs(
    nlp: StringNLP,
    problem: Problem,
    z: np.ndarray,
    grips: dict[str, GripWrench],
    contacts: Sequence[PointAction] = (),
    lam_si: np.ndarray | None = None,
    points: int = RESIDUAL_POINTS,
) -> BalanceInputs:
    """Return what the strong-form balance of shape z needs (``residual.BalanceInputs``).

    The grid, the shape and its constitutive moment on it, and every point action: the grip
    reactions ``grips``, the obstacle ``contacts`` and, given the SI multipliers ``lam_si``, the
    relative positions' reactions.  ``equilibrium_residual`` of it is the shape's residual;
    ``element_error.py`` reads the imbalance per element; ``points``: the grid's uniform
    intervals (``residual_grid``).
    """
    m, st, L = nlp.model, problem.string, problem.string.length
    grip_s = {g.name: g.s for g in problem.grips}
    grid = residual_grid(nlp, problem, points)
    s = grid.s
    nodes = m.quad.nodes
    rel_s = problem.relative_ends() if lam_si is not None else []
    point_s = np.array(list(grip_s.values()) + [ld.s for ld in problem.loads] + rel_s)
    # one evaluation of the shape for the grid, the quadrature nodes and the point actions
    s_all = np.concatenate([s, nodes, point_s])
    x_all = m.positions(z, s_all)
    x, x_nodes, point_x = np.split(x_all, [len(s), len(s) + len(nodes)])
    rf = st.bend_stiffness(s)
    if nlp.director and m.layout.frame:
        frames = m.pose_frames(z, s)
        rl = st.lateral_stiffness(s) if m.lateral else rf  # a strip's stiffness about d2
        c = np.stack([st.twist_stiffness(s), rf, rl], axis=1)
        moment_c = np.einsum("kij,kj->ki", frames, c * m.curvature(z, s))
    elif nlp.director:
        moment_c = rf[:, None] * m.world_curvature(z, s)
    else:
        moment_c = euler_moments(nlp, z, s, rf, st.twist_stiffness(s))
    d_nodes = st.weight_per_length(nodes)
    w = m.position_matrix(s_all)[: len(s)]  # remembered by positions(z, s_all)
    actions = [
        PointAction(grip_s[name], point_x[k], wr.force, wr.torque)
        for k, (name, wr) in enumerate(grips.items())
    ]
    for k, ld in enumerate(problem.loads):
        moment = np.asarray(ld.moment, dtype=float)
        if not nlp.director:  # the Euler models apply the moment's component along n only
            n = nlp.r0[:, 2]
            moment = np.dot(moment, n) * n
        actions.append(
            PointAction(ld.s, point_x[len(grips) + k], np.asarray(ld.force, dtype=float), moment)
        )
    if rel_s and lam_si is not None:  # rel_s is empty without lam_si
        first = len(grips) + len(problem.loads)
        for k, (rel, force) in enumerate(
            zip(problem.relative_positions, relative_forces(nlp, lam_si))
        ):
            actions += [
                PointAction(rel.s_a, point_x[first + 2 * k], -force, np.zeros(3)),
                PointAction(rel.s_b, point_x[first + 2 * k + 1], force, np.zeros(3)),
            ]
    total = float(m.quad.weights @ d_nodes)
    return BalanceInputs(
        s,
        x,
        moment_c,
        w @ d_nodes,
        w @ (d_nodes[:, None] * x_nodes),
        actions + list(contacts),
        problem.gravity_unit,
        total,
        L,
        st.bend_stiffness.minimum,
        rf,
        grid,
    )


def euler_moments(
    nlp: StringNLP, z: np.ndarray, s: np.ndarray, rf: np.ndarray, rt: np.ndarray
) -> np.ndarray:
    """Return m = Q diag(Rf, Rf, Rt) Qᵀ ω [N·m] of an Euler model at arc lengths s.

    m = Q diag(Rf, Rf, Rt) Qᵀ ω [N·m] of an Euler model at arc lengths s, from the angles and
    their s-derivatives (no frames, no differences).  For Q = R0 Rz(−φ) Ry(−θ) Rz(−ψ) the Darboux
    vector is

        ω = R0 a − ψ' ζ,   a = −φ' e_z − θ' (sin φ, cos φ, 0),   ζ = R0 (−cos φ sin θ, sin φ sin θ,
        cos θ),

    so with ω·ζ = −φ' cos θ − ψ' (the twist rate):  m = Rf (R0 a − (a·ζ_0) ζ) + Rt (ω·ζ) ζ,  ζ_0 =
    R0ᵀ ζ. Rt = 0 where the twist is not modelled (the frames then carry no twist moment).
    """
    f = nlp.model.fields(z, np.asarray(s, dtype=float), ("phi", "theta", "psi"))
    phi, dphi, theta, dtheta = f["phi"], f["dphi"], f["theta"], f["dtheta"]
    sp, cp, st, ct = np.sin(phi), np.cos(phi), np.sin(theta), np.cos(theta)
    a = np.stack([-dtheta * sp, -dtheta * cp, -dphi], axis=1)
    zeta0 = np.stack([-cp * st, sp * st, ct], axis=1)
    bend = a - np.einsum("ki,ki->k", a, zeta0)[:, None] * zeta0
    moment = rf[:, None] * bend
    if nlp.model.layout.twist:
        moment += (rt * (-dphi * ct - f["dpsi"]))[:, None] * zeta0
    return moment @ nlp.r0.T
