"""A returned shape's outputs as one CasADi function.

For frame director models and the planar model, without self-contact slots.

``ShapeOutputs`` builds a result from many small numpy evaluations: the centreline and frames at
the output points, each grip's reaction, each obstacle's contact force and the equilibrium residual
(``wrenches.py``, ``residual.py``).  For a director model with frames (the default 3D model) and
for the planar model (what ``solver.model: auto`` streams while a scene stays in its plane) every
one of them is a fixed composition of matrix products with the structure's constant interpolation
matrices, so this module writes them as one function

    outputs(z, p, λ, prof) → (x(s_out), q(s_out), F_grips, T_grips, F_obstacles, residual, flip, T)

evaluated in one call (compiled C when the solver's derivatives are compiled, CasADi's virtual
machine until then). ``λ``: every row's SI multiplier; ``prof`` = (Rf, Rt, a strip's Rl) at the
residual's grid and Rf_min, from the string (``OutputFunction.profiles``); ``q``: the published
orientations, the interpolated nodal quaternions made unit with ``director.frame_to_quat``'s sign
(4 × K), for the planar model φ (1 × K); ``flip``: per grip t·R_g e_x and d1·R_g e_y at its node
(negative: the flipped sheet, ``frames.flipped_grips``; ones for the planar model, which has no
flipped sheet); ``T``: (1 + ε) t̂ at the quadrature nodes (3 × M), the centreline anywhere in one
product (``DirectorModel.positions_with``: the samples of ``results/self_pass.py``).

The arithmetic is the numpy path's, term for term (``wrenches.wrench``, ``wrenches.equilibrium``,
``residual.equilibrium_residual``), on the same grid (``wrenches.residual_grid``: split at the
grips, the point loads, the relative positions' ends, the mesh breakpoints and the obstacle
rows), with every obstacle sample as a point action (one that does not touch has λ = 0 and acts
with zero force).  Both paths agree to rounding (test_output_function.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from ...model.director import frame_columns
from ...model.problem import Problem, StringProperties
from .nlp import StringNLP
from .slot_envelope import action_function, shift_bound, slot_curve, slot_inputs
from .structure import breakpoint_node
from ..results.residual import ResidualGrid
from ..results.wrenches import residual_grid


#: the outputs' function's outputs, in order (the module docstring); ``TANGENTS``: where the
#: quadrature tangents are, after the published outputs (``results/outputs.py``) that come first
OUTPUTS: tuple[str, ...] = ("points", "quaternions", "grip_forces", "grip_torques", "contacts")
OUTPUTS += ("residual", "flip", "tangents")
TANGENTS = OUTPUTS.index("tangents")


def _unit_quaternion() -> ca.Function:
    """Build the function v → the unit quaternion of v, with ``frame_to_quat``'s sign.

    The unit quaternion (x, y, z, w) of a non-zero quaternion v, with the sign
    ``director.frame_to_quat`` gives its rotation matrix: the component Shepperd's method takes
    from the first largest of 1 + trace and 1 + 2 R_aa − trace (times |v|²: 4 w², 4 x², 4 y²,
    4 z²) is positive.
    Where two candidates tie to rounding the two may pick q and −q: the same rotation.
    """
    v = ca.SX.sym("v", 4)
    x2, y2, z2, w2 = v[0] * v[0], v[1] * v[1], v[2] * v[2], v[3] * v[3]
    a = [3 * w2 - x2 - y2 - z2, w2 + x2 - y2 - z2, w2 - x2 + y2 - z2, w2 - x2 - y2 + z2]
    component = [v[3], v[0], v[1], v[2]]
    chosen = ca.if_else(a[2] >= a[3], component[2], component[3])
    chosen = ca.if_else(ca.logic_and(a[1] >= a[2], a[1] >= a[3]), component[1], chosen)
    chosen = ca.if_else(
        ca.logic_and(ca.logic_and(a[0] >= a[1], a[0] >= a[2]), a[0] >= a[3]), component[0], chosen
    )
    return ca.Function(
        "unit_quaternion", [v], [ca.if_else(chosen < 0, -v, v) / ca.sqrt(ca.dot(v, v))]
    )


def _cross(a: ca.MX, b: ca.MX) -> ca.MX:
    """Column-wise a × b of 3×K matrices (b may be one column: it is broadcast)."""
    if b.shape[1] == 1 and a.shape[1] > 1:
        b = ca.repmat(b, 1, a.shape[1])
    if a.shape[1] == 1 and b.shape[1] > 1:
        a = ca.repmat(a, 1, b.shape[1])
    return ca.vertcat(
        a[1, :] * b[2, :] - a[2, :] * b[1, :],
        a[2, :] * b[0, :] - a[0, :] * b[2, :],
        a[0, :] * b[1, :] - a[1, :] * b[0, :],
    )


def _cumulative(f: ca.MX, operators: tuple) -> tuple[ca.MX, ca.MX]:
    """Return ∫_0^s f dσ at the grid's points and at its knots, f (3 × K) at the points.

    ``ResidualGrid.cumulative`` along the columns of f, by its ``operators`` (P, Q, E) as sparse
    DMs (the same sums).
    """
    P, Q, E = operators
    at_knots = ca.horzcat(ca.DM.zeros(3), ca.cumsum(ca.mtimes(f, P), 1))
    return ca.mtimes(at_knots[:, :-1], E) + ca.mtimes(f, Q), at_knots


def _column_norms_max(a: ca.MX) -> ca.MX:
    return ca.mmax(ca.sqrt(ca.sum1(a * a)))


def _slot_contacts(nlp, problem, z, p, lam, tq, s, x, m_bal, total_force, contact_totals):
    """Add the contact slots' forces to the moment balance, the force and ``contact_totals``.

    Contact slots (solver/contact/obstacle_slots.py): their arc lengths are parameters, so the
    running sums over s_a < s are a 0/1 matrix of p instead of fixed columns.  Returns the moment
    balance and the force.
    """
    lay, L, K = nlp.params, nlp.length, len(s)
    for i, ob in enumerate(problem.obstacles if nlp.obstacle_slots else ()):
        n_slots, on = nlp.obstacle_slots, p[lay[f"slots:{i}:on"]]
        # where each slot's force acts and its line (build/slot_envelope.py)
        X = slot_curve(nlp, tq, z, p, i)
        action = action_function(ob.type, shift_bound(L)).map(n_slots)
        shift, grads = action(*X, *slot_inputs(nlp, p, i))
        slot_x = X[0] + ca.repmat(shift, 3, 1) * X[1]
        f = -ca.repmat((ca.fmax(lam[nlp.slot_rows[i]], 0) * on).T, 3, 1) * grads
        contact_totals[i] += ca.sum2(f)
        # K × grid
        slot_s = p[lay[f"slots:{i}:s"]] + shift.T
        before = ca.repmat(slot_s, 1, K) < ca.repmat(ca.DM(s).T, n_slots, 1)
        m_bal -= ca.mtimes(_cross(slot_x, f), before) - _cross(x, ca.mtimes(f, before))
        total_force += ca.sum2(f)
    return m_bal, total_force


@dataclass
class _Fields:
    """The model's fields as symbols, as the outputs read them.

    The model's fields as symbols: the tangents at the quadrature nodes, and what else the
    outputs read (the planar model's φ coefficients and plane normal; the director model's nodal
    values and their frame function).
    """

    planar: bool
    #: the residual's grid s
    grid: np.ndarray
    #: T (3 × M): the tangents (1 + ε) t̂ at the quadrature nodes
    tq: ca.MX
    # each of these is set for one model only (planar: c_phi, normal; director: nodes_v,
    # frame_cols, vs), and read only in that model's branches: typed Any, not Optional
    c_phi: Any = None  # ca.MX
    normal: Any = None  # ca.DM
    nodes_v: Any = None  # ca.MX
    frame_cols: Any = None  # ca.Function
    vs: Any = None  # ca.MX


def _fields(nlp: StringNLP, z: ca.MX, grid: np.ndarray) -> _Fields:
    """Read the model's fields from z (see ``_Fields``)."""
    m, M = nlp.model, nlp.model.quad.count
    if not nlp.director:
        # the planar model: φ(s) in the plane of R0's first two columns, θ ≡ π/2, ψ constant
        c_phi, c_eps = m.coefficients(z, "phi"), m.coefficients(z, "eps")
        tq = m.tangents(
            ca.mtimes(ca.DM(m.B), c_phi),
            None,
            ca.mtimes(ca.DM(m.B), c_eps) if c_eps is not None else None,
            lib=ca,
        )
        return _Fields(True, grid, tq, c_phi=c_phi, normal=ca.DM(nlp.r0[:, 2]))
    # column i: node i
    nodes_v = ca.reshape(z[m.layout.rotation], m.layout.width, m.layout.nodes)
    vs = ca.MX.sym("v", 4)
    # (t, d1, d2) of a quaternion, stacked: at the quadrature nodes, at the residual's grid, at
    # the grips
    frame_cols = ca.Function(
        "frame_cols",
        [vs],
        [ca.vertcat(*(ca.vertcat(*c) for c in frame_columns(ca.vertsplit(vs), ca)))],
    )
    # t̂ at the quadrature nodes
    tq = frame_cols.map(M)(ca.mtimes(nodes_v, ca.DM(m.B.T)))[0:3, :]
    if m.layout.stretch:
        tq = tq * ca.repmat(1 + ca.mtimes(ca.DM(m.B), z[m.layout.eps]).T, 3, 1)
    return _Fields(False, grid, tq, nodes_v=nodes_v, frame_cols=frame_cols, vs=vs)


def _positions(nlp: StringNLP, problem: Problem, f: _Fields, z: ca.MX, s_out: np.ndarray):
    """Return x at the grid, the nodes, the point actions, the samples and s_out.

    x at the grid, the quadrature nodes, the point actions, the obstacle samples and s_out.

    Returns those five (3 × ·) blocks, the integration (or position) matrix of all of them, and the
    point actions' arc lengths (grips, loads, the relative positions' ends).
    """
    m, L, s = nlp.model, nlp.length, f.grid
    point_s = np.array(
        [g.s for g in problem.grips] + [ld.s for ld in problem.loads] + problem.relative_ends(),
        dtype=float,
    )
    s_out = np.asarray(s_out, dtype=float)
    pieces = [s, m.quad.nodes, point_s, nlp.obstacle_s, s_out]
    splits = np.cumsum([len(a) for a in pieces])
    w_all = (
        m.position_matrix(np.concatenate(pieces))
        if f.planar
        else m.mesh.integration_matrix(np.concatenate(pieces))
    )
    x_all = ca.repmat(z[0:3] * L, 1, int(splits[-1])) + ca.mtimes(f.tq, ca.DM(w_all.T))
    x, x_nodes, point_x, sample_x, x_out = (
        x_all[:, a:b] for a, b in zip([0, *splits[:-1]], splits)
    )
    return x, x_nodes, point_x, sample_x, x_out, w_all, point_s


def _weight_balance(nlp: StringNLP, p: ca.MX, gravity: ca.MX, x, x_nodes, w_grid: np.ndarray):
    """Return the weight's moment about x(s) at the grid, and the total weight.

    The weight's moment about x(s) at the grid, and the total weight per unit gravity.

    From the weight's integrals ∫_0^s D dσ and ∫_0^s D x dσ, and its total.
    """
    lay, m = nlp.params, nlp.model
    d_nodes = p[lay["D"]]
    weight = ca.mtimes(ca.DM(w_grid), d_nodes).T
    weight_moment = ca.mtimes(x_nodes * ca.repmat(d_nodes.T, 3, 1), ca.DM(w_grid.T))
    total = ca.dot(ca.DM(m.quad.weights), d_nodes)
    m_bal = -(_cross(weight_moment, gravity) - _cross(x, gravity) * ca.repmat(weight, 3, 1))
    return m_bal, total


def _load_actions(nlp: StringNLP, problem: Problem, f: _Fields, p, lam, forces, torques) -> None:
    """Append the loads' and the relative positions' point actions to ``forces``, ``torques``."""
    lay = nlp.params
    for k, _ in enumerate(problem.loads):
        forces.append(p[lay[f"load:{k}:force"]])
        # the planar model's: its component along n (checked)
        moment = p[lay[f"load:{k}:moment"]]
        torques.append(moment[0] * f.normal if f.planar else moment)
    for rows in nlp.relative_rows:  # wrenches.relative_forces: −F_b at s_a, F_b at s_b
        f_b = -ca.mtimes(ca.DM(nlp.relative_axes.T), lam[rows])
        forces += [-f_b, f_b]
        torques += [ca.DM.zeros(3), ca.DM.zeros(3)]


def _constitutive_moment(
    nlp: StringNLP, f: _Fields, s: np.ndarray, rf: ca.MX, rt: ca.MX, rl: ca.MX
):
    """Return the constitutive moment at the grid s.

    The constitutive moment at the grid s: R diag(Rt, Rf, Rl) Ω (Rl = Rf but for a strip); the
    planar model's −Rf φ' n
    (``wrenches.euler_moments`` at θ ≡ π/2, no twist).
    """
    m = nlp.model
    if f.planar:
        return ca.mtimes(-f.normal, rf * ca.mtimes(ca.DM(m.matrices(s)[1]), f.c_phi).T)
    vs = f.vs
    b_grid, db_grid = m.mesh.interpolation(s, "left")
    vsd = ca.MX.sym("dv", 4)
    c = ca.MX.sym("c", 3)
    cols = f.frame_cols(vs)
    t, d1, d2 = cols[0:3], cols[3:6], cols[6:9]
    qv, w, dqv, dw = vs[0:3], vs[3], vsd[0:3], vsd[3]
    omega = 2 * (w * dqv - dw * qv - ca.cross(qv, dqv)) / ca.dot(vs, vs)
    moment_fn = ca.Function(
        "moment_c",
        [vs, vsd, c],
        [t * c[0] * omega[0] + d1 * c[1] * omega[1] + d2 * c[2] * omega[2]],
    )
    return moment_fn.map(len(s))(
        ca.mtimes(f.nodes_v, ca.DM(b_grid.T)),
        ca.mtimes(f.nodes_v, ca.DM(db_grid.T)),
        ca.vertcat(rt, rf, rl),
    )


def _grip_actions(nlp: StringNLP, problem: Problem, f: _Fields, p: ca.MX, lam: ca.MX):
    """Each grip's force, torque and flip (``wrenches.wrench``), as three lists."""
    m, lay = nlp.model, nlp.params
    forces: list[Any] = []
    torques: list[Any] = []
    flips: list[Any] = []
    for g in problem.grips:
        rows = nlp.grip_rows[g.name]
        force = -ca.mtimes(ca.DM(nlp.grip_axes[g.name].T), lam[rows["position"]])
        if f.planar:  # only φ is held: the torque is along the plane normal, n·T = μ_φ
            forces.append(force)
            torques.append(lam[rows["angles"][0]] * f.normal if rows["angles"] else ca.DM.zeros(3))
            flips.append(ca.DM.ones(2))  # no flipped sheet: φ is the tangent's angle itself
            continue
        cols = f.frame_cols(f.nodes_v[:, breakpoint_node(m.mesh, g.s)])
        tg, d1g = cols[0:3], cols[3:6]
        target = ca.reshape(p[lay[f"grip:{g.name}:frame"]], 3, 3)
        torque: Any = ca.DM.zeros(3)
        if rows["angles"]:
            mu = lam[rows["angles"]]
            torque = -(mu[0] * ca.cross(tg, target[:, 1]) + mu[1] * ca.cross(tg, target[:, 2]))
            if len(rows["angles"]) == 3:
                torque -= mu[2] * ca.cross(d1g, target[:, 2])
        forces.append(force)
        torques.append(torque)
        flips.append(ca.vertcat(ca.dot(tg, target[:, 0]), ca.dot(d1g, target[:, 1])))
    return forces, torques, flips


def _sample_contacts(nlp: StringNLP, problem: Problem, p: ca.MX, lam: ca.MX, sample_x: ca.MX):
    """Every obstacle's forces at the samples: (their sum over obstacles, per obstacle total).

    A row that does not touch acts with no force, nor does a sample a contact slot replaces.
    """
    lay, samples = nlp.params, len(nlp.obstacle_s)
    sample_f, contact_totals = None, []
    for i, ob in enumerate(problem.obstacles):
        grads = nlp.obstacle_gradient[ob.type].map(samples)(
            sample_x, ca.repmat(p[lay[f"obstacle:{i}"]], 1, samples)
        )
        # a row that does not touch acts with no force
        lam_i = ca.fmax(lam[nlp.obstacle_rows[i]], 0).T
        if nlp.obstacle_slots:  # nor does a sample a contact slot replaces
            lam_i = lam_i * p[lay[f"samples:{i}:on"]].T
        f = -ca.repmat(lam_i, 3, 1) * grads
        contact_totals.append(ca.sum2(f))
        sample_f = f if sample_f is None else sample_f + f
    return sample_f, contact_totals


def _running_sums(
    groups: list, s: np.ndarray, x: ca.MX, m_bal: ca.MX, total_force: ca.MX
) -> tuple[ca.MX, ca.MX]:
    """Apply each sorted group's running sums to the moment balance and the force.

    Subtract each sorted group's running sums Σ_{s_a < s} (x_a − x(s)) × F_a + T_a from the
    moment balance and add its total to the force; return both.
    """
    for c_a, f_a, s_a in groups:
        # how many of the group lie strictly before s
        before = np.searchsorted(s_a, s, side="left").tolist()
        run_c = ca.horzcat(ca.DM.zeros(3), ca.cumsum(c_a, 1))
        run_f = ca.horzcat(ca.DM.zeros(3), ca.cumsum(f_a, 1))
        m_bal -= run_c[:, before] - _cross(x, run_f[:, before])
        total_force += run_f[:, -1]
    return m_bal, total_force


def _gradient_operator(s: np.ndarray) -> ca.DM:
    """np.gradient(·, s) along a K-point grid as a sparse K × K matrix D (tridiagonal).

    np.gradient of the indicator of the columns ≡ j (mod 3) gives in row r D's entry of column
    r + ((j − r + 1) mod 3) − 1 (one of r − 1, r, r + 1): three gradients, not the identity's.
    """
    K, r = len(s), np.arange(len(s))
    parts = []
    for j in range(3):
        d, c = np.gradient((r % 3 == j).astype(float), s), r + (j - r + 1) % 3 - 1
        keep = (d != 0.0) & (c >= 0) & (c < K)
        parts.append((r[keep], c[keep], d[keep]))
    rows, cols, vals = (np.concatenate(a) for a in zip(*parts))
    return ca.DM.triplet(rows.tolist(), cols.tolist(), ca.DM(vals), K, K)


def _residual(
    grid: ResidualGrid,
    x: ca.MX,
    delta: ca.MX,
    total_force: ca.MX,
    rf: ca.MX,
    rf_min: ca.MX,
    L: float,
) -> ca.MX:
    """Return (d_m, d_f, metres) as ``residual.equilibrium_residual`` from the imbalance."""
    s = grid.s
    d_m = _column_norms_max(delta)
    d_f = ca.norm_2(total_force)
    tangent = ca.mtimes(x, _gradient_operator(s).T)
    operators = tuple(
        ca.DM.triplet(a.row.tolist(), a.col.tolist(), ca.DM(a.data), *a.shape)
        for a in grid.operators()
    )
    phi = _cumulative(delta / ca.repmat(rf, 3, 1), operators)[0]
    dx, dx_knots = _cumulative(_cross(phi, tangent), operators)
    worst = ca.fmax(_column_norms_max(dx), _column_norms_max(dx_knots))
    metres = worst + d_f * L**3 / (3 * rf_min)
    return ca.vertcat(d_m, d_f, metres)


def _orientations(nlp: StringNLP, f: _Fields, s_out: np.ndarray) -> ca.MX:
    """Return the orientations at the outputs.

    The orientations at the outputs: the planar model's φ (``frames.frames_psi`` and
    ``pose_quaternions``), the director model's unit quaternions.
    """
    m = nlp.model
    if f.planar:
        return ca.mtimes(ca.DM(m.matrices(s_out)[0]), f.c_phi).T
    v_out = ca.mtimes(f.nodes_v, ca.DM(m.mesh.interpolation(s_out, "left")[0].T))
    return _unit_quaternion().map(len(s_out))(v_out)


class OutputFunction:
    """The outputs of one NLP's solutions as one CasADi function (module docstring)."""

    def __init__(self, nlp: StringNLP, problem: Problem, s_out: np.ndarray):
        m, L, lay = nlp.model, nlp.length, nlp.params
        self.grip_names = [g.name for g in problem.grips]
        self.residual_grid = residual_grid(nlp, problem)
        self.grid = s = self.residual_grid.s
        K = len(s)
        z = ca.MX.sym("z", m.layout.size)
        p = ca.MX.sym("p", lay.size)
        lam = ca.MX.sym("lam", int(nlp.lbg.size))
        #: a strip: prof carries Rl (its stiffness about d2) between Rt and Rf_min
        self.lateral = bool(getattr(m, "lateral", False))
        prof = ca.MX.sym("prof", (3 if self.lateral else 2) * K + 1)
        rf, rt, rf_min = prof[:K].T, prof[K : 2 * K].T, prof[prof.shape[0] - 1]
        rl = prof[2 * K : 3 * K].T if self.lateral else rf

        f = _fields(nlp, z, s)
        self.planar = f.planar
        x, x_nodes, point_x, sample_x, x_out, w_all, point_s = _positions(
            nlp, problem, f, z, s_out
        )
        moment_c = _constitutive_moment(nlp, f, s, rf, rt, rl)

        gravity = p[lay["gravity"]]
        m_bal, total = _weight_balance(nlp, p, gravity, x, x_nodes, w_all[:K, :])

        # point actions at fixed arc lengths: grips (wrenches.wrench), loads, the relative
        # positions' ends
        forces, torques, flips = _grip_actions(nlp, problem, f, p, lam)
        grip_forces, grip_torques, flip = (ca.horzcat(*a) for a in (forces, torques, flips))
        _load_actions(nlp, problem, f, p, lam, forces, torques)
        total_force = total * gravity
        # Σ_{a: s_a < s} (x_a − x(s)) × F_a + T_a = C(s) − x(s) × F(s), with C and F running sums
        # over the actions sorted by s: the point actions and the obstacle samples (every
        # obstacle's force at a sample summed: they share the samples) as two sorted groups
        order = np.argsort(point_s, kind="stable")
        point_f = ca.horzcat(*(forces[k] for k in order))
        point_c = _cross(point_x[:, order.tolist()], point_f) + ca.horzcat(
            *(torques[k] for k in order)
        )
        groups = [(point_c, point_f, point_s[order])]
        contact_totals = []
        if problem.obstacles:
            sample_f, contact_totals = _sample_contacts(nlp, problem, p, lam, sample_x)
            groups.append((_cross(sample_x, sample_f), sample_f, np.asarray(nlp.obstacle_s)))
            m_bal, total_force = _slot_contacts(
                nlp, problem, z, p, lam, f.tq, s, x, m_bal, total_force, contact_totals
            )
        self.n_obstacles = len(problem.obstacles)
        m_bal, total_force = _running_sums(groups, s, x, m_bal, total_force)
        residual = _residual(self.residual_grid, x, moment_c - m_bal, total_force, rf, rf_min, L)

        v_out = _orientations(nlp, f, np.asarray(s_out, dtype=float))
        zero = ca.DM.zeros(3, 0)
        self.function = ca.Function(
            "dlo_outputs",
            [z, p, lam, prof],
            [
                x_out,
                v_out,
                grip_forces,
                grip_torques,
                ca.horzcat(*contact_totals) if contact_totals else zero,
                residual,
                flip,
                f.tq,
            ],
            ["z", "p", "lam", "prof"],
            list(OUTPUTS),
        )
        self._profile_key: tuple | None = None

    @staticmethod
    def applies(nlp: StringNLP) -> bool:
        """Tell whether the outputs' function applies to ``nlp``.

        Director models with frames and the planar model, without self-contact slots (others,
        the tangent director model and the 3D Euler-angle model: the numpy path).
        """
        if nlp.self_contact_slots:
            return False
        return bool(nlp.model.layout.frame if nlp.director else nlp.model.layout.planar)

    def profiles(self, string: StringProperties) -> np.ndarray:
        """Return ``prof``: Rf, Rt (a strip's Rl) [N·m²] at the grid and Rf_min.

        ``prof``: Rf, Rt (and a strip's Rl) [N·m²] at the grid and Rf_min, remembered for the
        last string object.
        """
        key = self._profile_key
        if key is None or key[0] is not string:
            s = self.grid
            prof = np.concatenate(
                [
                    string.bend_stiffness(s),
                    string.twist_stiffness(s),
                    string.lateral_stiffness(s) if self.lateral else [],
                    [string.bend_stiffness.minimum],
                ]
            )
            self._profile_key = key = (string, prof)
        return key[1]
