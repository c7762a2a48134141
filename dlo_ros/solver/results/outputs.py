"""What a solve returns: the ShapeResult of a converged state, in SI units.

* the centreline x(s) [m] and pose quaternions at ``output_points`` arc lengths evenly spaced over
  [0, L];
* the energy terms [J] (bend, twist, stretch, gravity, external work; total = U − W; the work
  and total are None, with ``energy_note`` saying why, under a dead moment with no potential:
  ``moment_work.py``);
* each grip's reaction wrench and each obstacle's contact force (−Σ λ ∇h over its touching samples)
  [N];
* the stability verdict from the reduced Hessian (``stability.py``);
* the equilibrium residual (``wrenches.equilibrium``).  A shape whose residual exceeds the
  tolerance (``error_tolerance``, default 1e-3 L), or that is asked for less than a converged
  solve can be verified to (``residual.FLOOR``), is 'unverified' and carries no stability
  verdict; a director model's shape whose orientation rows hold on the flipped sheet is 'failed'
  and carries no shape.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any, cast

import numpy as np

from ...model.director import frame_to_quat
from ...model.problem import Problem
from ...model.rotations import pose_quaternions
from ..build import frames as F
from ..build.functions import NlpFunctions
from ..build.nlp import StringNLP
from ..build.output_function import TANGENTS
from ..build.slot_envelope import slot_contact_points
from ..options import SolverOptions
from ..build.parameters import ProblemParameters
from ..native.outputs import ComputedOutputs
from .moment_work import MomentWork, moment_work
from .residual import FLOOR, EquilibriumResidual, PointAction, equilibrium_residual
from .contacts import contact_loads
from .result import ContactLoad, GripWrench, Later, SelfContact, ShapeResult
from ..contact.self_contact import ContactSlots, slot_multiplier
from .stability import NO_FREEDOM, stability_verdict
from ..state import SolverState
from .wrenches import FramesOf, balance_inputs, wrench


def output_s(nlp: StringNLP, options: SolverOptions) -> np.ndarray:
    """Return the published arc lengths [m]: ``output_points`` evenly spaced over [0, L]."""
    return np.linspace(0.0, nlp.length, options.output_points)


def no_shape(
    options: SolverOptions, summary: Any, status: str, message: str, **fields: Any
) -> ShapeResult:
    """Return a result without a shape (invalid input, unreachable, infeasible, failed).

    A result without a shape (invalid input, unreachable, infeasible, failed): nothing in it
    could be mistaken for a shape, an energy, a wrench or an eigenvalue.
    """
    return ShapeResult(
        status=status,
        message=message,
        basis=options.basis,
        order=options.order,
        model=summary,
        **fields,
    )


def sample(
    nlp: StringNLP, z: np.ndarray, s_out: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return centreline points (N, 3) and φ, θ of an Euler model at ``s_out``.

    Centreline points (N, 3) and φ, θ of an Euler model at ``s_out``: ``RitzModel.positions``
    and ``fields`` with the output matrices looked up once and each field's coefficients multiplied
    once.
    """
    m = nlp.model
    b_out, _, w_out = m.matrices(s_out)
    cphi, cth, ceps = (m.coefficients(z, name) for name in ("phi", "theta", "eps"))
    theta_nodes = m.B @ cth if cth is not None else np.full(m.quad.count, np.pi / 2)
    t = m.tangents(m.B @ cphi, theta_nodes, m.B @ ceps if ceps is not None else None, lib=np)
    points = (z[0:3] * m.length)[None, :] + w_out @ t.T
    theta = b_out @ cth if cth is not None else np.full(len(s_out), np.pi / 2)
    return points, b_out @ cphi, theta


#: what a fixed model's 'unverified' message advises (``unverified_because``); with
#: ``solver.model: auto`` the answer says instead that auto refines its model (``auto/report.py``)
RAISE_ORDER = "; raise solver.order"


def unverified_because(residual_m: float, tolerance: float, length: float) -> str:
    """Return why a converged shape is no verified equilibrium to ``tolerance`` [m], or ''.

    Its residual [m] is over the tolerance, or the tolerance is below what a converged solve can
    be verified to (``residual.FLOOR`` · L, ``length`` L [m]).
    """
    if not residual_m <= tolerance:
        return (
            f"not a verified equilibrium: the equilibrium residual is {residual_m:.3g} m, over "
            f"the tolerance {tolerance:.3g} m (solver.error_tolerance{RAISE_ORDER})"
        )
    if tolerance < FLOOR * length:
        return (
            f"not a verified equilibrium to the tolerance {tolerance:.3g} m "
            "(solver.error_tolerance): below what a converged solve can be verified to, "
            f"{FLOOR:g} L; the equilibrium residual is {residual_m:.3g} m"
        )
    return ""


@dataclass(frozen=True)
class SolveRun:
    """What the solve that reached a state reports with its result."""

    ipopt_status: str
    iterations: int
    violation: float
    warm: bool
    steps: int


@dataclass(frozen=True)
class Evaluated:
    """A state's outputs as the numpy path or the compiled outputs' function evaluated them."""

    points: np.ndarray
    quats: np.ndarray
    grips: dict[str, GripWrench]
    contacts: dict[int, np.ndarray]
    residual: EquilibriumResidual
    flipped: str
    self_contacts: list[SelfContact]


def energies(values: np.ndarray, moments: MomentWork | None = None) -> dict[str, float | None]:
    """Return the energy terms [J] of the evaluated (bend, twist, stretch, gravity, work).

    ``moments``: the point moments' correction of the work (``moment_work.py``); its None makes
    external_work and total None (a dead moment without a potential).
    """
    bend, twist, stretch, grav, work = values.ravel().tolist()
    correction = 0.0 if moments is None else moments.correction
    if correction is None:
        return {
            "bend": bend,
            "twist": twist,
            "stretch": stretch,
            "gravity": grav,
            "external_work": None,
            "total": None,
        }
    work += correction
    return {
        "bend": bend,
        "twist": twist,
        "stretch": stretch,
        "gravity": grav,
        "external_work": work,
        "total": bend + twist + stretch + grav - work,
    }


class ShapeOutputs:
    """Builds the ShapeResult of a solved state of one NLP (see the module docstring)."""

    def __init__(
        self,
        nlp: StringNLP,
        fns: NlpFunctions,
        parameters: ProblemParameters,
        options: SolverOptions,
    ):
        self.nlp, self.fns, self.parameters, self.options = nlp, fns, parameters, options
        self.s_out = output_s(nlp, options)
        # λ_SI = λ / (row_scale · σ): the divisor of this NLP, formed once (the same numbers)
        self._lam_div = nlp.row_scale * nlp.sigma
        #: the self-contact slots p holds in the solve under way (set by ShapeSolver; None: not
        #: modelled)
        self.contact_slots: ContactSlots | None = None

    def si_multipliers(self, state: SolverState) -> np.ndarray:
        """Return the state's multipliers in SI units, λ / (row_scale · σ), as a new array."""
        return state.lam_g / self._lam_div if state.lam_g.size else state.lam_g

    def frames_of(self, current: Problem) -> FramesOf:
        """Material frames Q(z, s) with the twist-free frames anchored at ``current``'s grips."""
        return lambda z, s: F.frames(self.nlp, self.parameters, current, z, s)

    def result(
        self,
        problem: Problem,
        current: Problem,
        state: SolverState,
        ipopt_status: str,
        iterations: int,
        violation: float,
        warm: bool,
        steps: int,
        summary: Any,
    ) -> ShapeResult:
        """Return the ShapeResult of ``state`` solving ``problem``.

        The result of ``state`` solving ``problem``; its grips anchor the published twist-free
        frames (the tangent model's roll follows the first held grip being solved for).
        ``current``: the solver's committed scene, whose grips anchor the wrenches' frames;
        ``summary``: the result's model.
        """
        nlp, m = self.nlp, self.nlp.model
        z, p = state.z, state.p
        run = SolveRun(ipopt_status, iterations, violation, warm, steps)
        lam_si = self.si_multipliers(state)
        if self.fns.outputs is not None and self.contact_slots is None:
            return self._compiled_result(problem, current, state, lam_si, run, summary)
        s_out = self.s_out.copy()
        if nlp.director:
            points = m.positions(z, s_out)
            quats = frame_to_quat(F.pose_frames(nlp, self.parameters, problem, z, s_out))
        else:
            points, phi, theta = sample(nlp, z, self.s_out)
            quats = pose_quaternions(
                nlp.r0, phi, theta, F.frames_psi(nlp, self.parameters, current, z, s_out, p)
            )
        frames_of = self.frames_of(current)
        grips = {
            g.name: wrench(nlp, current.string, frames_of, g, z, lam_si) for g in problem.grips
        }
        contacts, actions = self._contacts(problem, z, p, lam_si)
        self_contacts = self._self_contacts(z, lam_si, self.contact_slots)
        for c in self_contacts:  # equal and opposite on the two strands
            actions += [
                PointAction(c.s_a, c.point_a, c.force, np.zeros(3)),
                PointAction(c.s_b, c.point_b, -c.force, np.zeros(3)),
            ]
        residual = equilibrium_residual(balance_inputs(nlp, problem, z, grips, actions, lam_si))
        flipped = F.flipped_grips(nlp, problem, z) if nlp.director else ""
        # IPOPT's answer keeps an active row's distance within ~1e-9 L of D (barrier
        # complementarity); self_contacts is empty without slots
        slots = self.contact_slots
        touching = [
            c
            for c in self_contacts
            if slots is not None and c.gap <= slots.geometry.distance + 1e-7 * nlp.length
        ]
        evaluated = Evaluated(points, quats, grips, contacts, residual, flipped, touching)
        return self._assemble(problem, state, summary, evaluated, run, lam_si)

    def point_actions(
        self, problem: Problem, current: Problem, state: SolverState
    ) -> tuple[dict[str, GripWrench], list[PointAction], np.ndarray]:
        """Return the grip reactions, the contact point actions and the SI multipliers of state.

        What ``result`` hands the equilibrium residual (``wrenches.equilibrium``), for a reader
        of the residual along the string (``element_error.py``); the numpy path, always.
        """
        nlp = self.nlp
        lam_si = self.si_multipliers(state)
        frames_of = self.frames_of(current)
        grips = {
            g.name: wrench(nlp, current.string, frames_of, g, state.z, lam_si)
            for g in problem.grips
        }
        actions = self._contacts(problem, state.z, state.p, lam_si)[1]
        # the pairs ``state`` holds: on a check's worker thread the solver's own are a later
        # update's (a background check read them and refined a Fig. 2 loop the inline one kept)
        slots = state.contact if state.contact is not None else self.contact_slots
        for c in self._self_contacts(state.z, lam_si, slots):
            actions += [
                PointAction(c.s_a, c.point_a, c.force, np.zeros(3)),
                PointAction(c.s_b, c.point_b, -c.force, np.zeros(3)),
            ]
        return grips, actions, lam_si

    def _compiled_result(
        self,
        problem: Problem,
        current: Problem,
        state: SolverState,
        lam_si: np.ndarray,
        run: SolveRun,
        summary: Any,
    ) -> ShapeResult:
        """Return ``result`` from one call of the compiled outputs' function.

        ``result`` from one call of the outputs' function (``output_function.py``): the same
        shape, wrenches, contact forces, residual and flip test as the numpy path.
        """
        plan = self.fns.output_function
        assert plan is not None  # the outputs' function exists: result() checked fns.outputs
        prof = plan.profiles(problem.string)
        # the compiled loop's, at its answer (native/outputs.py); SolverState types it as object
        computed = cast(ComputedOutputs | None, state.outputs)
        if computed is not None and computed.matches(state.z, state.p, lam_si, prof):
            points, v_out, forces, torques, contact, res, flip = computed.values[:TANGENTS]
        else:
            outputs = self.fns.outputs
            assert outputs is not None  # result() checked it
            points, v_out, forces, torques, contact, res, flip = outputs(
                state.z, state.p, lam_si, prof
            )[:TANGENTS]
        grips = {
            name: GripWrench(force=forces[:, k], torque=torques[:, k])
            for k, name in enumerate(plan.grip_names)
        }
        contacts = {i: contact[:, i] for i in range(plan.n_obstacles)}
        # frames.flipped_grips: t against the target's x axis, and d1 against its y axis for a
        # clamp
        tangent_dots, d1_dots = flip[0].tolist(), flip[1].tolist()  # (one read each, as floats)
        flipped = ", ".join(
            g.name
            for k, g in enumerate(problem.grips)
            if g.mode != "pin" and (tangent_dots[k] < 0 or (g.mode == "clamp" and d1_dots[k] < 0))
        )
        residual = EquilibriumResidual(*res[:3, 0].tolist())
        if plan.planar:  # v_out is φ: the orientations as ``sample`` and the numpy path make them
            phi = v_out.ravel()
            quats = pose_quaternions(
                self.nlp.r0,
                phi,
                np.full(phi.size, np.pi / 2),
                F.frames_psi(self.nlp, self.parameters, current, state.z, self.s_out, state.p),
            )
        else:
            quats = v_out.T
        evaluated = Evaluated(points.T, quats, grips, contacts, residual, flipped, [])
        return self._assemble(problem, state, summary, evaluated, run, lam_si)

    def _assemble(
        self,
        problem: Problem,
        state: SolverState,
        summary: Any,
        out: Evaluated,
        run: SolveRun,
        lam_si: np.ndarray,
    ) -> ShapeResult:
        """Return the ShapeResult of the evaluated outputs, with its status.

        The energies and the stability verdict come from the reduced Hessian; the status is
        'failed' on a flipped branch, 'unverified' over the residual's tolerance.  ``lam_si``: the
        state's SI multipliers (``si_multipliers``), a new array the result may keep.
        """
        options = self.options
        # the inertia's verdict, or the eigenvalue's (λ_min then deferred or a number); no freedom
        # left by the active rows (min_eig None): no admissible perturbation, so nothing can lower
        # the energy: stable, and the message says why there is no eigenvalue
        stable: bool | None
        stable, min_eig = stability_verdict(self.nlp, self.fns, state)  # fills state.energies
        assert state.energies is not None  # stability_verdict leaves it evaluated
        moments = moment_work(self.nlp, problem, state.z, state.p) if problem.loads else None
        energy = energies(state.energies, moments)
        status, message = (
            "ok",
            "converged"
            + (f" after {run.steps} continuation steps" if run.steps else "")
            + ("" if min_eig is not None else f"; {NO_FREEDOM}"),
        )
        tolerance = options.error_tolerance or 1e-3 * problem.string.length
        if out.flipped:  # not the grip's pose at all: no shape
            return no_shape(
                options,
                summary,
                "failed",
                f"landed on a flipped branch: {out.flipped}",
                iterations=run.iterations,
                constraint_violation=run.violation,
                warm_started=run.warm,
                ipopt_status=run.ipopt_status,
            )
        unverified = unverified_because(out.residual.metres, tolerance, problem.string.length)
        if unverified:
            status, stable, message = "unverified", None, unverified
        return ShapeResult(
            model=summary,
            status=status,
            message=message,
            s=self.s_out.copy(),
            points=out.points,
            orientations=out.quats,
            energy=energy,
            energy_note="" if moments is None else moments.reason,
            grips=out.grips,
            contact_forces=out.contacts,
            stable=stable,
            min_eigenvalue=min_eig,
            iterations=run.iterations,
            constraint_violation=run.violation,
            warm_started=run.warm,
            continuation_steps=run.steps,
            basis=options.basis,
            order=options.order,
            ipopt_status=run.ipopt_status,
            equilibrium_residual_m=out.residual.metres,
            self_contacts=out.self_contacts,
            contact_loads=self._contact_loads(problem, state, lam_si),
        )

    def _contact_loads(
        self, problem: Problem, state: SolverState, lam_si: np.ndarray
    ) -> list[ContactLoad] | Later[list[ContactLoad]]:
        """Return the obstacles' line loads and point forces (``contacts.contact_loads``).

        [] without obstacle rows; else worked out on first read (``result.Later``) from copies of
        the state's z and p and its SI multipliers (the state goes on to the next update).
        """
        nlp = self.nlp
        if not nlp.obstacle_rows:
            return []
        return Later(partial(contact_loads, nlp, problem, state.z.copy(), state.p.copy(), lam_si))

    def _self_contacts(
        self, z: np.ndarray, lam_si: np.ndarray, slots: ContactSlots | None
    ) -> list[SelfContact]:
        """Return the force of each self-contact slot of ``slots`` with a positive multiplier.

        Each slot with a positive multiplier λ [N/m] of its row D² − |x_a − x_b|² ≤ 0: the force
        2 λ (x_a − x_b) on the string at s_a (−∂(λ g)/∂x_a) and its opposite at s_b.
        """
        nlp = self.nlp
        if slots is None or not nlp.self_contact_rows:
            return []
        out = []
        for k, row in enumerate(nlp.self_contact_rows):
            pair = slots.pairs[k] if k < len(slots.pairs) else None
            if pair is None or not lam_si[row] > 0:
                continue
            s_a, s_b = slots.arc_lengths(k)  # the samples, or the closest points held exactly
            xa, xb = nlp.model.positions(z, np.array([s_a, s_b]))
            lam = slot_multiplier(lam_si[row], slots.distance(k))
            out.append(
                SelfContact(
                    s_a,
                    s_b,
                    xa,
                    xb,
                    2.0 * lam * (xa - xb),
                    float(np.linalg.norm(xa - xb)),
                )
            )
        return out

    def _contacts(
        self, problem: Problem, z: np.ndarray, p: np.ndarray, lam_si: np.ndarray
    ) -> tuple[dict[int, np.ndarray], list[PointAction]]:
        """Return each obstacle's total contact force [N] and the point actions on the string.

        Each obstacle's total contact force [N] (−Σ_j λ_j ∇h(x_j) over its samples, −λ_k ∇_X v*_k
        at σ_k + δ_k over its contact slots: ``slot_envelope.slot_contact_points``), and every
        touching sample's or slot's force as a point action on the string (for the equilibrium
        residual).
        """
        nlp = self.nlp
        contacts: dict[int, np.ndarray] = {}
        actions: list[PointAction] = []
        if not nlp.obstacle_rows:
            return contacts, actions
        touching = np.any(lam_si[nlp.n_free_rows :] > 0)  # obstacle rows come last
        sample_x = nlp.model.positions(z, nlp.obstacle_s) if touching else None
        for i, rows in enumerate(nlp.obstacle_rows):
            ob = problem.obstacles[i]
            lam = lam_si[rows]
            if nlp.obstacle_slots:  # a sample a contact slot replaces acts with no force
                lam = lam * p[nlp.params[f"samples:{i}:on"]]
            touch = np.flatnonzero(lam > 0)
            if not touch.size:
                contacts[i] = np.zeros(3)
                continue
            assert sample_x is not None  # a touching row: evaluated above
            # one call for every touching sample (CasADi maps a function over the columns)
            grads = (
                np.asarray(nlp.obstacle_gradient[ob.type](sample_x[touch].T, ob.params))
                .reshape(3, -1)
                .T
            )
            forces = -lam[touch, None] * grads
            contacts[i] = forces.sum(axis=0)
            actions += [
                PointAction(float(nlp.obstacle_s[j]), sample_x[j], f, np.zeros(3))
                for j, f in zip(touch, forces)
            ]
        # contact slots (solver/contact/obstacle_slots.py)
        for i, rows in enumerate(nlp.slot_rows):
            ob, lay = problem.obstacles[i], nlp.params
            touch = np.flatnonzero((lam_si[rows] > 0) & (p[lay[f"slots:{i}:on"]] > 0))
            if not touch.size:
                continue
            slot_s, slot_x, grads = slot_contact_points(
                nlp, ob.type, ob.params, problem.string.radius, z, p, i, touch
            )
            forces = -lam_si[np.asarray(rows)[touch], None] * grads
            contacts[i] = contacts[i] + forces.sum(axis=0)
            actions += [
                PointAction(float(sk), x, f, np.zeros(3))
                for sk, x, f in zip(slot_s, slot_x, forces)
            ]
        return contacts, actions
