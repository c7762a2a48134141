"""What a scene's structure fixes about its model: held twist, kinks and point moments.

These answer, from the scene alone, the questions ``StringNLP`` asks before it builds anything:
whether the twist is an unknown, where the solution may have a kink (the element breakpoints), and
whether point moments are applied.
"""

from __future__ import annotations

import numpy as np

from ...model.elements import ElementMesh
from ...model.problem import Problem
from ..options import SolverOptions


def twist_is_held(problem: Problem) -> bool:
    """Twist is an unknown only when something can hold it: two clamps and Rt > 0.

    With fewer clamps the string untwists to ω ≡ 0 at equilibrium (no point moment about the
    tangent is modelled), so ψ follows from φ and θ and need not be solved for.
    """
    clamps = sum(1 for g in problem.grips if g.mode == "clamp")
    return clamps >= 2 and not problem.string.twist_stiffness.is_zero


def breakpoints(problem: Problem) -> list[float]:
    """Return the arc lengths where the solution may have a kink.

    Arc lengths where the solution may have a kink: every grip strictly inside the string (a
    jump of the internal force and moment), every point load, both ends of every relative position
    (its reaction is a point force at each) and every knot of a piecewise-linear material profile
    (a jump of the curvature's derivative).
    """
    L = problem.string.length
    out = [g.s for g in problem.grips] + [ld.s for ld in problem.loads]
    out += problem.relative_ends()  # their reactions are point forces
    st = problem.string
    for prof in (
        st.bend_stiffness,
        st.twist_stiffness,
        st.lateral_bend_stiffness,
        st.weight_per_length,
        st.stretch_stiffness,
    ):
        if prof is not None and len(prof.s) > 1:
            out += list(prof.s)
    return sorted(s for s in out if 0.0 < s < L)


def models_twist(problem: Problem, options: SolverOptions) -> bool:
    """Tell whether a 3D model carries the roll about the tangent (the frame model).

    Whether a 3D model carries the roll about the tangent (the frame model): when two clamps
    hold it, and — for the director model — when a point moment acts and a clamp can react its
    twisting part (Rt > 0); and always for a strip (``string.lateral_bend_stiffness``): its two
    bending stiffnesses tie the bending to the roll, so the roll is an unknown even under one
    clamp.
    """
    if twist_is_held(problem) or is_strip(problem):
        return True
    if options.rotation != "director" or problem.string.twist_stiffness.is_zero:
        return False
    return has_point_moments(problem) and any(g.mode == "clamp" for g in problem.grips)


def is_strip(problem: Problem) -> bool:
    """Tell whether the string has two bending stiffnesses (``string.lateral_bend_stiffness``)."""
    return problem.string.lateral_bend_stiffness is not None


def has_point_moments(problem: Problem) -> bool:
    """Tell whether the scene applies a point moment.

    Point moments are modelled about the working-plane normal only (their work −m·φ is exact
    about n), so a scene with one keeps that normal as its pole.
    """
    return any(np.any(np.asarray(ld.moment, dtype=float) != 0.0) for ld in problem.loads)


def breakpoint_node(mesh: ElementMesh, s: float) -> int:
    """Return the mesh node at the breakpoint s (a grip's or a load's arc length).

    ``breakpoints`` makes every grip and load an element boundary, so s is always a node.
    """
    node = mesh.node_index(s)
    if node is None:
        raise ValueError(f"arc length {s} is not a node of the director model's mesh")
    return node
