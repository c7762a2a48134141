"""The NLP of one scene structure, built once; everything that moves is a parameter.

    minimise   σ (U_bend + U_twist + U_stretch + U_grav − W)(z; p) subject to (x(s_g) − p_g)/L = 0
    every grip            (paper eq. 6 / grips)
               φ(s_g) − φ_g = 0, θ(s_g) − θ_g = 0        clamp, tangent grips  (eq. 7)
               ψ(s_g) − ψ_g = 0                          clamp grips, when twist is modelled
               (x(s_b) − x(s_a) − l)/L = 0               relative positions    (eq. 6)
               (h_i(x(σ_j)) + r)/L ≤ 0                   obstacles × samples   (eq. 8)
               (b_k − |T q_k|²)/L ≤ 0                    self-contact slots (solver/contact/self_contact.py)

σ = L / max Rf makes the objective dimensionless and O(1); constraint rows are scaled as shown.
``row_scale`` converts IPOPT's multipliers back to SI: λ_SI = λ_ipopt / (row_scale · σ). Structure
(which grips, their s and modes, loads' s, obstacle types, twist and stretch fields) is fixed per
NLP; parameter values (grip targets, profiles, gravity, load values, obstacle poses) are not.

Every equality row (grips, relative positions, and for the director model the unit-norm rows) comes
before every inequality row (the director model's fold rows, then the obstacle rows, then the
self-contact slots: slot k's parameters are q_k = (W(s_a) − W(s_b))/√(2D), so that T q_k is x(s_a)
− x(s_b) scaled (T the quadrature-node tangents), and b_k = D/2 when the slot holds a pair, −L when
it is empty).  Besides the full KKT function (``kkt_fn``) there is ``kkt_free_fn``, for Newton
updates while no obstacle row is active: the Newton matrix and residual of the other rows (all
equalities) without the obstacle rows' Jacobian, Hessian or values.  Both are assembled from
per-quadrature-node derivatives (``assembled.py`` for the director model, ``assembled_euler.py``
for the planar and Euler-angle models), not differentiated from the flattened expressions here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import functools

import casadi as ca
import numpy as np

from ...model.director import DirectorModel
from ...model.elements import ElementMesh
from ...model.obstacles import OBSTACLE_TYPES
from ...model.problem import Problem
from ...model.ritz import RitzModel
from ...model.rotations import (
    farthest_pole,
    frame_with_pole,
    pole_angle_deg,
    quat_to_matrix,
    reference_frame,
)
from .assembled import AssembledKKT
from .assembled_euler import AssembledEulerKKT
from ..options import SolverOptions


@dataclass
class ParameterLayout:
    """Named slices of the parameter vector p."""

    slices: dict[str, slice] = field(default_factory=dict)
    size: int = 0

    def add(self, name: str, n: int) -> None:
        self.slices[name] = slice(self.size, self.size + n)
        self.size += n

    def __getitem__(self, name: str) -> slice:
        return self.slices[name]


def twist_is_held(problem: Problem) -> bool:
    """Twist is an unknown only when something can hold it: two clamps and Rt > 0.

    With fewer clamps the string untwists to ω ≡ 0 at equilibrium (no point moment about the
    tangent is modelled), so ψ follows from φ and θ and need not be solved for.
    """
    clamps = sum(1 for g in problem.grips if g.mode == "clamp")
    return clamps >= 2 and not problem.string.twist_stiffness.is_zero


def breakpoints(problem: Problem) -> list[float]:
    """Arc lengths where the solution may have a kink: every grip strictly inside the string (a
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
        st.weight_per_length,
        st.stretch_stiffness,
    ):
        if prof is not None and len(prof.s) > 1:
            out += list(prof.s)
    return sorted(s for s in out if 0.0 < s < L)


def models_twist(problem: Problem, options: SolverOptions) -> bool:
    """Whether a 3D model carries the roll about the tangent (the frame model): when two clamps
    hold it, and — for the director model — when a point moment acts and a clamp can react its
    twisting part (Rt > 0).
    """
    if twist_is_held(problem):
        return True
    if options.rotation != "director" or problem.string.twist_stiffness.is_zero:
        return False
    return has_point_moments(problem) and any(g.mode == "clamp" for g in problem.grips)


def has_point_moments(problem: Problem) -> bool:
    """Point moments are modelled about the working-plane normal only (their work −m·φ is exact
    about n), so a scene with one keeps that normal as its pole.
    """
    return any(np.any(np.asarray(ld.moment, dtype=float) != 0.0) for ld in problem.loads)


#: Newton steps a contact-free warm update takes in one call (``StringNLP.newton_fn``): with the
#start's
#: own system as the first, a grip move of 1 % of L converges to |r| ~ 1e-14 in three
NEWTON_STEPS = 3

#: a Newton step larger than this in any scaled unknown leaves the start's basin: IPOPT takes over
NEWTON_MAX_STEP = 0.5
#: active-set changes a warm Newton update may make before IPOPT takes over (newton.py)
NEWTON_ACTIVE_SET_CHANGES = 6
#: contact rows that may join or leave between Newton steps, per active set, before it is held
#(newton.py)
NEWTON_STEP_SWITCHES = 4
#: a contact row joins the active set above this excess g − bound, an active one leaves below
#−LEAVE_TOLERANCE : multiplier (scaled units)
JOIN_TOLERANCE, LEAVE_TOLERANCE = 1e-9, 1e-12
#: a warm update has converged when ‖∇f + Jᵀλ‖∞ and ‖g − bound‖∞ (scaled units) are below these
NEWTON_DUAL_TOLERANCE, NEWTON_PRIMAL_TOLERANCE = 1e-9, 1e-11
#: the compiled loops (native_newton.py) take Newton's own steps while a step exceeds
#NEWTON_CHORD_START : in a scaled unknown (and, with an active set, until a check of the rows
#changes none), then chord : steps on the last factored matrix.  They have converged when, besides
#the tolerances above, the last : step is below NEWTON_CHORD_TOLERANCE (or no longer shrinks:
#round-off); a step that shrinks by less : than NEWTON_CHORD_CONTRACTION against the one before has
#the matrix evaluated and factored anew; at : most NEWTON_CHORD_STEPS steps
NEWTON_CHORD_START, NEWTON_CHORD_TOLERANCE, NEWTON_CHORD_CONTRACTION, NEWTON_CHORD_STEPS = (
    0.05,
    1e-11,
    0.25,
    40,
)

#: δ / max|K| of the regularised Newton matrix K + diag(δ I, −δ I) of every warm update (newton.regularised)
NEWTON_REGULARISATION = 1e-10

#: a held grip tangent closer than this to the pole of the chord-and-gravity frame turns the pole
#[deg]
GRIP_POLE_MIN_DEG = 30.0


def choose_reference_frame(problem: Problem, frame: str) -> np.ndarray:
    """R0 for the Euler angles: identity for 'paper'; for 'auto' the working plane's frame.

    The working plane holds the chord between the first two grips (or the first grip's tangent) and
    gravity; its normal becomes the singular axis n = R0 e_z, which planar and near-planar shapes
    avoid. When a held grip tangent lies within GRIP_POLE_MIN_DEG of that normal (grippers holding
    the string across the chord), n is instead the direction farthest from the held tangents and
    the chord — unless point moments are applied (they are modelled about the working-plane
    normal).
    """
    if frame == "paper":
        return np.eye(3)
    grips = sorted(problem.grips, key=lambda g: g.s)
    if (
        len(grips) >= 2
        and np.linalg.norm(grips[-1].pose.position - grips[0].pose.position)
        > 1e-9 * problem.string.length
    ):
        chord = grips[-1].pose.position - grips[0].pose.position
    else:
        chord = quat_to_matrix(grips[0].pose.orientation)[:, 0]
    up = -problem.gravity_unit
    if abs(np.dot(chord / np.linalg.norm(chord), up)) > 0.999:
        # chord along gravity: take the plane of the chord and the first grip's tangent or normal
        r = quat_to_matrix(grips[0].pose.orientation)
        up = r[:, 0] if abs(np.dot(r[:, 0], up)) < 0.999 else r[:, 1]
    r0 = reference_frame(chord, up)
    # a held tangent on (or near) the pole makes the grip's Euler angles singular: then turn the
    # pole to the direction farthest from the held tangents and the chord (planar scenes never need
    # this)
    held = [quat_to_matrix(g.pose.orientation)[:, 0] for g in grips if g.mode != "pin"]
    if (
        held
        and not has_point_moments(problem)
        and pole_angle_deg(np.array(held), r0[:, 2]) < GRIP_POLE_MIN_DEG
    ):
        normal, _ = farthest_pole(np.array(held + [chord / np.linalg.norm(chord)]))
        r0 = frame_with_pole(normal, -chord)
    return r0


def planarity_violation(problem: Problem, normal: np.ndarray, tolerance: float = 1e-9) -> str:
    """Why the scene is not planar in the plane through the first grip with ``normal`` ('' if it
    is).

    Planar means: every grip position lies in the plane and every held tangent lies in it; gravity,
    forces and relative offsets lie in it; moments are along the normal; obstacles are half-spaces
    whose normals lie in the plane, or spheres/capsules/boxes centred on it (symmetric about it).
    """
    n = normal / np.linalg.norm(normal)
    L = problem.string.length
    origin = problem.grips[0].pose.position
    for i, g in enumerate(problem.grips):
        off = abs(np.dot(g.pose.position - origin, n))
        if off > tolerance * L:
            return f"grips[{i}].position is {off:.3g} m out of the plane"
        if (
            g.mode != "pin"
            and abs(np.dot(quat_to_matrix(g.pose.orientation)[:, 0], n)) > tolerance
        ):
            return f"grips[{i}].orientation: the tangent leaves the plane"
    if abs(np.dot(problem.gravity_unit, n)) > tolerance:
        return "gravity.direction is not in the plane"
    for i, ld in enumerate(problem.loads):
        if abs(np.dot(ld.force, n)) > tolerance * (1 + np.linalg.norm(ld.force)):
            return f"loads[{i}].force is not in the plane"
    for i, rel in enumerate(problem.relative_positions):
        if abs(np.dot(rel.offset, n)) > tolerance * L:
            return f"relative_positions[{i}].offset is not in the plane"
    for i, ob in enumerate(problem.obstacles):
        p = np.asarray(ob.params, dtype=float)
        why = ob.obstacle_type.planarity_violation(p, origin, n, tolerance, L)
        if why:
            return f"obstacles[{i}]: {why}"
    return ""


class StringNLP:
    """CasADi functions of one scene structure: the NLP, reactions, energies and the Lagrangian
    Hessian.
    """

    def __init__(
        self, problem: Problem, options: SolverOptions, reference_frame: np.ndarray | None = None
    ):
        """reference_frame: R0 to use instead of ``choose_reference_frame`` (3D models only: a
        planar model's R0 is fixed by its plane).
        """
        problem.validate()
        options.validate()
        self.problem = problem
        self.options = options
        L = problem.string.length
        self.length = L
        # 'auto' is resolved by AutoShapeSolver (solver.make_solver); a plain ShapeSolver solves
        # 'full'
        self.planar = options.model == "planar"
        self.director = not self.planar and options.rotation == "director"
        self.twist = models_twist(problem, options) and not self.planar
        self.stretch = problem.string.stretch_stiffness is not None
        if reference_frame is not None and self.planar:
            raise ValueError("a planar model's reference frame is fixed by its plane")
        self.r0 = (
            np.asarray(reference_frame, dtype=float)
            if reference_frame is not None
            else choose_reference_frame(problem, options.frame)
        )
        if self.planar:
            reason = planarity_violation(problem, self.r0[:, 2])
            if reason:
                raise ValueError(f"solver.model: 'planar' does not fit this scene: {reason}")
        if self.director:
            # Clenshaw–Curtis quadrature per element: n_e + 8 nodes resolve the normalised fields
            # to the accuracy of the basis (bench/results/director_convergence.md); collocated LGL
            # does not
            mesh = ElementMesh(
                L,
                breakpoints(problem),
                options.order,
                max(2, min(8, options.quadrature_nodes - options.order)),
            )
            self.model = DirectorModel(L, mesh, self.twist, self.stretch)
        else:
            self.model = RitzModel(
                L,
                options.basis,
                options.order,
                options.quadrature_nodes,
                self.r0,
                self.twist,
                self.stretch,
                self.planar,
            )
        self.sigma = L / problem.string.bend_stiffness.maximum
        self._moment_stiffness: ca.Function | None = None
        #: IPOPT's derivative functions (``ipopt_derivatives``), built on first use
        self._ipopt_derivatives: dict[str, ca.Function] | None = None
        self._build()

    # ------------------------------------------------------------------------------------------------
    def _build(self) -> None:
        P, m, L = self.problem, self.model, self.length
        M = m.quad.count
        lay = ParameterLayout()
        for name in ("Rf", "Rt", "Re", "D"):
            lay.add(name, M)
        for name, size in m.material_sizes().items():  # filled by material_parameters
            lay.add(name, size)
        lay.add("gravity", 3)
        lay.add("radius", 1)
        for g in P.grips:
            lay.add(f"grip:{g.name}:position", 3)
            if self.director:
                lay.add(f"grip:{g.name}:frame", 9)  # R_g column-major: t_g, d1_g, d2_g
            else:
                lay.add(f"grip:{g.name}:angles", 3)
        for i, _ in enumerate(P.loads):
            lay.add(f"load:{i}:force", 3)
            if self.director:
                lay.add(f"load:{i}:moment", 3)
                lay.add(
                    f"load:{i}:reference", 4
                )  # q_ref (or t_ref) of the moment's pseudo-potential
            else:
                lay.add(f"load:{i}:moment", 1)
        for i, _ in enumerate(P.relative_positions):
            lay.add(f"relative:{i}", 3)
        for i, ob in enumerate(P.obstacles):
            lay.add(f"obstacle:{i}", OBSTACLE_TYPES[ob.type].size)
        #: contact slots per obstacle (solver/contact/obstacle_slots.py): rows at arc lengths σ that are
        #parameters, : placed at the string's closest approaches; per slot σ, on (1 or 0: an empty
        #slot reads −1 ≤ 0) and : the row W(σ) of the integration matrix, x(σ) = x0 + T W(σ)ᵀ
        self.obstacle_slots = self.options.obstacle_slots if P.obstacles else 0
        for i, _ in enumerate(P.obstacles):
            if self.obstacle_slots:
                lay.add(
                    f"samples:{i}:on", self.options.obstacle_samples
                )  # 0: the sample a slot replaces
                lay.add(f"slots:{i}:s", self.obstacle_slots)
                lay.add(f"slots:{i}:on", self.obstacle_slots)
                lay.add(f"slots:{i}:w", self.obstacle_slots * M)  # slot k's row at k M … (k + 1) M
        self.self_contact_slots = self.options.self_contact_pairs if self.director else 0
        for k in range(self.self_contact_slots):
            lay.add(f"self:{k}", M + 1)
        self.params = lay

        z = ca.SX.sym("z", m.layout.size)
        p = ca.SX.sym("p", lay.size)
        profiles = {k: p[lay[k]] for k in ("Rf", "Rt", "Re", "D", *m.material_sizes())}
        bend, twist, stretch, grav, t = m.energy_terms(z, profiles, p[lay["gravity"]])

        # every arc length where a position is needed, evaluated with one matrix product
        s_points: list[float] = [g.s for g in P.grips]
        s_points += [ld.s for ld in P.loads]
        for rel in P.relative_positions:
            s_points += [rel.s_a, rel.s_b]
        self.obstacle_s = (
            np.linspace(0.0, L, self.options.obstacle_samples) if P.obstacles else np.zeros(0)
        )
        s_all = np.concatenate([np.asarray(s_points, dtype=float), self.obstacle_s])
        X = m.positions_sym(z, t, s_all) if len(s_all) else ca.SX(3, 0)
        col = 0
        grip_x = X[:, col : col + len(P.grips)]
        col += len(P.grips)
        load_x = X[:, col : col + len(P.loads)]
        col += len(P.loads)
        rel_x = X[:, col : col + 2 * len(P.relative_positions)]
        col += 2 * len(P.relative_positions)
        obs_x = X[:, col:]

        work = ca.SX(0)
        for i, _ in enumerate(P.loads):
            work += ca.dot(p[lay[f"load:{i}:force"]], load_x[:, i])
            if self.director:
                work += m.moment_work_sym(
                    z,
                    m.mesh.node_index(P.loads[i].s),
                    p[lay[f"load:{i}:moment"]],
                    p[lay[f"load:{i}:reference"]],
                )
            else:
                work -= p[lay[f"load:{i}:moment"]][0] * m.angle_sym(z, "phi", P.loads[i].s)

        g_rows: list[ca.SX] = []
        self.row_scale: list[float] = []
        self.row_kind: list[tuple] = []
        lbg: list[float] = []
        ubg: list[float] = []

        def add(
            expr: ca.SX, scale: float, kind: tuple, lower: float = 0.0, upper: float = 0.0
        ) -> None:
            g_rows.append(expr / scale)
            self.row_scale.append(scale)
            self.row_kind.append(kind)
            lbg.append(lower)
            ubg.append(upper)

        self.grip_rows: dict[str, dict[str, list[int]]] = {}
        self.grip_axes: dict[str, np.ndarray] = {}
        in_plane = self.r0[:, :2].T  # e1, e2
        for gi, g in enumerate(P.grips):
            rows: dict[str, list[int]] = {"position": [], "angles": []}
            target = p[lay[f"grip:{g.name}:position"]]
            # A planar model moves out of its plane only through x0·n: one grip fixes that, and the
            # other grips' out-of-plane rows would repeat it (dependent rows break IPOPT's LICQ).
            axes = np.eye(3) if (not self.planar or gi == 0) else in_plane
            for k, axis in enumerate(axes):
                rows["position"].append(len(g_rows))
                add(
                    ca.dot(ca.DM(axis), grip_x[:, gi] - target),
                    L,
                    ("grip", g.name, "position", tuple(np.round(axis, 12))),
                )
            self.grip_axes[g.name] = axes
            if self.director:
                rows["angles"] = self._director_grip_rows(z, p, g, add, len(g_rows))
                self.grip_rows[g.name] = rows
                continue
            angles = p[lay[f"grip:{g.name}:angles"]]
            held = ["phi"] if self.planar else ["phi", "theta"]
            names = {"clamp": held + ["psi"] if self.twist else held, "tangent": held, "pin": []}[
                g.mode
            ]
            for k, name in enumerate(names):
                rows["angles"].append(len(g_rows))
                add(m.angle_sym(z, name, g.s) - angles[k], 1.0, ("grip", g.name, name, k))
            self.grip_rows[g.name] = rows
        #: per relative position: its rows and their axes (c_r in c_r · (x(s_b) − x(s_a) − offset)
        #= 0)
        self.relative_rows: list[list[int]] = []
        self.relative_axes = in_plane if self.planar else np.eye(3)
        for i, _ in enumerate(P.relative_positions):
            off = p[lay[f"relative:{i}"]]
            self.relative_rows.append([])
            for k, axis in enumerate(self.relative_axes):
                self.relative_rows[-1].append(len(g_rows))
                add(
                    ca.dot(ca.DM(axis), rel_x[:, 2 * i + 1] - rel_x[:, 2 * i] - off),
                    L,
                    ("relative", i, k),
                )
        if self.director:
            for i, expr in enumerate(m.norm_rows_sym(z)):
                add(expr, 1.0, ("norm", i))
            # inequality rows (folds, then obstacles) come after every equality row
            for i, expr in enumerate(m.fold_rows_sym(z)):
                add(expr, 1.0, ("fold", i), -ca.inf, 0.0)
        self.obstacle_rows: list[list[int]] = []
        radius = p[lay["radius"]][0]
        for i, ob in enumerate(P.obstacles):
            rows = []
            h = OBSTACLE_TYPES[ob.type].h
            for j in range(len(self.obstacle_s)):
                rows.append(len(g_rows))
                expr = h(obs_x[:, j], p[lay[f"obstacle:{i}"]]) + radius
                if (
                    self.obstacle_slots
                ):  # a sample replaced by a slot reads −1 ≤ 0 (obstacle_slots.py)
                    on = p[lay[f"samples:{i}:on"]][j]
                    expr = on * expr - (1 - on) * L
                add(expr, L, ("obstacle", i, j), -ca.inf, 0.0)
            self.obstacle_rows.append(rows)
        #: per obstacle: its contact slots' rows, on·(h(x(σ_k)) + r) − (1 − on) L ≤ 0, scaled by
        #1/L
        self.slot_rows: list[list[int]] = []
        for i, ob in enumerate(P.obstacles):
            if not self.obstacle_slots:
                break
            h = OBSTACLE_TYPES[ob.type].h
            on = p[lay[f"slots:{i}:on"]]
            slot_x = ca.repmat(z[0:3] * L, 1, self.obstacle_slots) + ca.mtimes(
                t, self.slot_matrix(p, i).T
            )
            self.slot_rows.append([])
            for k in range(self.obstacle_slots):
                self.slot_rows[-1].append(len(g_rows))
                expr = (
                    on[k] * (h(slot_x[:, k], p[lay[f"obstacle:{i}"]]) + radius) - (1 - on[k]) * L
                )
                add(expr, L, ("slot", i, k), -ca.inf, 0.0)
        # self-contact slots: x(s_a) − x(s_b) = T q_k is linear in the tangents, whatever the pair
        self.self_contact_rows: list[int] = []
        for k in range(self.self_contact_slots):
            prm = p[lay[f"self:{k}"]]
            gap = ca.mtimes(t, prm[:M])
            self.self_contact_rows.append(len(g_rows))
            add(prm[M] - ca.dot(gap, gap), L, ("self", k), -ca.inf, 0.0)

        self.n_grip_equalities = sum(
            len(r["position"]) + len(r["angles"]) for r in self.grip_rows.values()
        )
        objective = self.sigma * (bend + twist + stretch + grav - work)
        g = ca.vertcat(*g_rows) if g_rows else ca.SX(0, 1)
        self.lbg, self.ubg = np.array(lbg), np.array(ubg)
        self.equality = self.lbg == self.ubg
        #: inequality rows a warm Newton update may make active (obstacle and self-contact rows:
        #physical : contacts; a fold guard at its bound is no equilibrium, so Newton leaves that to
        #IPOPT)
        self.contact_row = np.array(
            [kind[0] in ("obstacle", "slot", "self") for kind in self.row_kind], dtype=bool
        )
        self.row_scale = np.array(self.row_scale)
        self.nlp = {"x": z, "p": p, "f": objective, "g": g}
        self.z_sym, self.p_sym, self.g_sym = z, p, g

        self.energy_fn = ca.Function("energy", [z, p], [bend, twist, stretch, grav, work])
        # Inequality rows come last.  Without them the KKT function is what a Newton update needs
        # while no obstacle row is active: most of the KKT work is x(s_j) at the obstacle samples.
        inequalities = np.flatnonzero(self.lbg != self.ubg)
        self.n_free_rows = nf = int(inequalities[0]) if inequalities.size else g.shape[0]
        # the rows before the obstacle rows are equalities with bound 0 (grips, relative positions)
        assert np.all(self.lbg[:nf] == 0.0) and np.all(self.ubg[:nf] == 0.0)
        # the inequality rows' values: once per update (the convergence check), not per Newton step
        self.obstacle_g_fn = None
        # assembled from per-quadrature-node derivatives (solver/build/assembled.py, assembled_euler.py):
        # compact code (seconds of gcc instead of minutes), a faster interpreted call, and no
        # flattened Hessian to build
        assembled = AssembledKKT(self) if self.director else AssembledEulerKKT(self)
        self._assembled = assembled
        #: E (d·M × n): the unknowns → the per-node values u_k (``assembled.py``), d = node_width
        self.node_map, self.node_width = assembled.E, assembled.d
        self.kkt_free_fn, self.residual_free_fn = assembled.kkt_free()
        self.kkt_fn, self.residual_fn = assembled.kkt()
        if nf < g.shape[0]:
            self.obstacle_g_fn = assembled.inequality_g()
        zm, pm, lm = (
            ca.MX.sym("z", z.shape[0]),
            ca.MX.sym("p", lay.size),
            ca.MX.sym("lam", g.shape[0]),
        )
        self.hessian_fn = ca.Function(
            "lagrangian_hessian", [zm, pm, lm], [self.kkt_fn(zm, pm, lm)[3]]
        )
        self.jac_g_fn = assembled.jacobian()
        self.newton_fn = self.newton_function()
        self.g_fn = ca.Function("g", [z, p], [g])
        # ∂h/∂x of each obstacle type, evaluated only where a contact is active (for contact
        # forces)
        self.obstacle_gradient = {}
        xs = ca.SX.sym("x", 3)
        for kind in {ob.type for ob in P.obstacles}:
            ps = ca.SX.sym("po", OBSTACLE_TYPES[kind].size)
            self.obstacle_gradient[kind] = ca.Function(
                f"dh_{kind}", [xs, ps], [ca.gradient(OBSTACLE_TYPES[kind].h(xs, ps), xs)]
            )
        # rows of p that only grip targets occupy: they enter g linearly, so H and J do not depend
        # on them
        grip_only = np.zeros(lay.size, dtype=bool)
        for grip in P.grips:
            grip_only[lay[f"grip:{grip.name}:position"]] = True
            if not self.director:  # a director model's held frame R_g multiplies z in its rows
                grip_only[lay[f"grip:{grip.name}:angles"]] = True
        self.grip_parameter_mask = grip_only
        # ∂g/∂p restricted to grip targets: constant (each target enters one row as −target/scale)
        self._target_jacobian = np.asarray(
            ca.Function("dg_dp", [z, p], [ca.jacobian(g, p)])(
                np.zeros(z.shape[0]), np.zeros(lay.size)
            )
        )
        self._target_jacobian[:, ~grip_only] = 0.0

    @staticmethod
    def slot_parameters(i: int) -> tuple[str, str, str, str]:
        """The names of obstacle i's slot parameters in p: σ, on, W(σ) and the samples'
        switches.
        """
        return f"slots:{i}:s", f"slots:{i}:on", f"slots:{i}:w", f"samples:{i}:on"

    def disabled_rows(self, p: np.ndarray) -> np.ndarray:
        """Rows that p switches off (empty contact slots, samples a slot replaces): they read −1 ≤
        0 whatever the shape, so a warm start's multiplier on one belongs to no row of p.
        """
        off, lay = np.zeros(self.lbg.size, dtype=bool), self.params
        for i, rows in enumerate(self.slot_rows):
            off[rows] = p[lay[f"slots:{i}:on"]] == 0
            off[self.obstacle_rows[i]] = p[lay[f"samples:{i}:on"]] == 0
        return off

    def slot_matrix(self, p, i: int):
        """W(σ) (K × M) of obstacle i's contact slots, from p (numpy or CasADi)."""
        w = p[self.params[f"slots:{i}:w"]]
        K, M = self.obstacle_slots, self.model.quad.count
        return w.reshape(K, M) if isinstance(w, np.ndarray) else ca.reshape(w, M, K).T

    def _director_grip_rows(self, z: ca.SX, p: ca.SX, grip, add, first: int) -> list[int]:
        """Orientation rows of a grip on a director model: t·R_g e_y = t·R_g e_z = 0 (clamp,
        tangent) and d1·R_g e_z = 0 (clamp, twist modelled), at the grip's node.  Returns their row
        indices.
        """
        m = self.model
        node = m.mesh.node_index(grip.s)
        t, d1 = m.node_columns_sym(z, node)
        frame = ca.reshape(p[self.params[f"grip:{grip.name}:frame"]], 3, 3)
        rows = []
        if grip.mode in ("clamp", "tangent"):
            add(ca.dot(t, frame[:, 1]), 1.0, ("grip", grip.name, "t.d1", 0))
            add(ca.dot(t, frame[:, 2]), 1.0, ("grip", grip.name, "t.d2", 1))
            rows += [first, first + 1]
        if grip.mode == "clamp" and self.twist:
            add(ca.dot(d1, frame[:, 2]), 1.0, ("grip", grip.name, "d1.d2", 2))
            rows.append(first + len(rows))
        return rows

    def newton_function(self, kkt_free: ca.Function | None = None) -> ca.Function:
        """A contact-free warm update in one call: an MX function around ``kkt_free`` (default
        ``kkt_free_fn``; the compiled one loaded with ``casadi.external`` has the same inputs and
        outputs).

        Inputs u = [z; λ_free], p, and the Newton system (K0, r0) at u for the new targets.  It
        takes NEWTON_STEPS steps u ← u − K⁻¹ r (the first with K0, r0: for new grip targets the
        start's own K and a shifted r, so it costs no evaluation; then one evaluation per step) and
        evaluates the system once more at the end.  Outputs: u, K, r, ∇f and the energies at that
        u, and
        max |Δz| over the steps (the caller rejects a step > 0.5 and checks r for convergence).
        The steps use LAPACK's LU ('lapacklu'), which CasADi cannot generate C for, so this
        function stays interpreted (a thin MX layer); CasADi's own QR, which it can generate, costs
        more per solve than the LU.
        """
        kkt_free = kkt_free or self.kkt_free_fn
        n, nf, n_p = self.z_sym.shape[0], self.n_free_rows, self.p_sym.shape[0]
        u0, pp = ca.MX.sym("u", n + nf), ca.MX.sym("p", n_p)
        k0, r0 = ca.MX.sym("K0", n + nf, n + nf), ca.MX.sym("r0", n + nf)
        u, kkt, residual, largest = u0, k0, r0, ca.MX(0)
        # newton.regularised: K + diag(δ I, −δ I) bounds the step along a symmetry of the scene
        sign = ca.DM(np.concatenate([np.ones(n), -np.ones(nf)]))
        for _ in range(NEWTON_STEPS):
            delta = NEWTON_REGULARISATION * ca.fmax(ca.mmax(ca.fabs(kkt)), 1.0)
            step = ca.solve(kkt + ca.diag(delta * sign), residual, "lapacklu")
            largest = ca.fmax(largest, ca.norm_inf(step[:n]))
            u = u - step
            kkt, residual, grad, energies = kkt_free(u[:n], pp, u[n:])
        return ca.Function(
            "dlo_newton", [u0, pp, k0, r0], [u, kkt, residual, grad, energies, largest]
        )

    def moment_stiffness_fn(self) -> ca.Function:
        """The part of the exact equations' Jacobian that the pseudo-potential's Hessian lacks, at
        one load (director models).  The exact equations are ∇f and ∂g/∂z at p with every moment's
        centre q_ref set
        to its load's own normalised rotation N(v) = v/|v| (``ProblemParameters.centre_moments``): there
        ∇_v W_M = M·δθ exactly.  Their Jacobian is ∇²L (q_ref held) plus, at each load's node
        values v,

            C = −σ ∂(∇_v W_M)/∂q_ref · ∂N/∂v        (width × width),

        a function of v and M only: (v, M) → C.  Newton on these equations (``newton.newton`` with
        ``ExactMomentKKT``) solves for the equilibrium under dead moments directly, where
        re-centring the pseudo-potential between solves is a fixed point that need not converge.
        Built on first use.
        """
        if self._moment_stiffness is None:
            m = self.model
            width = m.layout.width
            v, moment, ref = ca.SX.sym("v", width), ca.SX.sym("M", 3), ca.SX.sym("r", 4)
            grad = -self.sigma * ca.gradient(m.moment_work_node_sym(v, moment, ref), v)
            normalised = ca.vertcat(v / ca.norm_2(v), ca.SX.zeros(4 - width))
            dgrad_dref = ca.substitute(ca.jacobian(grad, ref), ref, normalised)
            stiffness = ca.mtimes(dgrad_dref, ca.jacobian(normalised, v))
            self._moment_stiffness = ca.Function(
                "dlo_moment_stiffness", [v, moment], [ca.densify(stiffness)]
            )
        return self._moment_stiffness

    def material_parameters(self, p: np.ndarray) -> None:
        """Fill p's material terms (stiffness matrices, weight moments) from its Rf, Rt, Re, D
        slices.
        """
        lay = self.params
        profiles = {k: p[lay[k]] for k in ("Rf", "Rt", "Re", "D")}
        for name, value in self.model.material_terms(profiles).items():
            p[lay[name]] = value.ravel(order="F")

    @functools.cached_property
    def kkt_free_split_fn(self) -> ca.Function:
        """``kkt_free_fn`` with K's per-node Hessian part Eᵀ W left out and W last
        (``assembled.py``): what the compiled contact-free loop evaluates, adding Eᵀ W by BLAS.
        Built when first asked for.
        """
        return self._assembled.kkt_free_split()

    @functools.cached_property
    def node_blocks(self):
        """The node map as the dense blocks the compiled functions add Eᵀ W by
        (``native_newton.NodeBlocks``), made once per NLP.
        """
        from ..native.newton import NodeBlocks

        return NodeBlocks(self.node_map, self.node_width)

    @functools.cached_property
    def kkt_split_fn(self) -> ca.Function:
        """``kkt_fn`` split as ``kkt_free_split_fn`` (the compiled active-set loop's)."""
        return self._assembled.kkt_split()

    def target_shift(self, p_old: np.ndarray, p_new: np.ndarray) -> np.ndarray:
        """g(z, p_new) − g(z, p_old) when only grip targets differ (exact: they enter g
        linearly).
        """
        return self._target_jacobian @ (p_new - p_old)

    # ------------------------------------------------------------------------------------------------
    def make_solver(
        self, warm: bool, max_iterations: int | None = None, max_wall_time: float = 0.0
    ) -> ca.Function:
        """An IPOPT solver for this NLP: cold (default barrier start) or warm (primal-dual warm
        start); ``max_iterations``: IPOPT's limit (default: the options', and at most 200 when
        warm); ``max_wall_time`` [s]: IPOPT's limit on one call's wall-clock time (0: none).
        """
        o = self.options
        ipopt = {
            "print_level": 0,
            "sb": "yes",
            "tol": o.tolerance,
            "acceptable_tol": 1e-7,
            "constr_viol_tol": 1e-10,
            "max_iter": o.max_iterations,
            "linear_solver": "mumps",
            "hessian_approximation": "exact",
        }
        if warm:
            ipopt.update(
                {
                    "warm_start_init_point": "yes",
                    "mu_init": 1e-7,
                    "warm_start_bound_push": 1e-9,
                    "warm_start_slack_bound_push": 1e-9,
                    "warm_start_mult_bound_push": 1e-9,
                    "max_iter": min(o.max_iterations, 200),
                }
            )
        if max_iterations is not None:
            ipopt["max_iter"] = int(max_iterations)
        if max_wall_time > 0:
            ipopt["max_wall_time"] = float(max_wall_time)
        return ca.nlpsol(
            "dlo_warm" if warm else "dlo_cold",
            "ipopt",
            self.nlp,
            {
                "ipopt": ipopt,
                "print_time": False,
                "error_on_fail": False,
                **self.ipopt_derivatives(),
            },
        )

    def ipopt_derivatives(self) -> dict[str, ca.Function]:
        """IPOPT's derivative functions (nlpsol's ``grad_f``, ``jac_g`` and ``hess_lag`` options)
        from the assembled KKT function, built once and shared by the cold and the warm solver.
        Left to nlpsol, each solver would differentiate the flattened NLP symbolically: its SX
        Hessian is most of a solver's set-up (bench/results/compile_cost.md).  IPOPT's Hessian is
        that of γ f + λᵀg; ``hessian_fn`` gives ∇²f + Σ λ_i ∇²g_i, which is linear in λ, so

            ∇²(γ f + λᵀg) = H(z, p, λ) + (γ − 1) H(z, p, 0),

        the second term evaluated only when γ ≠ 1 (IPOPT's restoration phase).
        """
        if self._ipopt_derivatives is None:
            n, m, n_p = self.z_sym.shape[0], self.lbg.size, self.p_sym.shape[0]
            z, p, gamma, lam = (
                ca.MX.sym("x", n),
                ca.MX.sym("p", n_p),
                ca.MX.sym("lam_f"),
                ca.MX.sym("lam_g", m),
            )
            zero = ca.MX.zeros(m)
            hess = self.hessian_fn(z, p, lam) + ca.if_else(
                gamma == 1, ca.MX.zeros(n, n), (gamma - 1) * self.hessian_fn(z, p, zero), True
            )
            x, f = self.nlp["x"], self.nlp["f"]
            self._ipopt_derivatives = {
                # the gradient alone: the KKT function would evaluate the Hessian as well
                "grad_f": ca.Function(
                    "nlp_grad_f",
                    [x, self.nlp["p"]],
                    [f, ca.gradient(f, x)],
                    ["x", "p"],
                    ["f", "grad_f_x"],
                ),
                "jac_g": ca.Function(
                    "nlp_jac_g",
                    [z, p],
                    [self.g_fn(z, p), self.jac_g_fn(z, p)],
                    ["x", "p"],
                    ["g", "jac_g_x"],
                ),
                "hess_lag": ca.Function(
                    "nlp_hess_l",
                    [z, p, gamma, lam],
                    [ca.triu(hess)],
                    ["x", "p", "lam_f", "lam_g"],
                    ["triu_hess_gamma_x_x"],
                ),
            }
        return self._ipopt_derivatives
