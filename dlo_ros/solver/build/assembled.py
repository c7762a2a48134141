"""The KKT functions of a director model, assembled from per-quadrature-node derivatives.

The KKT functions of a director model, assembled from per-quadrature-node derivatives (the
planar and Euler-angle models reuse this with their own per-node parts: ``assembled_euler.py``).

``StringNLP.kkt_free_fn`` differentiates one flattened expression of the whole Lagrangian: its C is
straight-line code (a dense Hessian expanded at every quadrature node) that gcc needs minutes for.
This module builds the same function (same inputs, outputs and row order) from the Lagrangian's
structure, so that its code is a loop over quadrature nodes plus a few sparse matrix products:

    L(z, λ) = Σ_k φ_k(u_k) + ℓ(z, λ) + Λ(z, λ)

* u_k = E_k z = (v(σ_k), v'(σ_k), ε(σ_k)): the rotation field (quaternion or tangent), its
  s-derivative and the strain at quadrature node σ_k — one row block of the constant sparse E;
* φ_k = σ [½ w_k Rf_k b(u_k) + ½ w_k Rt_k τ(u_k) + ½ w_k Re_k ε_k²] + a_k · T(u_k),  T = (1 + ε)
  t̂,
  with b, τ the bend and twist integrands (``director.integrands``) and a_k ∈ R³ every term that is
  linear in the positions x(s) = x0 + Σ_k W_k(s) T_k:
      a_k = −σ m_k ĝ − σ Σ_i W_k(s_i) F_i + Σ_r λ_r W_rk c_r / L_r
  (gravity through the weight moments m, point forces, and the position rows r: c_r · (x(s) −
  target) or c_r · (x(s_b) − x(s_a) − offset), scaled by L_r);
* ℓ: the same terms' part in x0 = z[0:3] L (linear in z: no Hessian);
* Λ: the rows local to one node (unit norm, a grip's orientation) and the point moments'
  pseudo-potentials, small CasADi SX expressions of a node's values differentiated directly.

Hence ∇L = Eᵀ [∇φ_k]_k + ∇ℓ + ∇Λ,  ∇²L = Eᵀ diag(∇²φ_k) E + ∇²Λ,  and a position row's Jacobian is
c_r·∂x/∂z = κ_r c_r ⊗ (∂x0/∂z) + Σ_k W_rk c_r·(∂T/∂u)_k E_k.  The per-node derivatives (∇φ_k,
∇²φ_k, ∂T/∂u) come from one small SX function mapped over the nodes (a loop in C).
"""

from __future__ import annotations

import functools
from typing import Any

import casadi as ca
import numpy as np

from ...model.director import DirectorModel, integrands
from .structure import breakpoint_node
from .assembled_contact import (
    contact_blocks,
    group_terms,
    in_row_order,
    inequality_g,
    nonlinear_rows,
    sparse,
    spread,
    x0_columns,
)
from .assembled_local import local_rows_function
from .mesh_parameters import KktGeometry, node_map_of


class AssembledKKT:
    """Builds the KKT functions of a director-model ``StringNLP`` (module docstring).

    The model-specific parts are ``_node_map``, ``_node_coefficients``, ``node_function``,
    ``tangent_function`` and ``direct_terms``; ``assembled_euler.AssembledEulerKKT`` overrides
    them for the Euler-angle models (planar and 3D).
    """

    #: a DirectorModel here, a RitzModel in AssembledEulerKKT (each class reads its own's members)
    model: Any

    def __init__(self, nlp) -> None:
        model = nlp.model
        if not isinstance(model, DirectorModel):
            raise TypeError("the assembled KKT function needs a director model")
        self.nlp, self.model = nlp, model
        self._local_functions: dict[bytes, ca.Function] = {}  # local_function's, by rows
        lay = model.layout
        self.width, self.stretch, self.frame = lay.width, lay.stretch, lay.frame
        self.d = 2 * lay.width + int(lay.stretch)  # per-node unknowns u_k
        self.M = model.quad.count
        self.n = lay.size
        self.E = self._node_map()
        #: the node map, weights and integration rows: read from p (``mesh_parameters.py``)
        self.geometry = KktGeometry(self)
        self._rows()

    # ---- constants ------------------------------------------------------------------------------
    def _node_map(self) -> np.ndarray:
        """E (d·M × n): row j + d k of E z is component j of u_k (E is block-sparse by element)."""
        mesh = self.model.mesh
        return node_map_of(self.model.layout, self.d, mesh.B, mesh.dB)

    def _rows(self) -> None:
        """Sort the rows into position rows, node-local rows and rows nonlinear in x.

        Sort the rows: position rows (c_r, the arc lengths of W_r, κ_r, target), node-local rows,
        and (left to ``_nonlinear_rows``) obstacle rows and self-contact slots.  W_r and the
        loads' W are ``KktGeometry.rows`` of those arc lengths.
        """
        nlp, P = self.nlp, self.nlp.problem
        grips = {g.name: g for g in P.grips}
        pos, local = [], []
        C, kappa = [], []
        at: list[tuple[float, ...]] = []  # the arc lengths of each position row's W (b − a)
        target = np.zeros((0, nlp.params.size))
        for r, kind in enumerate(nlp.row_kind):
            row_target = np.zeros(nlp.params.size)
            if kind[0] == "grip" and kind[2] == "position":
                axis = np.array(kind[3], dtype=float)
                g = grips[kind[1]]
                C.append(axis)
                at.append((g.s,))
                kappa.append(1.0)
                row_target[nlp.params[f"grip:{g.name}:position"]] = axis
            elif kind[0] == "relative":
                rel = P.relative_positions[kind[1]]
                axis = (nlp.r0[:, :2].T if nlp.planar else np.eye(3))[
                    kind[2]
                ]  # as StringNLP's rows
                C.append(axis)
                at.append((rel.s_a, rel.s_b))
                kappa.append(0.0)
                row_target[nlp.params[f"relative:{kind[1]}"]] = axis
            elif kind[0] in (
                "obstacle",
                "slot",
                "self",
            ):  # nonlinear in the positions: _nonlinear_rows
                continue
            else:
                local.append(r)
                continue
            pos.append(r)
            target = np.vstack([target, row_target])
            if not np.isclose(nlp.row_scale[r], nlp.length):
                raise ValueError(f"position row {kind} is not scaled by L")
        self.pos_rows, self.local_rows = np.array(pos, dtype=int), np.array(local, dtype=int)
        self.C = np.array(C).reshape(-1, 3)
        self.kappa = np.array(kappa)
        self.target = target
        #: the arc lengths of the position rows' and the loads' W (``KktGeometry.rows``)
        self.position_points, self.load_points = at, [(ld.s,) for ld in P.loads]

    # ---- the per-node function ------------------------------------------------------------------
    def _node_coefficients(self, p, a):
        """c_k (a column per node) of ``node_function`` from the parameters and a_k (3 × M)."""
        lay, weights = self.nlp.params, self.geometry.weights(p)
        return ca.vertcat(
            weights * p[lay["Rf"]].T, weights * p[lay["Rt"]].T, weights * p[lay["Re"]].T, a
        )

    @functools.cached_property
    def node_function(self) -> ca.Function:
        """Build the per-node function: energies, T_k and φ_k's derivatives from (u_k, c_k).

        (u_k, c_k) → [bend_k, twist_k, stretch_k, T_k, ∇φ_k, ∇²φ_k, ∂T/∂u]; c_k = (w Rf, w Rt, w
        Re, a_k).
        """
        w, d = self.width, self.d
        u, c = ca.SX.sym("u", d), ca.SX.sym("c", 6)
        rows = [u[a] for a in range(w)]
        drows = [u[w + a] for a in range(w)]
        b, tw, tangent = integrands(rows, drows, self.frame)
        bend = 0.5 * c[0] * b
        twist = 0.5 * c[1] * tw if self.frame else ca.SX(0)
        return self.density_function(u, c, bend, twist, ca.vertcat(*tangent))

    def density_function(self, u, c, bend, twist, t) -> ca.Function:
        """Return ``node_function`` from u_k, c_k, bend_k, twist_k, unit T_k (+ stretch, φ_k)."""
        stretch = ca.SX(0)
        if self.stretch:  # ½ Re ε², the tangent scaled by 1 + ε
            eps = u[2 * self.width]
            stretch = 0.5 * c[2] * eps * eps
            t = (1 + eps) * t
        phi = self.nlp.sigma * (bend + twist + stretch) + ca.dot(c[3:6], t)
        hess, grad = ca.hessian(phi, u)
        return ca.Function(
            "dlo_node_density",
            [u, c],
            [bend, twist, stretch, t, grad, ca.densify(hess), ca.densify(ca.jacobian(t, u))],
        )

    def direct_terms(self, z: ca.SX, p: ca.SX) -> tuple[ca.SX, ca.SX]:
        """Return the point moments' work and the energy parts computed directly from z.

        (W_M, U_direct): the point moments' work (here their pseudo-potentials Σ W_M at their
        nodes) and the (bend, twist, stretch) energy parts computed directly from z rather than per
        node (none for a director model: structurally zero).
        """
        nlp, model = self.nlp, self.model
        moments = ca.SX(0)
        for i, ld in enumerate(nlp.problem.loads):
            moments += model.moment_work_sym(
                z,
                breakpoint_node(model.mesh, ld.s),
                p[nlp.params[f"load:{i}:moment"]],
                p[nlp.params[f"load:{i}:reference"]],
            )
        return moments, ca.SX(3, 1)

    def quadratic_terms(self, p: ca.SX) -> list[tuple[slice, ca.SX]]:
        """Return (s, K) of U_direct's parts ½ z_sᵀ K z_s: all of U_direct, or none (director)."""
        return []

    def local_function(self, rows: np.ndarray) -> ca.Function:
        """Build the function of the node-local ``rows``: their g, ∂g/∂z, ∇Λ and ∇²Λ.

        (z, p, λ_local) → [g_local, ∂g_local/∂z, ∇Λ, ∇²Λ, W_M, U_direct]: the node-local
        ``rows`` (unit norm, grip orientation, folds; an Euler-angle model's angle rows) and
        ``direct_terms``: Λ = λ·g_local − σ W_M + σ Σ U_direct (``assembled_local.py``).  Built
        once per set of rows: the KKT functions ask for the same one.
        """
        key = np.asarray(rows).tobytes()
        built = self._local_functions.get(key)
        if built is None:
            built = self._local_functions[key] = local_rows_function(self, rows)
        return built

    # ---- the nonlinear position rows: obstacles and self-contact slots -------------------------
    @functools.cached_property
    def tangent_function(self) -> ca.Function:
        """u_k → T_k = (1 + ε) t̂ (the first pass, for rows nonlinear in the positions)."""
        w = self.width
        u = ca.SX.sym("u", self.d)
        t = ca.vertcat(
            *integrands([u[a] for a in range(w)], [u[w + a] for a in range(w)], self.frame)[2]
        )
        return ca.Function("dlo_node_tangent", [u], [t * (1 + u[2 * w]) if self.stretch else t])

    def inequality_g(self) -> ca.Function:
        """Build ``dlo_obstacle_g`` (``assembled_contact.inequality_g``)."""
        return inequality_g(self)

    # ---- the KKT functions ----------------------------------------------------------------------
    def kkt_free(self) -> tuple[ca.Function, ca.Function]:
        """Build the contact-free KKT function and its residual alone.

        (``dlo_kkt_free``, ``dlo_residual_free``): (z, p, λ_free) → [K, r, ∇f, energies] as the
        flattened one of ``StringNLP``, K = [∇²L Jᵀ; J 0] and r = [∇f + Jᵀλ; g] over the rows
        before the first inequality row; and (z, p, λ_free) → r alone (the same expression, without
        K's products: a fraction of the cost, for the chord steps of ``native.newton``).
        """
        nlp, n, nf = self.nlp, self.n, self.nlp.n_free_rows
        z, p, lam = ca.MX.sym("z", n), ca.MX.sym("p", nlp.params.size), ca.MX.sym("lam_free", nf)
        grad, hess, g, jac, grad_f, energies = self._system(z, p, lam, nf)
        kkt = ca.blockcat([[hess, jac.T], [jac, ca.MX(nf, nf)]])
        residual = ca.densify(ca.vertcat(grad, g))
        return (
            ca.Function(
                "dlo_kkt_free",
                [z, p, lam],
                [ca.densify(kkt), residual, ca.densify(grad_f), ca.densify(energies)],
            ),
            ca.Function("dlo_residual_free", [z, p, lam], [residual]),
        )

    def kkt_free_split(self) -> ca.Function:
        """Build the contact-free KKT function with K's per-node Hessian part left out.

        ``dlo_kkt_free_split``: (z, p, λ_free) → [K − [Eᵀ W 0; 0 0], r, ∇f, energies, W] with W
        = diag(∇²φ_k) E (d·M × n): ``kkt_free``'s outputs with K's per-node Hessian part Eᵀ W left
        out, and W.  That product is most of K's cost in CasADi's sparse loops (E is dense within
        an element); the compiled functions add it with BLAS, by dense blocks of E
        (``native.newton.NodeBlocks``).
        """
        nlp, n, nf = self.nlp, self.n, self.nlp.n_free_rows
        z, p, lam = ca.MX.sym("z", n), ca.MX.sym("p", nlp.params.size), ca.MX.sym("lam_free", nf)
        grad, hess, g, jac, grad_f, energies, weighted, _ = self._system(z, p, lam, nf, split=True)
        kkt = ca.blockcat([[hess, jac.T], [jac, ca.MX(nf, nf)]])
        return ca.Function(
            "dlo_kkt_free_split",
            [z, p, lam],
            [
                ca.densify(kkt),
                ca.densify(ca.vertcat(grad, g)),
                ca.densify(grad_f),
                ca.densify(energies),
                ca.densify(weighted),
            ],
        )

    def kkt_split(self) -> tuple[ca.Function, tuple[int, ...]]:
        """Build ``kkt``'s function with ∇²L's per-node part and the rows' curvature left out.

        (``dlo_kkt_split``, sizes): ``kkt``'s outputs with ∇²L's per-node part Eᵀ W left out, then
        W (as ``kkt_free_split``), then the curvature term of the rows nonlinear in the positions
        as blocks D, w (``assembled_contact.contact_blocks``), which ∇²L lacks too; and the
        blocks' sizes.
        """
        nlp, n, rows = self.nlp, self.n, self.nlp.g_sym.shape[0]
        z, p, lam = ca.MX.sym("z", n), ca.MX.sym("p", nlp.params.size), ca.MX.sym("lam", rows)
        _, hess, g, jac, grad_f, energies, weighted, contact = self._system(
            z, p, lam, rows, split=True
        )
        d, w, sizes = contact
        fn = ca.Function(
            "dlo_kkt_split",
            [z, p, lam],
            [
                ca.densify(grad_f),
                ca.densify(g),
                ca.densify(jac),
                ca.densify(hess),
                ca.densify(energies),
                ca.densify(weighted),
                ca.densify(d),
                ca.densify(w),
            ],
        )
        return fn, sizes

    def kkt(self) -> tuple[ca.Function, ca.Function]:
        """Build the full KKT function over every row, and its residual alone.

        (``dlo_kkt``, ``dlo_residual``): (z, p, λ) → [∇f, g, ∂g/∂z, ∇²L, energies] over every
        row, as ``StringNLP.kkt_fn``; and (z, p, λ) → [∇L; g] (the chord steps of
        ``native.newton.ActiveNewton``).
        """
        nlp, n, rows = self.nlp, self.n, self.nlp.g_sym.shape[0]
        z, p, lam = ca.MX.sym("z", n), ca.MX.sym("p", nlp.params.size), ca.MX.sym("lam", rows)
        grad, hess, g, jac, grad_f, energies = self._system(z, p, lam, rows)
        return (
            ca.Function(
                "dlo_kkt",
                [z, p, lam],
                [
                    ca.densify(grad_f),
                    ca.densify(g),
                    ca.densify(jac),
                    ca.densify(hess),
                    ca.densify(energies),
                ],
            ),
            ca.Function("dlo_residual", [z, p, lam], [ca.densify(ca.vertcat(grad, g))]),
        )

    def _position_rows(self, T, jt, x0, p, E):
        """(g, ∂g/∂z) of the position rows: c_r · (κ_r x0 + Σ_k W_rk T_k − target_r) / L."""
        L, d, n = self.nlp.length, self.d, self.n
        omega = self.geometry.rows(p, self.position_points)
        X = ca.mtimes(T, omega.T)  # 3 × rows: Σ_k W_rk T_k
        g = (
            ca.DM(self.kappa) * ca.mtimes(ca.DM(self.C), x0)
            + ca.sum1(ca.DM(self.C).T * X).T
            - ca.mtimes(sparse(self.target), p)
        ) / L
        jac = ca.mtimes(ca.mtimes(ca.DM(self.C), jt) * spread(omega, 1, d, self.M), E) / L
        return g, jac + sparse(x0_columns(self.C * self.kappa[:, None], n))

    def jacobian(self) -> ca.Function:
        """``constraint_jacobian``: (z, p) → ∂g/∂z over every row, without the Hessian's work."""
        nlp, M, d, n, L = self.nlp, self.M, self.d, self.n, self.nlp.length
        rows = nlp.g_sym.shape[0]
        z, p = ca.MX.sym("z", n), ca.MX.sym("p", nlp.params.size)
        E = self.geometry.node_map(p)
        u = ca.reshape(ca.mtimes(E, z), d, M)
        t = self.tangent_function
        uu = ca.SX.sym("u", d)
        node = ca.Function(
            "dlo_node_tangent_jacobian", [uu], [t(uu), ca.densify(ca.jacobian(t(uu), uu))]
        )
        T, jt = node.map(M, "serial")(u)
        parts = []
        if self.pos_rows.size:
            parts.append((self.pos_rows, *self._position_rows(T, jt, z[0:3] * L, p, E)))
        if self.local_rows.size:
            zs, ps = nlp.z_sym, nlp.p_sym
            g_local = nlp.g_sym[self.local_rows.tolist()]
            local = ca.Function(
                "dlo_local_jacobian", [zs, ps], [g_local, ca.jacobian(g_local, zs)]
            )
            parts.append((self.local_rows, *local(z, p)))
        if rows > nlp.n_free_rows:
            rows_nl, g_nl, _, _, groups = nonlinear_rows(self, z, p, ca.MX(rows, 1), T)
            if rows_nl:
                jac_nl, _ = group_terms(self, groups, jt, E, n, hessian=False)
                parts.append(
                    (np.array(rows_nl, dtype=int), ca.vertcat(*g_nl), ca.vertcat(*jac_nl))
                )
        _, jac = in_row_order(parts, rows)
        return ca.Function(
            "constraint_jacobian", [z, p], [ca.densify(jac) if jac is not None else ca.MX(0, n)]
        )

    def _linear_terms(self, p, lam, pos_rows: np.ndarray, gravity, m):
        """Return (a, ∂ℓ/∂x0, forces): the terms linear in the positions (``_system``).

        (a, ∂ℓ/∂x0, forces): the terms linear in the positions (``_system``).

        a (3 × M) holds gravity through the weight moments ``m``, the point forces and the
        position rows ``pos_rows`` (λ: every row's multipliers); ∂ℓ/∂x0 the same terms' part in x0.
        """
        nlp, L, sigma, lay = self.nlp, self.nlp.length, self.nlp.sigma, self.nlp.params
        # a_k: the terms linear in the positions
        a = -sigma * ca.mtimes(gravity, m.T)
        forces = [p[lay[f"load:{i}:force"]] for i in range(len(nlp.problem.loads))]
        F = ca.horzcat(*forces) if forces else None
        if F is not None:
            a -= sigma * ca.mtimes(F, self.geometry.rows(p, self.load_points))
        lam_pos = lam[pos_rows.tolist()] if pos_rows.size else ca.MX(0, 1)
        if pos_rows.size:
            a += ca.mtimes(
                ca.DM(self.C).T * ca.repmat((lam_pos / L).T, 3, 1),
                self.geometry.rows(p, self.position_points),
            )  # Σ_r c_r λ_r/L W_r
        dx0 = -sigma * L * gravity * p[lay["weight_total"]]
        if F is not None:
            dx0 -= sigma * L * ca.sum2(F)
        if pos_rows.size:
            dx0 += ca.mtimes(ca.DM(self.C * self.kappa[:, None]).T, lam_pos)
        return a, dx0, forces

    def _energies(self, p, x0, T, per_node, direct, moments, forces, gravity, m):
        """Return the energies (bend, twist, stretch, gravity, work) from the per-node sums.

        The energies (bend, twist, stretch, gravity, work) from the per-node sums.

        ``per_node``: the bend, twist and stretch integrands per node; ``direct``: the node-local
        parts added to them; ``moments``: the point moments' work.
        """
        lay = self.nlp.params
        bend, twist, stretch = (
            ca.sum2(e) + direct[i] if direct.sparsity().has_nz(i, 0) else ca.sum2(e)
            for i, e in enumerate(per_node)
        )
        grav = -ca.dot(gravity, x0 * p[lay["weight_total"]] + ca.mtimes(T, m))
        work = moments
        loads = self.geometry.rows(p, self.load_points) if forces else None
        for i, force in enumerate(forces):
            work += ca.dot(force, x0 + ca.mtimes(T, loads[i, :].T))
        return ca.vertcat(bend, twist, stretch, grav, work)

    def _system(self, z, p, lam, rows: int, split: bool = False):
        """Return ∇L, ∇²L, g, ∂g/∂z, ∇f and the energies over the first ``rows`` rows.

        ∇L, ∇²L, g, ∂g/∂z, ∇f and the energies over the first ``rows`` rows (λ: their
        multipliers). ``split``: ∇²L without its per-node part Eᵀ W nor the curvature of the rows
        nonlinear in the positions; then W = diag(∇²φ_k) E and those rows' blocks (D, w, sizes:
        ``assembled_contact.contact_blocks``) as seventh and eighth items.
        """
        nlp, M, d, n, L = self.nlp, self.M, self.d, self.n, self.nlp.length
        lay = nlp.params
        E = self.geometry.node_map(p)  # (for ∂g/∂z and ∇²L: ∇L and g need E z, Eᵀ v alone)
        u = ca.reshape(self.geometry.apply(p, z, E), d, M)
        x0 = z[0:3] * L
        pos_rows = self.pos_rows[self.pos_rows < rows]
        local_rows = self.local_rows[self.local_rows < rows]
        gravity, m = p[lay["gravity"]], p[lay["weight_moments"]]
        a, dx0, forces = self._linear_terms(p, lam, pos_rows, gravity, m)
        # rows nonlinear in the positions need T first (their gradient enters a_k)
        nonlinear: tuple = ([], [], None, None, [])
        if rows > nlp.n_free_rows:
            T0 = self.tangent_function.map(M, "serial")(u)
            nonlinear = nonlinear_rows(self, z, p, lam, T0)
            a += nonlinear[2]
            dx0 += nonlinear[3]
        bend_k, twist_k, stretch_k, T, grad_k, hess_k, jt_k = self.node_function.map(M, "serial")(
            u, self._node_coefficients(p, a)
        )

        # ∇L: per-node part, the x0 part, the node-local part
        grad = self.geometry.apply_transpose(p, ca.vec(grad_k), E)
        grad += ca.vertcat(dx0, ca.MX(n - 3, 1))
        lam_local = lam[local_rows.tolist()] if local_rows.size else ca.MX(0, 1)
        g_loc, j_loc, grad_loc, hess_loc, moments, direct = self.local_function(local_rows)(
            z, p, lam_local
        )
        grad += grad_loc
        # ∇²L = Eᵀ diag(∇²φ_k) E + ∇²Λ (+ Dᵀ diag(λ ∇²ψ) D for rows nonlinear in the positions)
        if d == 1:  # diag(h) E is E with row k scaled by h_k: no matrix product
            weighted_E = E * ca.repmat(hess_k.T, 1, n)
        else:
            weighted_E = ca.mtimes(
                ca.sparsity_cast(hess_k, ca.diagcat(*[ca.Sparsity.dense(d, d)] * M)), E
            )
        hess = hess_loc if split else ca.mtimes(E.T, weighted_E) + hess_loc

        parts = []  # (rows, g, ∂g/∂z)
        if pos_rows.size:
            parts.append((pos_rows, *self._position_rows(T, jt_k, x0, p, E)))
        if local_rows.size:
            parts.append((local_rows, g_loc, j_loc))
        rows_nl, g_nl, _, _, groups = nonlinear
        # the split's curvature blocks (none)
        contact: tuple[ca.MX, ca.MX, tuple[int, ...]] = (ca.MX(0, n), ca.MX(0, 1), ())
        if rows_nl:
            # split: the rows' curvature as blocks (``contact_blocks``), not summed
            jac_nl, contact_hess = group_terms(self, groups, jt_k, E, n, hessian=not split)
            if contact_hess is not None:
                hess += contact_hess
            if split:
                contact = contact_blocks(self, groups, jt_k, E, n)
            parts.append((np.array(rows_nl, dtype=int), ca.vertcat(*g_nl), ca.vertcat(*jac_nl)))
        g, jac = in_row_order(parts, rows)

        grad_f = grad - ca.mtimes(jac.T, lam)
        energies = self._energies(
            p, x0, T, (bend_k, twist_k, stretch_k), direct, moments, forces, gravity, m
        )
        if split:
            return grad, hess, g, jac, grad_f, energies, weighted_E, contact
        return grad, hess, g, jac, grad_f, energies
