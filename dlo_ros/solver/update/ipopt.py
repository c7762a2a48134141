"""The IPOPT fallback: cold and warm-started interior-point solves of the NLP, and leaving saddles.

A solve is accepted when IPOPT reports success (``SUCCESS``), the largest constraint violation is
below 1e-6 L and z is finite.  Warm solves restart from a committed equilibrium's z and multipliers
with IPOPT's warm-start options (``StringNLP.make_solver``).

MUMPS (IPOPT's linear solver) is not thread-safe across instances (coin-or/Ipopt#733): every IPOPT
call in the process, and every freeing of an IPOPT instance, holds the module-wide ``IPOPT_LOCK``.
"""

from __future__ import annotations

import threading
from typing import Callable

import numpy as np

from .kkt import violation
from ..build.nlp import StringNLP
from ..results.result import ShapeResult
from ..results.stability import is_stable
from ..state import SolverState

SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
TIME_LIMIT = "Maximum_WallTime_Exceeded"  # IPOPT's status for a call stopped by its max_wall_time
INFEASIBLE = "Infeasible_Problem_Detected"
IPOPT_LOCK = (
    threading.Lock()
)  # MUMPS is not thread-safe across IPOPT instances (coin-or/Ipopt#733)

#: (ok, state, IPOPT's return status, iterations, constraint violation [m or rad]) of one IPOPT
# solve
Attempt = tuple[bool, SolverState, str, int, float]


#: IPOPT iterations of one attempt to leave a saddle (``escape_saddle``): the successful attempts
# over : the unit tests took 5–62; a failed one ran to the solver's limit (500, 1.4 s at order 16),
# four times : per escape, while a stream waited
ESCAPE_MAX_ITERATIONS = 150


class IpoptSolvers:
    """The IPOPT solvers of one NLP: cold, warm, and the cold one for leaving saddles.

    The last stops at ESCAPE_MAX_ITERATIONS.  Each is created on first use (a helper that only
    takes Newton steps never needs them); all use the NLP's ``ipopt_derivatives``.  A warm update
    calls copies of them that stop at ``solver.update_time_limit``.
    """

    def __init__(self, nlp: StringNLP):
        self.nlp = nlp
        self._solvers: dict[
            str, object
        ] = {}  # "cold", "warm", "escape" and their "_in_update" copies → nlpsol

    def get(self, warm: bool, escape: bool = False, in_update: bool = False):
        """Return the warm or the cold solver, created now if it is not yet.

        ``escape``: the cold one for leaving a saddle; ``in_update``: its copy that stops at
        ``solver.update_time_limit`` (for a warm update's attempts).
        """
        kind = ("escape" if escape else "warm" if warm else "cold") + (
            "_in_update" if in_update else ""
        )
        if kind not in self._solvers:
            limit = min(self.nlp.options.max_iterations, ESCAPE_MAX_ITERATIONS) if escape else None
            wall = self.nlp.options.update_time_limit if in_update else 0.0
            self._solvers[kind] = self.nlp.make_solver(
                warm=warm, max_iterations=limit, max_wall_time=wall
            )
        return self._solvers[kind]

    def prepare(self) -> None:
        """Create the cold solver and a warm update's warm solver now."""
        self.get(False), self.get(True, in_update=True)

    def free(self) -> None:
        """Drop the solvers, under ``IPOPT_LOCK``.

        Freeing an IPOPT/MUMPS instance must not overlap a solve in another thread.
        """
        with IPOPT_LOCK:
            self._solvers.clear()


def call(
    nlp: StringNLP,
    solver,
    z0: np.ndarray,
    p: np.ndarray,
    lam_g0: np.ndarray | None = None,
    lam_x0: np.ndarray | None = None,
) -> Attempt:
    """Solve once with IPOPT from z0 at parameters p; a warm solver also takes λ_g0 and λ_x0."""
    args: dict[str, np.ndarray | None] = {"x0": z0, "p": p, "lbg": nlp.lbg, "ubg": nlp.ubg}
    if lam_g0 is not None:
        args["lam_g0"] = lam_g0
        args["lam_x0"] = lam_x0
    with IPOPT_LOCK:
        sol = solver(**args)
        stats = solver.stats()
    z = np.asarray(sol["x"]).ravel()
    lam_g = np.asarray(sol["lam_g"]).ravel()
    lam_x = np.asarray(sol["lam_x"]).ravel()
    g = np.asarray(sol["g"]).ravel()
    viol = violation(nlp, g)
    ok = stats["return_status"] in SUCCESS and viol < 1e-6 * nlp.length and np.all(np.isfinite(z))
    return (
        bool(ok),
        SolverState(z, lam_g, lam_x, p, g=g),
        stats["return_status"],
        int(stats.get("iter_count", 0)),
        viol,
    )


def witness(nlp: StringNLP, g: np.ndarray | None) -> str:
    """Return ', most violated: <row> by <amount>' at the best point IPOPT found.

    The witness of an 'infeasible' or 'failed' verdict; '' when nothing is violated.
    """
    if g is None or not g.size:
        return ""
    excess = np.maximum(np.maximum(nlp.lbg - g, 0.0), np.maximum(g - nlp.ubg, 0.0)) * nlp.row_scale
    i = int(np.argmax(excess))
    if not excess[i] > 0:
        return ""
    kind = nlp.row_kind[i]
    names = {
        "grip": lambda k: f"grip {k[1]!r} {k[2]}",
        "obstacle": lambda k: f"obstacle {k[1]} at s = {nlp.obstacle_s[k[2]]:.4g} m",
        "relative": lambda k: f"relative position {k[1]}",
        "norm": lambda k: f"unit norm at node {k[1]}",
        "fold": lambda k: f"fold guard at node {k[1]}",
        "self": lambda k: f"self-contact slot {k[1]}",
        "slot": lambda k: f"obstacle {k[1]} contact slot {k[2]}",
    }
    return f", most violated: {names.get(kind[0], str)(kind)} by {excess[i]:.3g}"


def unverified_unstable(result: ShapeResult, state: SolverState) -> bool:
    """Tell whether an unverified ``result`` has a negative reduced eigenvalue (``is_stable``)."""
    if result.status != "unverified" or result.min_eigenvalue is None:
        return False
    assert state.hessian is not None  # the result's eigenvalue was judged with it (outputs.py)
    return not is_stable(result.min_eigenvalue, state.hessian, state.unstable_direction)


#: appended to the message of a result that replaced an unstable equilibrium
LEFT_SADDLE = "; left an unstable equilibrium along its negative-curvature mode"


def lower_than(candidate: ShapeResult, saddle: ShapeResult) -> bool:
    """Tell whether ``candidate`` went downhill from ``saddle``.

    Its total energy is below ``saddle``'s by more than 1e-12 relative.  Without a total (a dead
    moment with no potential: ``results/moment_work.py``) there is no energy to go down: any
    candidate counts, and ``escape_saddle`` keeps the first stable one.
    """
    total, new = saddle.energy.get("total"), candidate.energy.get("total")
    if total is None or new is None:
        return True
    return new < total - 1e-12 * abs(total)


def escape_saddle(
    result: ShapeResult,
    state: SolverState,
    attempt: Callable[[np.ndarray, np.ndarray], Attempt],
    build: Callable[..., ShapeResult],
    depth: int = 3,
) -> tuple[ShapeResult, SolverState]:
    """Leave a saddle: re-solve from beside it, for a stable result of lower energy.

    A stationary point with negative reduced curvature is not a shape a string rests in: an
    unstable result, or an unverified one (its residual over the tolerance) whose reduced Hessian
    has a negative eigenvalue.  Step along the unstable eigenvector (both signs, 0.2 then 0.6 rad
    at most in any coefficient) and re-solve cold (``attempt(z0, p)``); keep the first stable
    result of lower energy.  A lower but still unstable stationary point is left the same way, up
    to ``depth`` saddles deep (a compressed twist-free strip falls from the planar buckle through
    a half-twisted saddle).
    Symmetric starts (a planar guess for a scene whose minimum is twisted, paper Fig. 2) land on
    such saddles. ``build(state, ipopt_status, iterations, violation, warm_started,
    continuation_steps)`` makes the result of a re-solved state.
    """
    if state.unstable_direction is None or not (
        result.stable is False or unverified_unstable(result, state)
    ):
        return result, state
    d = state.unstable_direction / np.max(np.abs(state.unstable_direction))
    lower: tuple[ShapeResult, SolverState] | None = None
    for step in (
        0.2,
        0.6,
    ):  # a larger step when IPOPT falls back onto the saddle from the small one
        for sign in (1.0, -1.0):
            ok, trial, status, it, viol = attempt(state.z + sign * step * d, state.p)
            result.iterations += it
            if not ok:
                continue
            candidate = build(
                trial,
                status,
                result.iterations,
                viol,
                result.warm_started,
                result.continuation_steps,
            )
            if candidate.status == "failed":
                continue
            if not lower_than(candidate, result):
                continue
            if candidate.stable:
                candidate.message += LEFT_SADDLE
                return candidate, trial
            if lower is None:
                lower = (candidate, trial)
    if lower is not None and depth > 1:
        candidate, trial = escape_saddle(lower[0], lower[1], attempt, build, depth - 1)
        if candidate.stable:
            return candidate, trial
    result.message += (
        "; unstable equilibrium (no stable one found nearby)"
        if result.stable is False
        else "; a direction of negative curvature (no stable equilibrium found nearby)"
    )
    return result, state
