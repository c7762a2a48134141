"""Warm-start transfer: another model's committed equilibrium as this model's start, across models.

Fields are re-expanded in the target model's basis from their values at its nodes: the director
models from the source's pose frames (and strain), the Euler models from the source's fields (a
planar solution gets θ ≡ π/2, a solution without ψ its zero-twist ψ, an inextensible one ε ≡ 0),
re-extracting the Euler angles of the material frames in the target's reference frame R0 (unwrapped
along s) when the frames differ.  Multipliers are matched by constraint-row identity (grip, name,
component), the grip position rows through the reaction force vector (each model may use other axes
for them), an obstacle's contact slots by their arc length (each model places its own:
``obstacle_slots.py``), its rows by arc length too (a point force to the target's row nearest
along s, a line load spread over the target's rows under it: rows on the nodes of an element mesh
move between meshes, ``obstacle_points.carried_forces``); rows the source did not have get
zero, and a director target gets least-squares multipliers of its equality rows at the adopted
shape, ∇f + J_freeᵀ λ ≈ 0 (zeros would make its first Newton update fail).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ...model.problem import GripPose, Obstacle, Problem
from ...model.ritz import RitzModel
from ...model.rotations import euler_from_frame
from ..build.functions import NlpFunctions
from ..build.initial_guess import match_clamp_rolls
from ..contact import obstacle_slots as OSL
from ..contact.obstacle_points import carried_forces
from ..contact import self_contact as SC
from ..build.nlp import StringNLP
from ..build.parameters import ProblemParameters
from ..state import SolverState
from .inputs import structure_key

if TYPE_CHECKING:
    from ..shape_solver import ShapeSolver


@dataclass
class SourceShape:
    """What the target needs of the source's equilibrium, at the target's nodes (SI units)."""

    x0: np.ndarray  # x(0) [m]
    frames: np.ndarray | None  # pose frames (director target)
    eps: np.ndarray | None  # ε at the nodes (director target with stretch)
    fields: dict[str, np.ndarray] | None  # φ, θ, ψ, ε at the nodes (Euler target)
    x0_scaled: np.ndarray  # x(0) / L_target (Euler target's first unknowns)
    forces: dict[str, np.ndarray]  # each grip's reaction force [N]
    multipliers: dict[tuple, float]  # the source's SI multipliers by row identity
    slots: list[
        tuple[np.ndarray, np.ndarray]
    ]  # per obstacle: its filled contact slots' s [m] and SI multipliers
    #: per obstacle of the source: (the obstacle, its rows' s [m], their SI multipliers [N], the
    #: rows' quadrature weights [m])
    obstacle_rows: list[tuple[Obstacle, np.ndarray, np.ndarray, np.ndarray]]


def sample_source(source: ShapeSolver, src: SolverState, target: StringNLP) -> SourceShape:
    """Return the source's equilibrium ``src`` as ``target`` needs it.

    The caller holds the source's lock.
    """
    frames = eps = f = None
    if target.director:
        nodes = target.model.mesh.nodes
        # at the parameters src was solved at: the source may be a stream's model whose scene
        # (the anchor grip's target) has moved on since ``src`` was taken (a check's snapshot)
        frames = source.pose_frames(src.z, nodes, src.p)
        eps = source.strain(src.z, nodes) if target.model.layout.stretch else None
    else:
        nodes = target.model.quad.nodes
        f = (
            source.model.fields(src.z, nodes)
            if not source.nlp.director
            else {"eps": source.strain(src.z, nodes)}
        )
        if source.nlp.director or not np.allclose(source.nlp.r0, target.r0):
            q = source.frames(src.z, nodes, src.p)
            angles = np.array([euler_from_frame(target.r0, qk) for qk in q])
            f["phi"], f["theta"], f["psi"] = (
                np.unwrap(angles[:, 0]),
                angles[:, 1],
                np.unwrap(angles[:, 2]),
            )
        elif not source.model.layout.twist and target.model.layout.twist:
            f["psi"] = source.frames_psi(src.z, nodes, src.p)
    nlp = source.nlp
    lam_src = src.lam_g / (np.asarray(nlp.row_scale) * nlp.sigma) if src.lam_g.size else src.lam_g
    # grip position rows: carry the reaction force vector, whatever axes each model's rows use
    forces = {
        name: nlp.grip_axes[name].T @ lam_src[rows["position"]]
        for name, rows in nlp.grip_rows.items()
    }
    # obstacle rows by arc length, not index: on element meshes they sit on the nodes, which
    # differ between meshes (the index matched a force to another node)
    multipliers = {
        kind: lam_src[i]
        for i, kind in enumerate(nlp.row_kind)
        if kind[0] not in ("slot", "obstacle")
    }
    obstacle_rows = [
        (ob, nlp.obstacle_s, lam_src[np.asarray(nlp.obstacle_rows[i])], nlp.obstacle_weights)
        for i, ob in enumerate(nlp.problem.obstacles)
    ]
    slots = []
    for i, rows in enumerate(nlp.slot_rows):
        filled = src.p[nlp.params[f"slots:{i}:on"]] > 0
        slots.append(
            (src.p[nlp.params[f"slots:{i}:s"]][filled], lam_src[np.asarray(rows)[filled]])
        )
    return SourceShape(
        src.z[0:3] * source.model.length,
        frames,
        eps,
        f,
        src.z[0:3] * source.model.length / target.model.length,
        forces,
        multipliers,
        slots,
        obstacle_rows,
    )


def warm_state(
    nlp: StringNLP,
    fns: NlpFunctions,
    parameters: ProblemParameters,
    problem: Problem,
    source: SourceShape,
) -> SolverState:
    """Return the target's warm start (z, λ, p) for ``problem`` from the sampled ``source``."""
    model, lay, lay_p = nlp.model, nlp.model.layout, nlp.params
    if nlp.director:
        frames = source.frames
        assert frames is not None  # sampled for a director target (sample_source)
        if lay.frame:
            frames = match_clamp_rolls(nlp, frames, problem)
        z = model.z_from_frames(source.x0, frames, source.eps)
    else:
        assert isinstance(model, RitzModel) and source.fields is not None  # an Euler target
        z = np.zeros(lay.size)
        z[0:3] = source.x0_scaled
        for name in ("phi", "theta", "psi", "eps"):
            if model.coefficients(z, name) is not None:
                z[model.layout.slice(name)] = np.linalg.lstsq(
                    model.B, source.fields[name], rcond=None
                )[0]
    lam = np.zeros(nlp.lbg.size)
    for i, kind in enumerate(nlp.row_kind):
        if kind[0] == "grip" and kind[2] == "position" and kind[1] in source.forces:
            value = float(np.dot(np.array(kind[3]), source.forces[kind[1]]))
        elif kind in source.multipliers:
            value = source.multipliers[kind]
        else:
            continue
        lam[i] = value * nlp.row_scale[i] * nlp.sigma
    for k, ob in enumerate(nlp.problem.obstacles):  # each force to the row nearest along s
        for src_ob, src_s, src_lam, src_w in source.obstacle_rows:
            if src_ob == ob:
                held = np.asarray(nlp.obstacle_rows[k])
                carried = carried_forces(
                    src_s, src_lam, nlp.obstacle_s, src_w, nlp.obstacle_weights
                )
                lam[held] = carried * np.asarray(nlp.row_scale)[held] * nlp.sigma
                break
    p = parameters.pack(problem, z)
    for i, rows in enumerate(
        nlp.slot_rows
    ):  # a slot at the arc length of a source's slot takes its multiplier
        if i >= len(source.slots) or not source.slots[i][0].size:
            continue
        src_s, src_lam = source.slots[i]
        for k, row in enumerate(rows):
            if p[lay_p[f"slots:{i}:on"]][k] > 0:
                j = OSL.carried_slot(src_s, p[lay_p[f"slots:{i}:s"]][k], nlp.length)
                if j is not None:
                    lam[row] = src_lam[j] * nlp.row_scale[row] * nlp.sigma
    if nlp.director:
        # rows the source had no twin for (unit norms, folds, the frame rows): least-squares
        # multipliers
        nf = nlp.n_free_rows
        grad, _, jac, _, _ = fns.kkt(
            z, p, lam
        )  # ∇f does not depend on λ; one call gives ∇f and ∂g/∂z
        rest = (
            np.asarray(grad).ravel() + jac[nf:].T @ lam[nf:]
        )  # contacts keep their matched multipliers
        lam[:nf] = np.linalg.lstsq(jac[:nf].T, -rest, rcond=None)[0]
    return SolverState(z, lam, np.zeros(lay.size), p)


def held_poses(
    parameters: ProblemParameters, problem: Problem, src: SolverState
) -> dict[str, GripPose] | None:
    """Return the grip poses ``src`` is the equilibrium of, if they are ``problem``'s.

    ``problem``'s poses when its grip targets are the ones ``src.p`` holds; None when they are not
    (a scene set since, whose poses ``src`` was not solved for).
    """
    mask = parameters.nlp.grip_parameter_mask
    p = parameters.pack(problem, src.z, src.p)
    return (
        {g.name: g.pose for g in problem.grips} if np.array_equal(p[mask], src.p[mask]) else None
    )


def only_mesh_differs(target: ShapeSolver, source: ShapeSolver) -> bool:
    """Tell whether ``target``'s model is ``source``'s on another element mesh, and nothing else.

    The same options, scene structure and reference frame R0; another ``mesh_spec``.  A state
    mapped between them is marked ``SolverState.remeshed``.
    """
    return (
        target.mesh_spec != source.mesh_spec
        and target.options == source.options
        and structure_key(target.problem, target.options)
        == structure_key(source.problem, source.options)
        and np.array_equal(target.nlp.r0, source.nlp.r0)
    )


def adopted_copy(adopted: SolverState) -> SolverState:
    """Return a copy of an adopted state with its derivatives.

    A solve from it shifts g and the residual to its own targets (``newton``).
    """
    state = adopted.copy()
    state.g = adopted.g
    state.jacobian, state.hessian, state.gradient, state.energies = (
        adopted.jacobian,
        adopted.hessian,
        adopted.gradient,
        adopted.energies,
    )
    state.kkt, state.residual = adopted.kkt, adopted.residual
    return state


def adopted_state(
    nlp: StringNLP,
    fns: NlpFunctions,
    parameters: ProblemParameters,
    problem: Problem,
    source: SourceShape,
    contact: SC.ContactSlots | None,
    length: float,
) -> SolverState:
    """Return the target's warm start from ``source`` (``warm_state``) with the source's pairs.

    ``contact``: the source's self-contact pairs; when the target has as many slots, the same
    pairs in the same slots are copied and filled into p (the multipliers ``warm_state`` matched
    row by row belong to them).  ``length``: the string's length L [m].
    """
    state = warm_state(nlp, fns, parameters, problem, source)
    if contact is not None and len(contact.pairs) == nlp.self_contact_slots:
        state.contact = contact.copy()
        SC.fill(state.p, state.contact, nlp, length)
    return state


@dataclass
class Adoption:
    """The last mapping ``ShapeSolver.adopt_warm_start`` made, to adopt again without mapping.

    Weak references to the source solver and its state: a pooled model must not keep an evicted
    one alive.
    """

    source: weakref.ref  # the source solver
    state: weakref.ref  # its state that was mapped
    adopted: SolverState  # the state adopted from it, with its derivatives (``fill_start``)
    scene: Problem  # the adopting solver's scene then

    def is_of(self, source: object, state: SolverState) -> bool:
        """Tell whether this adoption mapped ``state`` of ``source`` (both still alive)."""
        return self.source() is source and self.state() is state
