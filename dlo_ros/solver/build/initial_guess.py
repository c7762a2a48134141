"""The start of a cold solve: a buckled shape that meets the grips.

Between the outermost grips a and b the tangent turns by β(s) = −α sin(2πu), u = (s − s_a)/(s_b −
s_a), with α the root of J0(α) = chord/span, so the guess has the grips' chord; the buckle bends
toward gravity (a hanging cable's sag).  A single grip gives a straight string along its tangent.
The piecewise-linear interpolant of the misfits at the grips is then added, so the guess meets
every held angle or tangent (a guess that breaks the clamps lets IPOPT wander into loops), and x0
puts the first grip on its target.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import j0

from ...model.transport import transported_frames
from ...model.problem import Problem
from ...model.rotations import quat_to_matrix
from .nlp import StringNLP
from .parameters import ProblemParameters


def initial_guess(nlp: StringNLP, parameters: ProblemParameters, problem: Problem) -> np.ndarray:
    """Return the buckled initial guess z (see the module docstring).

    The buckled guess z (see the module docstring); ``parameters`` packs the grips' angle
    targets.
    """
    if nlp.director:
        return director_guess(nlp, problem)
    m, lay = nlp.model, nlp.model.layout
    nodes = m.quad.nodes
    grips = sorted(problem.grips, key=lambda g: g.s)
    a, b = grips[0], grips[-1]
    r0 = nlp.r0
    ring = False
    if len(grips) >= 2 and np.linalg.norm(b.pose.position - a.pose.position) > 1e-9:
        chord = b.pose.position - a.pose.position
        span = b.s - a.s
        ratio = min(1.0, np.linalg.norm(chord) / span)
        alpha = inverse_j0(float(ratio))
        d = chord / np.linalg.norm(chord)
    else:
        d = quat_to_matrix(a.pose.orientation)[:, 0]
        alpha, span = 0.0, (b.s - a.s if len(grips) >= 2 else 1.0)
        ring = (
            len(grips) >= 2
        )  # the outer grips at one point: a ring through it (as director_guess)
    local = r0.T @ d
    theta0 = float(np.arccos(np.clip(local[2], -1, 1)))
    phi0 = float(np.arctan2(local[1], -local[0])) if np.hypot(local[0], local[1]) > 1e-12 else 0.0
    u = np.clip((nodes - a.s) / span, 0.0, 1.0)
    wave = 2 * np.pi * u if ring else alpha * np.sin(2 * np.pi * u)
    # bend toward gravity, within the plane of the chord and gravity; a planar model bends in φ
    g = problem.gravity_unit
    down_perp = g - np.dot(g, d) * d
    phi, theta = np.full_like(nodes, phi0), np.full_like(nodes, theta0)
    bend_in_phi = lay.planar or (np.linalg.norm(down_perp) > 1e-9 and abs(np.sin(theta0)) > 0.3)
    if bend_in_phi:
        # dζ/dφ at (φ0, θ0): +φ turns the tangent toward this direction
        dz_dphi = r0 @ np.array(
            [np.sin(theta0) * np.sin(phi0), np.sin(theta0) * np.cos(phi0), 0.0]
        )
        sign = np.sign(np.dot(dz_dphi, down_perp)) or 1.0
        phi = phi0 + sign * wave
    else:
        theta = theta0 + wave
    z = np.zeros(lay.size)
    fit = lambda f: np.linalg.lstsq(m.B, f, rcond=None)[0]  # noqa: E731
    z[lay.slice("phi")] = fit(phi)
    if not lay.planar:
        z[lay.slice("theta")] = fit(theta)
    # bend the guess so it meets every held angle: add the piecewise-linear interpolant of the
    # residuals at the grips
    p = parameters.pack(problem, z, slots=False)
    fields = {"phi": phi, "theta": theta, "psi": np.zeros_like(nodes)}
    for k, name in enumerate(("phi", "theta", "psi")):
        if lay.planar and name != "phi" or name == "psi" and not lay.twist:
            continue
        holders = [
            g for g in grips if g.mode == "clamp" or (g.mode == "tangent" and name != "psi")
        ]
        if not holders:
            continue
        current = m.fields(z, np.array([g.s for g in holders]))[name]
        residual = [
            p[nlp.params[f"grip:{g.name}:angles"]][k] - c for g, c in zip(holders, current)
        ]
        z[lay.slice(name)] = fit(fields[name] + np.interp(nodes, [g.s for g in holders], residual))
    x_a = m.positions(z, np.array([a.s]))[0]
    z[0:3] = (a.pose.position - x_a) / m.length
    return z


def director_guess(nlp: StringNLP, problem: Problem) -> np.ndarray:
    """Return the buckled guess for a director model, as nodal frames.

    The buckled guess for a director model, as nodal frames: tangent t(s) = cos β d + sin β e
    with β = α sin 2πu (d the chord, e toward gravity), bent to meet every held tangent (the
    piecewise-linear interpolant of the misfits at the grips is added), frames carried along
    without twist from the first clamp and turned about t by the interpolated roll misfit at the
    other clamps.  Outer grips at one point get a ring, β = 2πu, instead.
    """
    m, r0 = nlp.model, nlp.r0
    nodes = m.mesh.nodes
    grips = sorted(problem.grips, key=lambda g: g.s)
    a, b = grips[0], grips[-1]
    ring = False
    if len(grips) >= 2 and np.linalg.norm(b.pose.position - a.pose.position) > 1e-9:
        chord = b.pose.position - a.pose.position
        span = b.s - a.s
        alpha = inverse_j0(float(min(1.0, np.linalg.norm(chord) / span)))
        d = chord / np.linalg.norm(chord)
    else:
        d = quat_to_matrix(a.pose.orientation)[:, 0]
        alpha, span = 0.0, (b.s - a.s if len(grips) >= 2 else 1.0)
        # the outer grips at one point: a ring through it (β = 2πu), which closes and does not
        # cross itself; the straight guess misses the second grip by the whole span
        ring = len(grips) >= 2
    g = problem.gravity_unit
    e = g - np.dot(g, d) * d
    if np.linalg.norm(e) < 1e-6:
        e = np.cross(r0[:, 2], d)
    if np.linalg.norm(e) < 1e-6:  # chord along gravity and the frame's normal: any perpendicular
        e = np.cross(np.eye(3)[int(np.argmin(np.abs(d)))], d)
    e /= np.linalg.norm(e)
    u = np.clip((nodes - a.s) / span, 0.0, 1.0)
    beta = 2 * np.pi * u if ring else alpha * np.sin(2 * np.pi * u)
    t = np.cos(beta)[:, None] * d[None, :] + np.sin(beta)[:, None] * e[None, :]
    holders = [gr for gr in grips if gr.mode != "pin"]
    if holders:
        idx = [m.mesh.node_index(gr.s) for gr in holders]
        misfit = np.array(
            [quat_to_matrix(gr.pose.orientation)[:, 0] - t[i] for gr, i in zip(holders, idx)]
        )
        s_h = [gr.s for gr in holders]
        t = t + np.stack([np.interp(nodes, s_h, misfit[:, k]) for k in range(3)], axis=1)
        t /= np.linalg.norm(t, axis=1)[:, None]
    clamps = [gr for gr in grips if gr.mode == "clamp"]
    k0 = int(np.argmin(np.abs(nodes - (clamps[0].s if clamps else nodes[0]))))
    if clamps:
        hint = quat_to_matrix(clamps[0].pose.orientation)[:, 1]
    else:
        hint = r0[:, 2] if abs(np.dot(r0[:, 2], t[k0])) < 0.9 else r0[:, 0]
    frames = transported_frames(t, k0, hint)
    if m.layout.frame:
        frames = match_clamp_rolls(nlp, frames, problem)
    z = m.z_from_frames(np.zeros(3), frames)
    z[0:3] = (a.pose.position - m.positions(z, np.array([a.s]))[0]) / m.length
    return z


def match_clamp_rolls(nlp: StringNLP, frames: np.ndarray, problem: Problem) -> np.ndarray:
    """Turn node frames about their tangents to match the clamps' rolls.

    Node frames (director model) turned about their tangents by the piecewise-linear interpolant
    of the roll misfit at the clamps (each in (−π, π]): a shape from a model without twist (or a
    target turned while the plane was held) then meets the clamps' rolls, so Newton does not settle
    on the flipped sheet d1 = −d1_g that the clamp rows also admit.
    """
    clamps = sorted((g for g in problem.grips if g.mode == "clamp"), key=lambda g: g.s)
    if not clamps:
        return frames
    mesh = nlp.model.mesh
    rolls = []
    for g in clamps:
        f = frames[mesh.node_index(g.s)]
        target = quat_to_matrix(g.pose.orientation)[:, 1]
        rolls.append(
            math.atan2(
                float(np.dot(np.cross(f[:, 1], target), f[:, 0])), float(np.dot(f[:, 1], target))
            )
        )
    gamma = np.interp(mesh.nodes, [g.s for g in clamps], rolls)
    t, d1, d2 = frames[:, :, 0], frames[:, :, 1], frames[:, :, 2]
    d1n = np.cos(gamma)[:, None] * d1 + np.sin(gamma)[:, None] * d2
    return np.stack([t, d1n, np.cross(t, d1n)], axis=-1)


def inverse_j0(ratio: float) -> float:
    """Return α in [0, 2.4048] with J0(α) = ratio, by bisection.

    α in [0, 2.4048] with J0(α) = ratio (chord/length of the guess β = −α sin 2πu), by
    bisection.
    """
    lo, hi = 0.0, 2.404825557695773
    if ratio >= 1.0:
        return 0.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if j0(mid) > ratio:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
