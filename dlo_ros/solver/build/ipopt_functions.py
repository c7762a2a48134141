"""IPOPT for one NLP: its options, and its derivative functions from the assembled KKT function.

``StringNLP.make_solver`` builds an ``nlpsol`` from these; ``ipopt_derivatives`` gives it
``grad_f``, ``jac_g`` and ``hess_lag``, so that nlpsol differentiates nothing itself.
"""

from __future__ import annotations

import casadi as ca

from ..options import SolverOptions


#: nlpsol's own options: quiet, a failed solve is a status (not an exception), and no λ_p, so
#: no "nlp_grad" (the reverse derivative of the whole problem, built at each new NLP's first
#: solver: 30-40 ms of the 40-45 a Fig. 3 mesh's took); nothing here reads λ_p or differentiates
#: a solver
NLPSOL_OPTIONS = {
    "print_time": False,
    "error_on_fail": False,
    "calc_lam_p": False,
    "no_nlp_grad": True,
}


def ipopt_options(
    options: SolverOptions, warm: bool, max_iterations: int | None, max_wall_time: float
) -> dict:
    """Return IPOPT's options, cold (default barrier start) or warm (warm start).

    IPOPT's options: cold (default barrier start) or warm (primal-dual warm start).

    ``max_iterations``: IPOPT's limit (default: the options', and at most 200 when warm);
    ``max_wall_time`` [s]: IPOPT's limit on one call's wall-clock time (0: none).
    """
    ipopt = {
        "print_level": 0,
        "sb": "yes",
        "tol": options.tolerance,
        "acceptable_tol": 1e-7,
        "constr_viol_tol": 1e-10,
        "max_iter": options.max_iterations,
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
                "max_iter": min(options.max_iterations, 200),
            }
        )
    if max_iterations is not None:
        ipopt["max_iter"] = int(max_iterations)
    if max_wall_time > 0:
        ipopt["max_wall_time"] = float(max_wall_time)
    return ipopt


def ipopt_problem(
    nlp: dict, g_fn: ca.Function, values: tuple[ca.Function, ...] | None = None
) -> dict[str, ca.MX]:
    """Return nlpsol's problem (x, p, f, g) as calls of functions built once.

    ``nlp``: the SX expressions (x, p, f, g); ``g_fn``: (x, p) → g, already built;
    ``values``: the assembled (objective, energy, rows) whose energy (x, p) → f replaces ``nlp``'s
    f (``assembled_values.py``).
    Given the expressions themselves, every nlpsol built its own function of the whole graph: most
    of an IPOPT solver's creation (a new mesh's two solvers took a third of a second, 80 ms so).
    """
    z, p = ca.MX.sym("x", nlp["x"].shape[0]), ca.MX.sym("p", nlp["p"].shape[0])
    if values is not None:
        return {"x": z, "p": p, "f": values[1](z, p), "g": g_fn(z, p)}
    f = ca.Function("f", [nlp["x"], nlp["p"]], [nlp["f"]])
    return {"x": z, "p": p, "f": f(z, p), "g": g_fn(z, p)}


def ipopt_derivatives(
    nlp: dict,
    hessian_fn: ca.Function,
    g_fn: ca.Function,
    jac_g_fn: ca.Function,
    values: tuple[ca.Function, ...] | None = None,
) -> dict[str, ca.Function]:
    """Build IPOPT's derivative functions (nlpsol's grad_f, jac_g and hess_lag).

    IPOPT's derivative functions (nlpsol's ``grad_f``, ``jac_g`` and ``hess_lag`` options).

    ``nlp``: nlpsol's dict (x, p, f, g); ``hessian_fn``, ``g_fn`` and ``jac_g_fn``: the NLP's
    Lagrangian Hessian ∇²f + Σ λ_i ∇²g_i, rows and their Jacobian (``StringNLP``).  Left to
    nlpsol, each solver would differentiate the flattened NLP symbolically: its SX Hessian is most
    of a solver's set-up (bench/results/compile_cost.md).  IPOPT's Hessian is that of γ f + λᵀg;
    ``hessian_fn`` is linear in λ, so

        ∇²(γ f + λᵀg) = H(z, p, λ) + (γ − 1) H(z, p, 0),

    the second term evaluated only when γ ≠ 1 (IPOPT's restoration phase).
    """
    n, m, n_p = nlp["x"].shape[0], nlp["g"].shape[0], nlp["p"].shape[0]
    z, p, gamma, lam = (
        ca.MX.sym("x", n),
        ca.MX.sym("p", n_p),
        ca.MX.sym("lam_f"),
        ca.MX.sym("lam_g", m),
    )
    zero = ca.MX.zeros(m)
    hess = hessian_fn(z, p, lam) + ca.if_else(
        gamma == 1, ca.MX.zeros(n, n), (gamma - 1) * hessian_fn(z, p, zero), True
    )
    if values is not None:  # (x, p) → [f, ∇f] assembled (``assembled_values.py``)
        value, gradient = values[0](z, p)
        names = (["x", "p"], ["f", "grad_f_x"])
        grad_f = ca.Function("nlp_grad_f", [z, p], [value, gradient], *names)
    else:  # the gradient alone: the KKT function would evaluate the Hessian as well
        x, f = nlp["x"], nlp["f"]
        grad_f = ca.Function(
            "nlp_grad_f", [x, nlp["p"]], [f, ca.gradient(f, x)], ["x", "p"], ["f", "grad_f_x"]
        )
    return {
        "grad_f": grad_f,
        "jac_g": ca.Function(
            "nlp_jac_g",
            [z, p],
            [g_fn(z, p), jac_g_fn(z, p)],
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
