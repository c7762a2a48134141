"""The contact-free KKT function of a director model, assembled from per-quadrature-node derivatives.

``StringNLP.kkt_free_fn`` differentiates one flattened expression of the whole Lagrangian: its C is
straight-line code of ~6·10⁵ operations (full model, order 16) that gcc needs minutes for.  This
module builds the same function (same inputs, outputs and row order) from the Lagrangian's structure,
so that its code is a loop over quadrature nodes plus a few sparse matrix products:

    L(z, λ) = Σ_k φ_k(u_k) + ℓ(z, λ) + Λ(z, λ)

* u_k = E_k z = (v(σ_k), v'(σ_k), ε(σ_k)): the rotation field (quaternion or tangent), its
  s-derivative and the strain at quadrature node σ_k — one row block of the constant sparse E;
* φ_k = σ [½ w_k Rf_k b(u_k) + ½ w_k Rt_k τ(u_k) + ½ w_k Re_k ε_k²] + a_k · T(u_k),  T = (1 + ε) t̂,
  with b, τ the bend and twist integrands (``director.integrands``) and a_k ∈ R³ every term that is
  linear in the positions x(s) = x0 + Σ_k W_k(s) T_k:
      a_k = −σ m_k ĝ − σ Σ_i W_k(s_i) F_i + Σ_r λ_r W_rk c_r / L_r
  (gravity through the weight moments m, point forces, and the position rows r: c_r · (x(s) − target)
  or c_r · (x(s_b) − x(s_a) − offset), scaled by L_r);
* ℓ: the same terms' part in x0 = z[0:3] L (linear in z: no Hessian);
* Λ: the rows local to one node (unit norm, a grip's orientation) and the point moments'
  pseudo-potentials, small CasADi SX expressions of a node's values differentiated directly.

Hence ∇L = Eᵀ [∇φ_k]_k + ∇ℓ + ∇Λ,  ∇²L = Eᵀ diag(∇²φ_k) E + ∇²Λ,  and a position row's Jacobian is
c_r·∂x/∂z = κ_r c_r ⊗ (∂x0/∂z) + Σ_k W_rk c_r·(∂T/∂u)_k E_k.  The per-node derivatives (∇φ_k, ∇²φ_k,
∂T/∂u) come from one small SX function mapped over the nodes (a loop in C).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..model.director import DirectorModel, integrands


def _sparse(matrix: np.ndarray) -> ca.DM:
    """A CasADi DM holding only the non-zero entries of ``matrix``."""
    return ca.sparsify(ca.DM(matrix))


class AssembledKKT:
    """Builds ``kkt_free`` (see the module docstring) for a ``StringNLP`` whose model is a DirectorModel."""

    def __init__(self, nlp) -> None:
        model = nlp.model
        if not isinstance(model, DirectorModel):
            raise TypeError("the assembled KKT function needs a director model")
        self.nlp, self.model = nlp, model
        lay = model.layout
        self.width, self.stretch, self.frame = lay.width, lay.stretch, lay.frame
        self.d = 2 * lay.width + int(lay.stretch)  # per-node unknowns u_k
        self.M = model.quad.count
        self.n = lay.size
        self.E = self._node_map()
        self._rows()

    # ---- constants ---------------------------------------------------------------------------------
    def _node_map(self) -> np.ndarray:
        """E (d·M × n): row j + d k of E z is component j of u_k (E is block-sparse by element)."""
        lay, mesh, d, w = self.model.layout, self.model.mesh, self.d, self.width
        E = np.zeros((d * self.M, self.n))
        for k in range(self.M):
            for a in range(w):
                cols = 3 + w * np.arange(lay.nodes) + a
                E[d * k + a, cols] = mesh.B[k]
                E[d * k + w + a, cols] = mesh.dB[k]
            if lay.stretch:
                E[d * k + 2 * w, lay.eps] = mesh.B[k]
        return E

    def _rows(self) -> None:
        """Split the free rows into position rows (c_r, W_r, κ_r, target) and node-local rows."""
        nlp, P, model = self.nlp, self.nlp.problem, self.model
        grips = {g.name: g for g in P.grips}
        nf = nlp.n_free_rows
        pos, local = [], []
        C, Om, kappa = [], [], []
        target = np.zeros((0, nlp.params.size))
        for r in range(nf):
            kind = nlp.row_kind[r]
            row_target = np.zeros(nlp.params.size)
            if kind[0] == "grip" and kind[2] == "position":
                axis = np.array(kind[3], dtype=float)
                g = grips[kind[1]]
                C.append(axis)
                Om.append(model.position_matrix(np.array([g.s]))[0])
                kappa.append(1.0)
                row_target[nlp.params[f"grip:{g.name}:position"]] = axis
            elif kind[0] == "relative":
                rel = P.relative_positions[kind[1]]
                axis = np.eye(3)[kind[2]]
                C.append(axis)
                W = model.position_matrix(np.array([rel.s_a, rel.s_b]))
                Om.append(W[1] - W[0])
                kappa.append(0.0)
                row_target[nlp.params[f"relative:{kind[1]}"]] = axis
            else:
                local.append(r)
                continue
            pos.append(r)
            target = np.vstack([target, row_target])
            if not np.isclose(nlp.row_scale[r], nlp.length):
                raise ValueError(f"position row {kind} is not scaled by L")
        self.pos_rows, self.local_rows = np.array(pos, dtype=int), np.array(local, dtype=int)
        self.C = np.array(C).reshape(-1, 3)
        self.Omega = np.array(Om).reshape(-1, self.M)
        self.kappa = np.array(kappa)
        self.target = target
        self.loads_W = model.position_matrix(np.array([ld.s for ld in P.loads])) if P.loads else np.zeros((0, self.M))

    # ---- the per-node function ---------------------------------------------------------------------
    def node_function(self) -> ca.Function:
        """(u_k, c_k) → [bend_k, twist_k, stretch_k, T_k, ∇φ_k, ∇²φ_k, ∂T/∂u]; c_k = (w Rf, w Rt, w Re, a_k)."""
        w, d = self.width, self.d
        u, c = ca.SX.sym("u", d), ca.SX.sym("c", 6)
        rows = [u[a] for a in range(w)]
        drows = [u[w + a] for a in range(w)]
        b, tw, tangent = integrands(rows, drows, self.frame)
        bend = 0.5 * c[0] * b
        twist = 0.5 * c[1] * tw if self.frame else ca.SX(0)
        t = ca.vertcat(*tangent)
        if self.stretch:
            eps = u[2 * w]
            stretch = 0.5 * c[2] * eps * eps
            t = (1 + eps) * t
        else:
            stretch = ca.SX(0)
        phi = self.nlp.sigma * (bend + twist + stretch) + ca.dot(c[3:6], t)
        hess, grad = ca.hessian(phi, u)
        return ca.Function("dlo_node_density", [u, c],
                           [bend, twist, stretch, t, grad, ca.densify(hess), ca.densify(ca.jacobian(t, u))])

    def local_function(self) -> ca.Function:
        """(z, p, λ_local) → [g_local, ∂g_local/∂z, ∇Λ, ∇²Λ, W_moments]: the node-local rows and the
        point moments' pseudo-potential Σ W_M (Λ = λ·g_local − σ Σ W_M)."""
        nlp, model, P = self.nlp, self.model, self.nlp.problem
        z, p = nlp.z_sym, nlp.p_sym
        g_local = nlp.g_sym[self.local_rows.tolist()] if self.local_rows.size else ca.SX(0, 1)
        moments = ca.SX(0)
        for i, ld in enumerate(P.loads):
            moments += model.moment_work_sym(z, model.mesh.node_index(ld.s), p[nlp.params[f"load:{i}:moment"]],
                                             p[nlp.params[f"load:{i}:reference"]])
        lam = ca.SX.sym("lam_local", g_local.shape[0])
        lagrangian = ca.dot(lam, g_local) - nlp.sigma * moments
        hess, grad = ca.hessian(lagrangian, z)
        return ca.Function("dlo_local_rows", [z, p, lam],
                           [g_local, ca.jacobian(g_local, z), grad, hess, moments])

    # ---- the KKT function --------------------------------------------------------------------------
    def kkt_free(self) -> ca.Function:
        """``dlo_kkt_free``: (z, p, λ_free) → [K, r, ∇f, energies] as ``StringNLP.kkt_free_fn``."""
        nlp, M, d, n, L = self.nlp, self.M, self.d, self.n, self.nlp.length
        lay, sigma = nlp.params, nlp.sigma
        nf = nlp.n_free_rows
        z, p, lam = ca.MX.sym("z", n), ca.MX.sym("p", lay.size), ca.MX.sym("lam_free", nf)
        E = _sparse(self.E)
        u = ca.reshape(ca.mtimes(E, z), d, M)
        x0 = z[0:3] * L
        weights = ca.DM(self.model.mesh.weights).T
        gravity, m = p[lay["gravity"]], p[lay["weight_moments"]]
        # a_k: the terms linear in the positions
        a = -sigma * ca.mtimes(gravity, m.T)
        forces = [p[lay[f"load:{i}:force"]] for i in range(len(nlp.problem.loads))]
        F = ca.horzcat(*forces) if forces else None
        if F is not None:
            a -= sigma * ca.mtimes(F, ca.DM(self.loads_W))
        lam_pos = lam[self.pos_rows.tolist()] if self.pos_rows.size else ca.MX(0, 1)
        if self.pos_rows.size:
            a += ca.mtimes(ca.DM(self.C).T, ca.mtimes(ca.diag(lam_pos / L), ca.DM(self.Omega)))
        coef = ca.vertcat(weights * p[lay["Rf"]].T, weights * p[lay["Rt"]].T, weights * p[lay["Re"]].T, a)
        bend_k, twist_k, stretch_k, T, grad_k, hess_k, jt_k = self.node_function().map(M, "serial")(u, coef)

        # gradient of L: per-node part, the x0 part, the node-local part
        grad = ca.mtimes(E.T, ca.vec(grad_k))
        dx0 = -sigma * L * gravity * p[lay["weight_total"]]
        if F is not None:
            dx0 -= sigma * L * ca.sum2(F)
        if self.pos_rows.size:
            dx0 += ca.mtimes(ca.DM(self.C * self.kappa[:, None]).T, lam_pos)
        grad += ca.vertcat(dx0, ca.MX(n - 3, 1))
        lam_local = lam[self.local_rows.tolist()] if self.local_rows.size else ca.MX(0, 1)
        g_loc, j_loc, grad_loc, hess_loc, moments = self.local_function()(z, p, lam_local)
        grad += grad_loc

        # ∇²L = Eᵀ diag(∇²φ_k) E + ∇²Λ
        blocks = ca.sparsity_cast(hess_k, ca.diagcat(*[ca.Sparsity.dense(d, d)] * M))
        hess = ca.mtimes(E.T, ca.mtimes(blocks, E)) + hess_loc

        # the position rows: values and Jacobian
        rows_g = [None] * nf
        jac_parts = []
        if self.pos_rows.size:
            X = ca.mtimes(T, ca.DM(self.Omega).T)  # 3 × rows: Σ_k W_rk T_k
            g_pos = (ca.DM(self.kappa) * ca.mtimes(ca.DM(self.C), x0) + ca.sum1(ca.DM(self.C).T * X).T
                     - ca.mtimes(ca.DM(self.target), p)) / L
            omega_rep = np.repeat(self.Omega, d, axis=1)  # W_rk at column j + d k
            j_pos = ca.mtimes(ca.mtimes(ca.DM(self.C), jt_k) * ca.DM(omega_rep), E) / L
            j_pos += ca.DM(_x0_columns(self.C * self.kappa[:, None], n))
            jac_parts.append((self.pos_rows, g_pos, j_pos))
        if self.local_rows.size:
            jac_parts.append((self.local_rows, g_loc, j_loc))
        order = np.concatenate([rows for rows, _, _ in jac_parts]) if jac_parts else np.zeros(0, dtype=int)
        inverse = np.argsort(order).tolist()
        g = ca.vertcat(*[gp for _, gp, _ in jac_parts])[inverse] if jac_parts else ca.MX(0, 1)
        jac = ca.vertcat(*[jp for _, _, jp in jac_parts])[inverse, :] if jac_parts else ca.MX(0, n)

        grad_f = grad - ca.mtimes(jac.T, lam)
        bend, twist, stretch = ca.sum2(bend_k), ca.sum2(twist_k), ca.sum2(stretch_k)
        grav = -ca.dot(gravity, x0 * p[lay["weight_total"]] + ca.mtimes(T, m))
        work = moments
        for i, force in enumerate(forces):
            work += ca.dot(force, x0 + ca.mtimes(T, ca.DM(self.loads_W[i])))
        energies = ca.vertcat(bend, twist, stretch, grav, work)
        kkt = ca.blockcat([[hess, jac.T], [jac, ca.MX(nf, nf)]])
        residual = ca.vertcat(grad, g)
        return ca.Function("dlo_kkt_free", [z, p, lam],
                           [ca.densify(kkt), ca.densify(residual), ca.densify(grad_f), ca.densify(energies)])


def _x0_columns(coefficients: np.ndarray, n: int) -> np.ndarray:
    """A (rows × n) matrix with ``coefficients`` (rows × 3) in the x0 columns 0–2 (∂x0/∂z = L I, /L)."""
    out = np.zeros((coefficients.shape[0], n))
    out[:, 0:3] = coefficients
    return out
