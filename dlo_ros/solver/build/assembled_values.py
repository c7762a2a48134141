"""IPOPT's objective and rows assembled per quadrature node, reading the mesh's geometry from p.

The flattened SX expressions of ``StringNLP`` (its ``nlp['f']`` and ``g_sym``) bake the built
mesh's matrices in.  For a director model (p carries the mesh's geometry,
``mesh_parameters.py``) the functions IPOPT and the Newton stages evaluate are written here from
the same parts as the assembled KKT functions (``assembled.py``):

* ``dlo_objective`` (z, p) → [f, ∇f]: f = σ (U_bend + U_twist + U_stretch + U_grav − W) from the
  per-node densities with a_k = −σ (gravity and point forces) and the node-local terms, ∇f = Eᵀ
  [∇φ_k] + ∂ℓ/∂x0 + ∇Λ at λ = 0 (``AssembledKKT._system``'s gradient without its Hessian);
* ``dlo_rows`` (z, p) → g: every row, the position rows c_r · (κ_r x0 + Σ_k W_rk T_k − target_r)
  / L, the node-local rows and (``inequality_g``) the rows after the free rows, in the NLP's order.

So a built NLP of one mesh topology solves with IPOPT on any breakpoint positions of it, as its
Newton stages do (``test_mesh_parameters.py``).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from .assembled_contact import sparse


def _node_function(kkt, outputs: int) -> ca.Function:
    """Return ``kkt.node_function``'s first ``outputs`` outputs (the others' work is dropped)."""
    full = kkt.node_function
    u, c = ca.SX.sym("u", full.size1_in(0)), ca.SX.sym("c", full.size1_in(1))
    return ca.Function(f"dlo_node_first_{outputs}", [u, c], full(u, c)[:outputs])


def objective_function(kkt, gradient: bool = True) -> ca.Function:
    """Build ``dlo_objective``: (z, p) → [f, ∇f] (module docstring); ``gradient`` False: f alone.

    IPOPT evaluates f alone at its line search's trial points (``dlo_energy``).
    """
    nlp, M, d, n, L = kkt.nlp, kkt.M, kkt.d, kkt.n, kkt.nlp.length
    lay = nlp.params
    z, p = ca.MX.sym("z", n), ca.MX.sym("p", lay.size)
    u = ca.reshape(kkt.geometry.apply(p, z), d, M)
    x0 = z[0:3] * L
    gravity, m = p[lay["gravity"]], p[lay["weight_moments"]]
    none = np.zeros(0, dtype=int)
    a, dx0, forces = kkt._linear_terms(p, ca.MX(0, 1), none, gravity, m)
    per_node = _node_function(kkt, 5 if gradient else 4).map(M, "serial")(
        u, kkt._node_coefficients(p, a)
    )
    _, _, grad_loc, _, moments, direct = kkt.local_function(none)(z, p, ca.MX(0, 1))
    energies = kkt._energies(p, x0, per_node[3], per_node[:3], direct, moments, forces, gravity, m)
    f = nlp.sigma * (energies[0] + energies[1] + energies[2] + energies[3] - energies[4])
    if not gradient:
        return ca.Function("dlo_energy", [z, p], [f])
    grad = kkt.geometry.apply_transpose(p, ca.vec(per_node[4]))
    grad += ca.vertcat(dx0, ca.MX(n - 3, 1)) + grad_loc
    return ca.Function("dlo_objective", [z, p], [f, ca.densify(grad)])


def rows_function(kkt, inequality_g: ca.Function | None) -> ca.Function:
    """Build ``dlo_rows``: (z, p) → g over every row (module docstring).

    ``inequality_g``: the NLP's function of the rows after the free rows (None: there are none).
    """
    nlp, M, d, n, L = kkt.nlp, kkt.M, kkt.d, kkt.n, kkt.nlp.length
    nf, rows = nlp.n_free_rows, nlp.g_sym.shape[0]
    z, p = ca.MX.sym("z", n), ca.MX.sym("p", nlp.params.size)
    parts: list[tuple[np.ndarray, ca.MX]] = []
    if kkt.pos_rows.size:
        u = ca.reshape(kkt.geometry.apply(p, z), d, M)
        T = kkt.tangent_function.map(M, "serial")(u)
        X = ca.mtimes(T, kkt.geometry.rows(p, kkt.position_points).T)  # 3 × rows
        C = ca.DM(kkt.C)
        g = (
            ca.DM(kkt.kappa) * ca.mtimes(C, z[0:3] * L)
            + ca.sum1(C.T * X).T
            - ca.mtimes(sparse(kkt.target), p)
        ) / L
        parts.append((kkt.pos_rows, g))
    local = kkt.local_rows[kkt.local_rows < nf]
    if local.size:
        parts.append((local, kkt.local_function(local)(z, p, ca.MX(local.size, 1))[0]))
    order = np.concatenate([r for r, _ in parts]) if parts else np.zeros(0, dtype=int)
    if sorted(order.tolist()) != list(range(nf)):
        raise ValueError("assembled rows: the free rows not covered exactly once")
    free = ca.vertcat(*[g for _, g in parts])[np.argsort(order).tolist()] if parts else ca.MX(0, 1)
    if rows > nf:
        assert inequality_g is not None  # built by the NLP where rows follow the free rows
        free = ca.vertcat(free, inequality_g(z, p))
    return ca.Function("dlo_rows", [z, p], [ca.densify(free)])


def value_functions(kkt, inequality_g: ca.Function | None) -> tuple[ca.Function, ...] | None:
    """Return (``dlo_objective``, ``dlo_energy``, ``dlo_rows``), or None: no geometry in p."""
    if kkt.geometry.params is None:
        return None
    return (
        objective_function(kkt),
        objective_function(kkt, gradient=False),
        rows_function(kkt, inequality_g),
    )
