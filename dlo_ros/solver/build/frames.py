"""Frames and strain of a solution z, at any arc lengths s [m].

Two conventions: material frames Q(s) = [ξ η ζ] (ζ the tangent; the Euler models' frames, built
from φ, θ, ψ in the reference frame R0) and pose frames Q(s)·TANGENT_X = [t y z] (x along the
tangent; the published orientations and grip poses).  Where the model solves no twist (the tangent
director model, or an Euler model without ψ) the frames carry no twist from the first held grip
along s (the zero-twist ψ, anchored at that grip's roll), which is the equilibrium when nothing
holds the twist.
"""

from __future__ import annotations

import numpy as np

from ...model.problem import Grip, Problem
from ...model.rotations import TANGENT_X, material_frames, quat_to_matrix
from .nlp import StringNLP
from .parameters import ProblemParameters


def anchor_grip(problem: Problem) -> Grip | None:
    """Return the grip the twist-free frames start from.

    The grip the twist-free frames start from: the first (smallest s) that holds an
    orientation.
    """
    return next((g for g in sorted(problem.grips, key=lambda g: g.s) if g.mode != "pin"), None)


def strain(nlp: StringNLP, z: np.ndarray, s: np.ndarray) -> np.ndarray:
    """ε(s) of solution z (zeros when inextensible)."""
    m = nlp.model
    if not m.layout.stretch:
        return np.zeros(np.shape(s))
    if nlp.director:
        return m.mesh.interpolation(s)[0] @ m.strain_nodes(z)
    return m.fields(z, np.asarray(s), ("eps",))["eps"]


def frames_psi(
    nlp: StringNLP,
    parameters: ProblemParameters,
    problem: Problem,
    z: np.ndarray,
    s: np.ndarray,
    p: np.ndarray | None = None,
) -> np.ndarray:
    """Return ψ(s) [rad] of an Euler model as published.

    ψ(s) [rad] of an Euler model as published: the solved field, or the zero-twist ψ anchored at
    the first held grip (its target ψ from ``p``, or from ``problem`` packed at z).
    """
    m = nlp.model
    if m.layout.twist:
        return m.fields(z, s)["psi"]
    anchor = anchor_grip(problem)
    psi_anchor = 0.0
    if anchor is not None:
        pp = p if p is not None else parameters.pack(problem, z, slots=False)
        psi_anchor = float(pp[nlp.params[f"grip:{anchor.name}:angles"]][2])
    if m.layout.planar:  # θ ≡ π/2: ψ' = −φ' cosθ = 0, so ψ is the anchor's everywhere
        return np.full(np.shape(s), psi_anchor)
    return m.zero_twist_psi(z, s, anchor.s if anchor is not None else 0.0, psi_anchor)


def pose_frames(
    nlp: StringNLP,
    parameters: ProblemParameters,
    problem: Problem,
    z: np.ndarray,
    s: np.ndarray,
    p: np.ndarray | None = None,
) -> np.ndarray:
    """Return the frames (len(s), 3, 3) of solution z in the pose convention.

    Frames (len(s), 3, 3) in the pose convention (columns: tangent, y, z) of solution z.  A
    director model without twist carries its frames without twist from the first held grip, at
    its target orientation in ``p`` when given (the parameters z was solved at), else
    ``problem``'s.
    """
    if not nlp.director:
        return frames(nlp, parameters, problem, z, s, p) @ TANGENT_X
    anchor = anchor_grip(problem)
    if anchor is None:
        return nlp.model.pose_frames(z, s, None)
    if p is None:
        held = quat_to_matrix(anchor.pose.orientation)
    else:
        held = np.asarray(p[nlp.params[f"grip:{anchor.name}:frame"]]).reshape(3, 3, order="F")
    return nlp.model.pose_frames(z, s, (anchor.s, held))


def frames(
    nlp: StringNLP,
    parameters: ProblemParameters,
    problem: Problem,
    z: np.ndarray,
    s: np.ndarray,
    p: np.ndarray | None = None,
) -> np.ndarray:
    """Return the material frames Q(s) (columns ξ, η, ζ) of solution z.

    Material frames Q(s) (columns ξ, η, ζ) of solution z; ψ from the zero-twist rule if not
    solved.
    """
    if nlp.director:
        return pose_frames(nlp, parameters, problem, z, s) @ TANGENT_X.T
    f = nlp.model.fields(z, s)
    return material_frames(
        nlp.r0, f["phi"], f["theta"], frames_psi(nlp, parameters, problem, z, s, p)
    )


def node_frame(nlp: StringNLP, z: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray | None]:
    """(t, d1) of a director model at the node at arc length s (d1 None for the tangent model)."""
    m = nlp.model
    v = m.node_values(z)[m.mesh.node_index(s)]
    if m.layout.frame:
        r = quat_to_matrix(v / np.linalg.norm(v))
        return r[:, 0], r[:, 1]
    return v / np.linalg.norm(v), None


def flipped_grips(nlp: StringNLP, problem: Problem, z: np.ndarray) -> str:
    """Return the grips of a director model whose orientation rows hold on the wrong sheet.

    Grips of a director model whose orientation rows hold on the wrong sheet (t = −t_g, or d1 =
    −d1_g for a clamp with twist): the rows t·R_g e_y = t·R_g e_z = 0 allow it, the grip does
    not.
    """
    bad = []
    for g in problem.grips:
        if g.mode == "pin":
            continue
        t, d1 = node_frame(nlp, z, g.s)
        target = quat_to_matrix(g.pose.orientation)
        if np.dot(t, target[:, 0]) < 0 or (
            g.mode == "clamp" and d1 is not None and np.dot(d1, target[:, 1]) < 0
        ):
            bad.append(g.name)
    return ", ".join(bad)


def euler_angles_at(nlp: StringNLP, z: np.ndarray, s: float) -> tuple[float, float, float]:
    """(φ, θ, ψ) [rad] of an Euler model's solution z at arc length s."""
    f = nlp.model.fields(z, np.array([s]), ("phi", "theta", "psi"))
    return float(f["phi"][0]), float(f["theta"][0]), float(f["psi"][0])
