"""The NLP of one scene structure, built once; everything that moves is a parameter.

    minimise   σ (U_bend + U_twist + U_stretch + U_grav − W)(z; p)
    subject to (x(s_g) − p_g)/L = 0                      every grip            (paper eq. 6)
               φ(s_g) − φ_g = 0, θ(s_g) − θ_g = 0        clamp, tangent grips  (eq. 7)
               ψ(s_g) − ψ_g = 0                          clamp grips, when twist is modelled
               (x(s_b) − x(s_a) − l)/L = 0               relative positions    (eq. 6)
               (h_i(x(σ_j)) + r)/L ≤ 0                   obstacles × samples   (eq. 8)
               (b_k − |T q_k|²)/L ≤ 0                    self-contact slots    (self_contact.py)

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

import functools
from typing import Any

import casadi as ca
import numpy as np

from ...model.director import DirectorModel
from ...model.obstacles import OBSTACLE_TYPES
from ...model.problem import Problem
from ...model.ritz import RitzModel
from ..native.blocks import NodeBlocks
from ..contact.obstacle_points import obstacle_arc_lengths, row_spacing, row_weights
from ..options import SolverOptions
from .assembled import AssembledKKT
from .mesh import MeshSpec, element_mesh
from .assembled_euler import AssembledEulerKKT
from .assembled_strip import AssembledStripKKT
from .assembled_values import value_functions
from .newton_function import newton_function
from .ipopt_functions import NLPSOL_OPTIONS, ipopt_derivatives, ipopt_options, ipopt_problem
from .constraint_rows import (
    ConstraintRows,
    RowSymbols,
    director_rows,
    grip_rows,
    obstacle_rows,
    relative_rows,
    self_contact_rows,
    slot_rows,
)
from .parameter_layout import ParameterLayout, parameter_layout, slot_matrix, slot_parameter_names
from .slot_envelope import shift_bound
from .reference_frame import GRIP_POLE_MIN_DEG, choose_reference_frame, planarity_violation
from .structure import (
    breakpoint_node,
    breakpoints,
    has_point_moments,
    is_strip,
    models_twist,
    twist_is_held,
)

#: What callers import from here: ``StringNLP``, and (re-exported from the modules that hold them)
#: the structure and reference-frame helpers.
__all__ = [
    "GRIP_POLE_MIN_DEG",
    "ParameterLayout",
    "StringNLP",
    "breakpoints",
    "choose_reference_frame",
    "has_point_moments",
    "models_twist",
    "planarity_violation",
    "twist_is_held",
]


class StringNLP:
    """CasADi functions of one scene structure: the NLP, reactions, energies, Hessian."""

    #: False on a clone onto another mesh (``mesh_clone.py``): nlp/g_sym are the template mesh's
    own_symbols: bool = True

    def __init__(
        self,
        problem: Problem,
        options: SolverOptions,
        reference_frame: np.ndarray | None = None,
        mesh_spec: MeshSpec | None = None,
    ):
        """Build the NLP of ``problem``'s structure with ``options``.

        reference_frame: R0 to use instead of ``choose_reference_frame`` (3D models only: a
        planar model's R0 is fixed by its plane).  mesh_spec: the element mesh a refinement chose
        (element models only; default: the scene's breakpoints, ``solver.order`` shared out).
        """
        problem.validate()
        options.validate()
        self.problem = problem
        self.options = options
        self.mesh_spec = mesh_spec
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
        if is_strip(problem) and not self.director and not self.planar:
            raise ValueError(
                "string.lateral_bend_stiffness: the Euler-angle model (solver.rotation 'euler') "
                "has one bending stiffness; use solver.rotation 'director'"
            )
        if self.director:
            mesh = element_mesh(problem, options, mesh_spec)
            # either model class: they share the interface NLPs use, and code for one only
            # (``director``) branches on ``self.director``
            self.model: Any = DirectorModel(
                L, mesh, self.twist, self.stretch, lateral=is_strip(problem)
            )
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
                mesh=(
                    element_mesh(problem, options, mesh_spec)
                    if options.basis == "elements"
                    else None
                ),
            )
        self.sigma = L / problem.string.bend_stiffness.maximum
        self._moment_stiffness: ca.Function | None = None
        #: IPOPT's derivative functions (``ipopt_derivatives``), built on first use
        self._ipopt_derivatives: dict[str, ca.Function] | None = None
        self._build()

    # ---------------------------------------------------------------------------------------------
    def _build(self) -> None:
        """Build the NLP: p's layout, the objective, the rows and the functions of both."""
        P, m = self.problem, self.model
        lay, slots = parameter_layout(P, m, self.director, self.options)
        self.obstacle_slots, self.self_contact_slots = slots.obstacle, slots.self_contact
        self.params = lay

        z = ca.SX.sym("z", m.layout.size)
        p = ca.SX.sym("p", lay.size)
        materials = ("Rf", "Rt", "Re", "D", *(("Rl",) if "Rl" in lay.slices else ()))
        profiles = {k: p[lay[k]] for k in (*materials, *m.material_sizes())}
        bend, twist, stretch, grav, t = m.energy_terms(z, profiles, p[lay["gravity"]])
        grip_x, load_x, rel_x, obs_x = self._positions(z, t)
        work = self._load_work(z, p, load_x)
        sym = RowSymbols(z, p, t, m, lay, self.length, self.director, self.planar, self.twist)
        rows = self._rows(sym, grip_x, rel_x, obs_x)

        objective = self.sigma * (bend + twist + stretch + grav - work)
        g = ca.vertcat(*rows.exprs) if rows.exprs else ca.SX(0, 1)
        self.row_kind: list[tuple] = rows.kind
        self.lbg, self.ubg = np.array(rows.lower), np.array(rows.upper)
        self.equality = self.lbg == self.ubg
        #: inequality rows a warm Newton update may make active (obstacle and self-contact rows:
        #: physical contacts; a fold guard at its bound is no equilibrium, so Newton leaves that to
        #: IPOPT)
        self.contact_row = np.array(
            [kind[0] in ("obstacle", "slot", "self") for kind in self.row_kind], dtype=bool
        )
        self.row_scale = np.array(rows.scale)
        self.switchable_rows = self.contact_row & ~self.equality  #: inequality contact rows
        self.switchable_rows.flags.writeable = False
        self.nlp = {"x": z, "p": p, "f": objective, "g": g}
        self.z_sym, self.p_sym, self.g_sym = z, p, g

        self.energy_fn = ca.Function("energy", [z, p], [bend, twist, stretch, grav, work])
        self._functions(z, p, g)

    def _positions(self, z: ca.SX, t: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
        """Return x at the grips, the loads, the relative positions' ends and the samples.

        x at the grips, the loads, the relative positions' ends and the obstacle samples.

        Every arc length where a position is needed is evaluated with one matrix product.  Sets
        ``obstacle_s``, the obstacle rows' arc lengths (``solver.obstacle_points``: uniform
        samples or the mesh's nodes, ``contact/obstacle_points.py``), ``obstacle_weights``, the
        quadrature weight [m] each row stands for, and ``obstacle_spacing`` [m], the spacing the
        contact slots measure in.
        """
        P = self.problem
        s_points: list[float] = [g.s for g in P.grips]
        s_points += [ld.s for ld in P.loads]
        for rel in P.relative_positions:
            s_points += [rel.s_a, rel.s_b]
        self.obstacle_s = obstacle_arc_lengths(P, self.options, self.model)
        self.obstacle_weights = row_weights(self.obstacle_s, self.options, self.model)
        self.obstacle_spacing = row_spacing(self.obstacle_s)
        s_all = np.concatenate([np.asarray(s_points, dtype=float), self.obstacle_s])
        X = self.model.positions_sym(z, t, s_all) if len(s_all) else ca.SX(3, 0)
        col = 0
        grip_x = X[:, col : col + len(P.grips)]
        col += len(P.grips)
        load_x = X[:, col : col + len(P.loads)]
        col += len(P.loads)
        rel_x = X[:, col : col + 2 * len(P.relative_positions)]
        col += 2 * len(P.relative_positions)
        obs_x = X[:, col:]
        return grip_x, load_x, rel_x, obs_x

    def _load_work(self, z: ca.SX, p: ca.SX, load_x: ca.SX) -> ca.SX:
        """W: the point loads' work (forces, and moments: pseudo-potential or −m·φ)."""
        P, m, lay = self.problem, self.model, self.params
        work = ca.SX(0)
        for i, _ in enumerate(P.loads):
            work += ca.dot(p[lay[f"load:{i}:force"]], load_x[:, i])
            if self.director:
                work += m.moment_work_sym(
                    z,
                    breakpoint_node(m.mesh, P.loads[i].s),
                    p[lay[f"load:{i}:moment"]],
                    p[lay[f"load:{i}:reference"]],
                )
            else:
                work -= p[lay[f"load:{i}:moment"]][0] * m.angle_sym(z, "phi", P.loads[i].s)
        return work

    def _rows(self, sym: RowSymbols, grip_x: ca.SX, rel_x: ca.SX, obs_x: ca.SX) -> ConstraintRows:
        """Write every row in order (``constraint_rows``) and keep each group's row indices."""
        P = self.problem
        rows = ConstraintRows()
        self.grip_rows, self.grip_axes = grip_rows(rows, sym, P.grips, grip_x, self.r0)
        #: per relative position: its rows and their axes (c_r in c_r · (x(s_b) − x(s_a) −
        #: offset) = 0)
        self.relative_axes = self.r0[:, :2].T if self.planar else np.eye(3)
        self.relative_rows = relative_rows(
            rows, sym, P.relative_positions, rel_x, self.relative_axes
        )
        if self.director:
            director_rows(rows, sym)
        samples, slots = len(self.obstacle_s), self.obstacle_slots
        self.obstacle_rows = obstacle_rows(rows, sym, P.obstacles, obs_x, samples, slots)
        #: per obstacle: its contact slots' rows
        self.slot_rows = slot_rows(rows, sym, P.obstacles, slots, shift_bound(self.length))
        self.self_contact_rows = self_contact_rows(rows, sym, self.self_contact_slots)
        self.n_grip_equalities = sum(
            len(r["position"]) + len(r["angles"]) for r in self.grip_rows.values()
        )
        return rows

    def _functions(self, z: ca.SX, p: ca.SX, g: ca.SX) -> None:
        """Build the functions of the objective and rows: KKT, Hessian, Jacobian, Newton, g."""
        P, lay = self.problem, self.params
        # Inequality rows come last.  Without them the KKT function is what a Newton update needs
        # while no obstacle row is active: most of the KKT work is x(s_j) at the obstacle samples.
        inequalities = np.flatnonzero(self.lbg != self.ubg)
        self.n_free_rows = nf = int(inequalities[0]) if inequalities.size else g.shape[0]
        # the rows before the obstacle rows are equalities with bound 0 (grips, relative positions)
        assert np.all(self.lbg[:nf] == 0.0) and np.all(self.ubg[:nf] == 0.0)
        # the inequality rows' values: once per update (the convergence check), not per Newton step
        self.obstacle_g_fn = None
        # assembled from per-quadrature-node derivatives (solver/build/assembled.py,
        # assembled_euler.py): compact code (seconds of gcc instead of minutes), a faster
        # interpreted call, and no flattened Hessian to build
        assembled = (
            (AssembledStripKKT(self) if self.model.lateral else AssembledKKT(self))
            if self.director
            else AssembledEulerKKT(self)
        )
        self._assembled = assembled
        #: E (d·M × n): the unknowns → the per-node values u_k (``assembled.py``), d = node_width
        self.node_map, self.node_width = assembled.E, assembled.d
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
        #: IPOPT's objective [f, ∇f] and every row's value g: assembled from p's mesh geometry
        #: (director models: ``assembled_values.py``), else the flattened expressions
        self.value_fns = value_functions(assembled, self.obstacle_g_fn)
        self.g_fn = self.value_fns[2] if self.value_fns else ca.Function("g", [z, p], [g])
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
        self.scene_parameter_rows = np.flatnonzero(~grip_only)  #: the other rows (H, J read them)
        # ∂g/∂p restricted to grip targets: constant (each target enters one row as −target/scale);
        # only those columns differentiated and kept (all of ∂g/∂p: 0.9 GB at 640 nodes)
        self._target_columns = np.flatnonzero(grip_only)
        dg_dp = ca.Function("dg_dp", [z, p], [ca.jacobian(g, p[self._target_columns.tolist()])])
        self._target_jacobian = np.asarray(dg_dp(np.zeros(z.shape[0]), np.zeros(lay.size)))

    @staticmethod
    def slot_parameters(i: int) -> tuple[str, ...]:
        """Return the names of obstacle i's slot parameters in p (``slot_parameter_names``)."""
        return slot_parameter_names(i)

    def disabled_rows(self, p: np.ndarray) -> np.ndarray:
        """Return the rows that p switches off (empty contact slots, replaced samples).

        Rows that p switches off (empty contact slots, samples a slot replaces): they read −1 ≤
        0 whatever the shape, so a warm start's multiplier on one belongs to no row of p.
        """
        off, lay = np.zeros(self.lbg.size, dtype=bool), self.params
        for i, rows in enumerate(self.slot_rows):
            off[rows] = p[lay[f"slots:{i}:on"]] == 0
            off[self.obstacle_rows[i]] = p[lay[f"samples:{i}:on"]] == 0
        return off

    def slot_matrix(self, p, i: int, part: str = "w"):
        """Return W(σ) (K × M) of obstacle i's slots from p (``part`` "t": P(σ), "k": P'(σ))."""
        return slot_matrix(p, self.params, i, self.obstacle_slots, self.model.quad.count, part)

    def moment_stiffness_fn(self) -> ca.Function:
        """Build the moment stiffness C that the pseudo-potential's Hessian lacks.

        The part of the exact equations' Jacobian that the pseudo-potential's Hessian lacks, at
        one load (director models).  The exact equations are ∇f and ∂g/∂z at p with every moment's
        centre q_ref set to its load's own normalised rotation N(v) = v/|v|
        (``ProblemParameters.centre_moments``): there ∇_v W_M = M·δθ exactly.  Their Jacobian is
        ∇²L (q_ref held) plus, at each load's node values v,

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
        """Fill p's material terms (stiffness matrices, weight moments) from its profiles.

        Fill p's material terms (stiffness matrices, weight moments) from its Rf, Rt, Re, D
        slices.
        """
        lay = self.params
        profiles = {k: p[lay[k]] for k in ("Rf", "Rt", "Re", "D")}
        for name, value in self.model.material_terms(profiles).items():
            p[lay[name]] = value.ravel(order="F")

    @functools.cached_property
    def _kkt_free(self) -> tuple[ca.Function, ca.Function]:
        # built on first use: the passes of a cold refinement on contact never evaluate it
        return self._assembled.kkt_free()

    @property
    def kkt_free_fn(self) -> ca.Function:
        """The KKT function of the rows before the obstacle rows (module docstring)."""
        return self._kkt_free[0]

    @property
    def residual_free_fn(self) -> ca.Function:
        """``kkt_free_fn``'s residual alone."""
        return self._kkt_free[1]

    @functools.cached_property
    def jac_g_fn(self) -> ca.Function:
        """The rows' Jacobian ∂g/∂z, IPOPT's alone: built with its first IPOPT solver."""
        return self._assembled.jacobian()

    @functools.cached_property
    def newton_fn(self) -> ca.Function:
        """A contact-free warm update's first Newton steps as one function (newton_function.py)."""
        return newton_function(self)

    @functools.cached_property
    def kkt_free_split_fn(self) -> ca.Function:
        """``kkt_free_fn`` with K's per-node Hessian part Eᵀ W left out and W last.

        Built by ``assembled.py``: what the compiled contact-free loop evaluates, adding Eᵀ W by
        BLAS.
        """
        return self._assembled.kkt_free_split()

    @functools.cached_property
    def node_blocks(self):
        """The node map as the dense blocks the compiled functions add Eᵀ W by, once per NLP."""
        return NodeBlocks(self.node_map, self.node_width)

    @property
    def kkt_split_fn(self) -> ca.Function:
        """``kkt_fn`` split as ``kkt_free_split_fn`` (the compiled active-set loop's)."""
        return self._kkt_split[0]

    @property
    def contact_sizes(self) -> tuple[int, ...]:
        """The sizes of ``kkt_split_fn``'s curvature blocks (``contact_blocks``)."""
        return self._kkt_split[1]

    @functools.cached_property
    def _kkt_split(self) -> tuple[ca.Function, tuple[int, ...]]:
        return self._assembled.kkt_split()

    def target_shift(self, p_old: np.ndarray, p_new: np.ndarray) -> np.ndarray:
        """Return g(z, p_new) − g(z, p_old) when only grip targets differ (exact: g is linear)."""
        columns = self._target_columns
        return self._target_jacobian @ (p_new[columns] - p_old[columns])

    # ---------------------------------------------------------------------------------------------
    def make_solver(
        self, warm: bool, max_iterations: int | None = None, max_wall_time: float = 0.0
    ) -> ca.Function:
        """Build an IPOPT solver for this NLP, cold or warm (``ipopt_functions.ipopt_options``)."""
        ipopt = ipopt_options(self.options, warm, max_iterations, max_wall_time)
        return ca.nlpsol(
            "dlo_warm" if warm else "dlo_cold",
            "ipopt",
            self.ipopt_nlp,
            {
                "ipopt": ipopt,
                **NLPSOL_OPTIONS,
                **self.ipopt_derivatives(),
            },
        )

    @functools.cached_property
    def ipopt_nlp(self) -> dict[str, ca.MX]:
        """The problem nlpsol is given (``ipopt_functions.ipopt_problem``), made once per NLP."""
        return ipopt_problem(self.nlp, self.g_fn, self.value_fns)

    def ipopt_derivatives(self) -> dict[str, ca.Function]:
        """Give IPOPT's derivative functions, built once and shared by the cold and warm solver.

        See ``ipopt_functions.ipopt_derivatives``.
        """
        if self._ipopt_derivatives is None:
            self._ipopt_derivatives = ipopt_derivatives(
                self.nlp, self.hessian_fn, self.g_fn, self.jac_g_fn, self.value_fns
            )
        return self._ipopt_derivatives
