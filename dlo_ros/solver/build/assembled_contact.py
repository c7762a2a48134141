"""The assembled KKT functions' rows that are nonlinear in the positions.

These are the obstacle rows, the obstacles' contact slots and the self-contact slots:
rows ψ_j(X_j)/L of X_j = κ x0 + Σ_k ω_jk T_k (``assembled.py``'s module docstring).  Their values,
their part of a_k and of ∂L/∂x0, their Jacobian rows and their curvature blocks are written here
for ``AssembledKKT`` (passed in as ``kkt``: its node map E, sizes d, M, n, its NLP and model), and
so are the rows' values alone (``inequality_g``) and the small matrix helpers the KKT functions
share.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ...model.obstacles import OBSTACLE_TYPES
from .slot_envelope import (
    envelope_function,
    shift_bound,
    slot_curve,
    slot_inputs,
    value_function,
)


def sparse(matrix: np.ndarray) -> ca.DM:
    """Return a CasADi DM holding only the non-zero entries of ``matrix``.

    Built from its triplets: ``ca.sparsify(ca.DM(dense))`` visits every entry and took a third of
    a mesh model's build (the node maps are mostly zeros).
    """
    dense = np.asarray(matrix, dtype=float)
    if dense.ndim == 1:
        dense = dense[:, None]
    cols, rows = np.nonzero(dense.T)  # column-major, as CasADi stores the non-zeros
    pattern = ca.Sparsity.triplet(dense.shape[0], dense.shape[1], rows.tolist(), cols.tolist())
    return ca.DM(pattern, dense[rows, cols])


def x0_columns(coefficients: np.ndarray, n: int) -> np.ndarray:
    """Return a (rows × n) matrix with ``coefficients`` in the x0 columns 0–2.

    A (rows × n) matrix with ``coefficients`` (rows × 3) in the x0 columns 0–2 (∂x0/∂z = L I,
    /L).
    """
    out = np.zeros((coefficients.shape[0], n))
    out[:, 0:3] = coefficients
    return out


def block_diagonal(blocks: ca.MX, size: int = 3) -> ca.MX:
    """(b × bS) → the bS × bS block-diagonal matrix of its b × b blocks (b = ``size``)."""
    S = blocks.shape[1] // size
    return ca.sparsity_cast(blocks, ca.diagcat(*[ca.Sparsity.dense(size, size)] * S))


def in_row_order(parts, rows: int):
    """Return (g, ∂g/∂z) in the NLP's row order from parts that cover every row once.

    (g, ∂g/∂z) in the NLP's row order from [(rows, g, ∂g/∂z)] that cover rows 0 … rows − 1
    once.
    """
    order = np.concatenate([r for r, _, _ in parts]) if parts else np.zeros(0, dtype=int)
    if sorted(order.tolist()) != list(range(rows)):
        raise ValueError("assembled KKT: rows not covered exactly once")
    inverse = np.argsort(order).tolist()
    if not parts:
        return ca.MX(0, 1), None
    return ca.vertcat(*[gp for _, gp, _ in parts])[inverse], ca.vertcat(
        *[jp for _, _, jp in parts]
    )[inverse, :]


def obstacle_function(kind: str) -> tuple[ca.Function, bool]:
    """Build the function (x, parameters) → [h, ∇h, ∇²h] of one obstacle type.

    ((x, parameters) → [h, ∇h, ∇²h] of one obstacle type at one point, whether ∇²h is not
    zero).
    """
    x, po = ca.SX.sym("x", 3), ca.SX.sym("po", OBSTACLE_TYPES[kind].size)
    h = OBSTACLE_TYPES[kind].h(x, po)
    hess, grad = ca.hessian(h, x)
    return ca.Function(f"dlo_h_{kind}", [x, po], [h, grad, ca.densify(hess)]), hess.nnz() > 0


def nonlinear_rows(kkt, z, p, lam, T):
    """Write the obstacle rows and self-contact slots of the assembled KKT function.

    The obstacle rows and self-contact slots: rows ψ_j(X_j)/L of X_j = κ x0 + Σ_k ω_jk T_k.
    Returns (rows, their g, their part of a (3×M) and of ∂L/∂x0, and per group of rows sharing
    their X: (ω (S×M, constant or MX), κ, [∇ψ/L (3×S) per block of rows], Σ λ∇²ψ/L (3×3S) or
    None)).
    """
    nlp, M, L = kkt.nlp, kkt.M, kkt.nlp.length
    lay, P = nlp.params, nlp.problem
    rows_all, g_all, a, dx0, groups = [], [], ca.MX.zeros(3, M), ca.MX.zeros(3, 1), []
    radius = p[lay["radius"]][0]
    if P.obstacles:
        omega = kkt.geometry.obstacle_rows(p)  # S × M
        S = omega.shape[0]
        X = ca.repmat(z[0:3] * L, 1, S) + ca.mtimes(T, omega.T)
        spread3 = sparse(np.kron(np.eye(S), np.ones((1, 3))))  # λ_j → column 3j + c
        weighted, grads = None, []
        for i, ob in enumerate(P.obstacles):
            rows = nlp.obstacle_rows[i]
            fn, curved = obstacle_function(ob.type)
            h, dh, d2h = fn.map(S, "serial")(X, ca.repmat(p[lay[f"obstacle:{i}"]], 1, S))
            li = lam[rows] / L  # S
            rows_all += rows
            grad = dh
            if nlp.obstacle_slots:  # samples a contact slot replaces read −1 (obstacle_slots.py)
                on = p[lay[f"samples:{i}:on"]]
                li = li * on
                g_all.append((on * (h.T + radius) - (1 - on) * L) / L)
                grad = dh * ca.repmat(on.T, 3, 1)
            else:
                g_all.append((h.T + radius) / L)
            a += ca.mtimes(dh * ca.repmat(li.T, 3, 1), omega)
            dx0 += L * ca.mtimes(dh, li)
            if curved:  # a half-space's h is linear: no curvature term
                term = d2h * ca.repmat(ca.mtimes(li.T, spread3), 3, 1)
                weighted = term if weighted is None else weighted + term
            grads.append(grad / L)
        groups.append((omega, 1.0, grads, weighted))
    for i, ob in enumerate(P.obstacles if nlp.obstacle_slots else ()):
        # contact slots (solver/contact/obstacle_slots.py): rows on_k ψ(X_k, X'_k, X''_k) −
        # (1 − on_k) L, ψ the reach at the closest approach (slot_envelope.py), X_k = x0 + T W_kᵀ,
        # X'_k = T P_kᵀ, X''_k = T P'_kᵀ
        K, rows = nlp.obstacle_slots, nlp.slot_rows[i]
        omegas = tuple(nlp.slot_matrix(p, i, part) for part in "wtk")
        on = p[lay[f"slots:{i}:on"]]
        X = slot_curve(nlp, T, z, p, i)
        fn = envelope_function(ob.type, shift_bound(nlp.length))
        v, dv, d2v = fn.map(K, "serial")(*X, *slot_inputs(nlp, p, i))
        li = lam[rows] * on / L
        rows_all += rows
        g_all.append((on * v.T - (1 - on) * L) / L)
        grads = tuple(dv[3 * c : 3 * c + 3, :] for c in range(3))
        for grad, omega in zip(grads, omegas):
            a += ca.mtimes(grad * ca.repmat(li.T, 3, 1), omega)
        dx0 += L * ca.mtimes(grads[0], li)
        weighted = d2v * ca.repmat(
            ca.mtimes(li.T, sparse(np.kron(np.eye(K), np.ones((1, 9))))), 9, 1
        )
        scaled = tuple(grad * ca.repmat(on.T, 3, 1) / L for grad in grads)
        groups.append((omegas, (1.0, 0.0, 0.0), scaled, weighted))
    slots = nlp.self_contact_slots
    if slots:
        rows = list(nlp.self_contact_rows)
        Q = ca.horzcat(*[p[lay[f"self:{k}"]][:M] for k in range(slots)]).T  # K × M
        b = ca.vertcat(*[p[lay[f"self:{k}"]][M] for k in range(slots)])
        X = ca.mtimes(T, Q.T)  # 3 × K
        lk = lam[rows] / L
        rows_all += rows
        g_all.append((b - ca.sum1(X * X).T) / L)
        a += ca.mtimes(-2 * X * ca.repmat(lk.T, 3, 1), Q)
        # ∇²ψ = −2 I: the weighted blocks are −2 λ_k/L I
        weighted = ca.repmat(ca.DM(np.eye(3)), 1, slots) * ca.repmat(
            ca.mtimes(-2 * lk.T, sparse(np.kron(np.eye(slots), np.ones((1, 3))))), 3, 1
        )
        groups.append((Q, 0.0, [-2 * X / L], weighted))
    return rows_all, g_all, a, dx0, groups


def spread(omega, rows_per_sample: int, d: int, M: int):
    """Spread ω (S × M) over the d components of every node, r rows per sample.

    ω (S × M) → the (r S × dM) matrix whose row r j + c holds ω_jk at columns d k … d k + d
    − 1.
    """
    S = omega.shape[0]
    if isinstance(omega, np.ndarray):
        return ca.DM(np.repeat(np.repeat(omega, d, axis=1), rows_per_sample, axis=0))
    repeat = sparse(np.kron(np.eye(M), np.ones((1, d))))  # M × dM
    return ca.mtimes(
        sparse(np.kron(np.eye(S), np.ones((rows_per_sample, 1)))), ca.mtimes(omega, repeat)
    )


def group_jacobian(kkt, grads, jt, E, omega, kappa: float, n: int):
    """Return the Jacobian rows ∇ψ_jᵀ ∂X_j/∂z / L of one group of rows.

    Rows ∇ψ_jᵀ ∂X_j/∂z / L for ``grads`` = ∇ψ/L (3 × S): Σ_k ω_jk (∇ψ_jᵀ ∂T/∂u)_k E_k + κ L
    ∇ψ_jᵀ (x0).
    """
    jac = ca.mtimes(ca.mtimes(grads.T, jt) * spread(omega, 1, kkt.d, kkt.M), E)
    if kappa:
        jac += ca.horzcat(kappa * kkt.nlp.length * grads.T, ca.MX(grads.shape[1], n - 3))
    return jac


def position_derivatives(kkt, jt, E, omega, kappa: float, n: int):
    """Return D = ∂X/∂z (3S × n, row 3j + c) for X_j = κ x0 + Σ_k ω_jk T_k.

    D = ∂X/∂z (3S × n, row 3j + c) for X_j = κ x0 + Σ_k ω_jk T_k; ``omega`` constant or MX
    (S × M).
    """
    S, L = omega.shape[0], kkt.nlp.length
    D = ca.mtimes(spread(omega, 3, kkt.d, kkt.M) * ca.repmat(jt, S, 1), E)
    if kappa:
        D += sparse(
            np.kron(np.ones((S, 1)), np.hstack([kappa * L * np.eye(3), np.zeros((3, n - 3))]))
        )
    return D


def group_terms(kkt, groups, jt, E, n: int, hessian: bool = True):
    """Return every group's Jacobian rows and Σ Dᵀ diag(λ ∇²ψ) D over them (None: no term).

    A group (``nonlinear_rows``) is (ω, κ, [∇ψ/L per block of rows], weighted): rows ψ(X_j);
    or a slot group ((W, P, P'), (1, 0, 0), (∇_X ψ, ∇_X' ψ, ∇_X'' ψ)/L, weighted 9 × 9K): rows
    ψ(X_j, X'_j, X''_j) of three such combinations (``slot_envelope.py``), whose Jacobian is
    the sum of the three parts and whose D interleaves them per row.
    """
    jac, hess = [], None
    for omega, kappa, grads, weighted in groups:
        if isinstance(omega, tuple):
            rows = [group_jacobian(kkt, g, jt, E, o, k, n) for g, o, k in zip(grads, omega, kappa)]
            jac.append(rows[0] + rows[1] + rows[2])
        else:
            jac += [group_jacobian(kkt, gr, jt, E, omega, kappa, n) for gr in grads]
        if not hessian or weighted is None:
            continue
        D, size = group_position_derivatives(kkt, omega, kappa, jt, E, n)
        term = ca.mtimes(D.T, ca.mtimes(block_diagonal(weighted, size), D))
        hess = term if hess is None else hess + term
    return jac, hess


def group_position_derivatives(kkt, omega, kappa, jt, E, n: int) -> tuple[ca.MX, int]:
    """Return one group's D (b·rows × n, rows j·b … j·b + b − 1 for row j) and its block size b.

    b = 3 for rows ψ(X_j) (``position_derivatives``); b = 9 for a slot group's rows
    ψ(X_j, X'_j, X''_j), whose D interleaves the three parts per row.
    """
    if not isinstance(omega, tuple):
        return position_derivatives(kkt, jt, E, omega, kappa, n), 3
    K = omega[0].shape[0]
    D = ca.vertcat(*[position_derivatives(kkt, jt, E, o, k, n) for o, k in zip(omega, kappa)])
    order = [c * 3 * K + 3 * j + m for j in range(K) for c in range(3) for m in range(3)]
    return D[order, :], 9


def contact_blocks(kkt, groups, jt, E, n: int) -> tuple[ca.MX, ca.MX, tuple[int, ...]]:
    """Return the curvature term of the rows nonlinear in the positions as blocks, unsummed.

    (D, w, sizes): Σ_j D_jᵀ W_j D_j is ``group_terms``' Hessian term, one block j per row whose
    ψ is curved (a curved obstacle's sample, a contact slot, a self-contact slot), in the groups'
    order: D_j the rows of D (R × n) from Σ_{i<j} b_i on, b_j = ``sizes[j]``; W_j = λ_j ∇²ψ_j/L
    (b_j × b_j) column-major in w (Σ b_j² × 1) from Σ_{i<j} b_i² on.  The compiled split KKT
    function outputs them, and its callers add only the blocks whose W_j is not zero: a row's
    curvature counts only where its multiplier does, and on the main job's post 1 of 48 rows
    carried force while the full sum was half the function's time.
    """
    ds, ws, sizes = [], [], []
    for omega, kappa, _, weighted in groups:
        if weighted is None:
            continue
        D, size = group_position_derivatives(kkt, omega, kappa, jt, E, n)
        ds.append(D)
        ws.append(ca.vec(weighted))  # block j: columns j·b … j·b + b − 1, column-major
        sizes += [size] * (D.shape[0] // size)
    if not ds:
        return ca.MX(0, n), ca.MX(0, 1), ()
    return ca.vertcat(*ds), ca.vertcat(*ws), tuple(sizes)


def inequality_g(kkt) -> ca.Function:
    """Build ``dlo_obstacle_g``: the values of the rows after the free rows.

    ``dlo_obstacle_g``: (z, p) → the values of the rows after the free rows (folds,
    obstacles, self-contact slots), as ``g[n_free_rows:]`` of the NLP.
    """
    nlp, M, d, n, L = kkt.nlp, kkt.M, kkt.d, kkt.n, kkt.nlp.length
    lay, P, nf = nlp.params, nlp.problem, nlp.n_free_rows
    z, p = ca.MX.sym("z", n), ca.MX.sym("p", lay.size)
    u = ca.reshape(kkt.geometry.apply(p, z), d, M)
    T = kkt.tangent_function.map(M, "serial")(u)
    parts = []
    local = kkt.local_rows[kkt.local_rows >= nf]
    if local.size:
        parts.append((local, kkt.local_function(local)(z, p, ca.MX(local.size, 1))[0]))
    if P.obstacles:
        omega = kkt.geometry.obstacle_rows(p)
        S = omega.shape[0]
        X = ca.repmat(z[0:3] * L, 1, S) + ca.mtimes(T, omega.T)
        for i, ob in enumerate(P.obstacles):
            x, po = ca.SX.sym("x", 3), ca.SX.sym("po", OBSTACLE_TYPES[ob.type].size)
            h = ca.Function(f"dlo_h_{ob.type}_value", [x, po], [OBSTACLE_TYPES[ob.type].h(x, po)])
            values = (
                h.map(S, "serial")(X, ca.repmat(p[lay[f"obstacle:{i}"]], 1, S)).T
                + p[lay["radius"]][0]
            )
            if nlp.obstacle_slots:
                on = p[lay[f"samples:{i}:on"]]
                values = on * values - (1 - on) * L
            parts.append((np.array(nlp.obstacle_rows[i]), values / L))
        for i, ob in enumerate(P.obstacles if nlp.obstacle_slots else ()):
            K, on = nlp.obstacle_slots, p[lay[f"slots:{i}:on"]]
            X = slot_curve(nlp, T, z, p, i)
            v = value_function(ob.type, shift_bound(nlp.length))
            values = v.map(K, "serial")(*X, *slot_inputs(nlp, p, i))
            parts.append((np.array(nlp.slot_rows[i]), (on * values.T - (1 - on) * L) / L))
    if nlp.self_contact_slots:
        K = nlp.self_contact_slots
        Q = ca.horzcat(*[p[lay[f"self:{k}"]][:M] for k in range(K)]).T
        b = ca.vertcat(*[p[lay[f"self:{k}"]][M] for k in range(K)])
        X = ca.mtimes(T, Q.T)
        parts.append((np.array(nlp.self_contact_rows), (b - ca.sum1(X * X).T) / L))
    order = np.concatenate([r for r, _ in parts]) - nf
    if sorted(order.tolist()) != list(range(nlp.g_sym.shape[0] - nf)):
        raise ValueError("assembled inequality rows: rows not covered exactly once")
    g = ca.vertcat(*[v for _, v in parts])[np.argsort(order).tolist()]
    return ca.Function("dlo_obstacle_g", [z, p], [ca.densify(g)])
