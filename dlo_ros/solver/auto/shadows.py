"""Measurements of a committed shape on other models: shadows, 3D stability, pole, penetration.

Each function takes a :class:`.checks.CheckSnapshot` and the
:class:`.pool.ModelPool` whose models it solves on; the models it
builds stay pooled, since they are the ones an escalation switches to.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ...model import rotations
from ...model.rotations import frame_with_pole, pole_angle_deg
from ..build.nlp import has_point_moments
from ..results.result import ShapeResult
from ..shape_solver import ShapeSolver
from .choice import ModelChoice, full_choice
from .pool import ModelPool

if TYPE_CHECKING:  # the snapshot's class uses these functions (checks.py imports this module)
    from .checks import CheckSnapshot

#: the penetration check looks at this many times the samples (between them the sampled
#: constraints let the string cut into an obstacle: a chord of spacing h cuts a sphere of radius R
#: by about h²/8R)
PENETRATION_OVERSAMPLING = 8


def shadow_error(pool: ModelPool, snap: CheckSnapshot, choice: ModelChoice) -> float:
    """Return max |x(s) − x'(s)| [m] between the checked shape and model ``choice`` solved from it.

    ``choice`` is the next or the previous order, or 2n − 1 obstacle samples, solved from the
    checked shape (same branch): the a-posteriori estimate of the coarser of the two; nan when
    that solve fails (inconclusive: the next check retries; a streamed update's check stops at
    ``solver.update_time_limit``, ``snap.limited``).  The shadow is pooled: it is the model
    an escalation switches to.  With background checks it is compiled ahead
    (``ModelPool.compile_ahead``), as the models a switch or the queries use.
    """
    result = shadow_solve(pool, snap, choice)[1]
    if not result.ok:
        return float("nan")
    return float(np.max(np.linalg.norm(result.points - snap.points, axis=1)))


def shadow_solve(
    pool: ModelPool, snap: CheckSnapshot, choice: ModelChoice
) -> tuple[ShapeSolver, ShapeResult]:
    """Return the pooled model of ``choice`` and its answer at the snapshot's poses, from it.

    The answer is committed (the model's warm start for a switch to it, ``lead_in.py``), and
    kept in ``snap.answers`` with a copy of that state: a checked solve that switches to this
    model at these poses takes it instead of solving it again (``stream_checks.check_now``).
    """
    shadow = pool.solver_for(
        choice, snap.problem, stream=False, source=snap.inner, state=snap.state, once=True
    )
    if pool.worker.background and not shadow.kkt_compiled:
        # beside a stream: an interpreted shadow holds the GIL through long CasADi calls, and the
        # stream's updates during a check waited for them (compiled once, later checks release
        # it).  Only for its derivatives: a shadow whose derivatives are compiled (a clone of a
        # compiled mesh, build/mesh_clone.py) lacks at most its outputs' library, which pays only
        # for a model that streams (a switch compiles it); each check on the main job's post
        # started gcc on the outputs of a moved mesh that was never used again
        pool.compile_ahead(shadow)
    result = shadow.solve(snap.poses, limited=snap.limited)
    state = shadow.snapshot()
    if result.status in ("ok", "unverified") and state is not None:
        snap.answers[choice.key()] = (result, state)
    return shadow, result


def planar_3d_eigenvalue(pool: ModelPool, snap: CheckSnapshot) -> float | None:
    """Return the 3D model's smallest reduced-Hessian eigenvalue at the embedded planar shape.

    None when that is stable.  The 3D model is the pooled model a switch to 3D streams on: a
    check that refines a planar mesh builds the new mesh's one too (``checks.py``), so a check of
    the new model builds nothing, and a switch to 3D meanwhile waits for the check at most.
    """
    full = pool.solver_for(
        full_choice(snap.choice, snap.problem),
        snap.problem,
        stream=False,
        source=snap.inner,
        state=snap.state,
    )
    return full.unstable_eigenvalue()


def pole_angle(snap: CheckSnapshot) -> float | None:
    """Return the angle [degrees] between the Euler-angle pole and the checked shape's tangents.

    None when the model has no pole (the director model), the state is unknown, or the scene has
    point moments (they are modelled about the pole, which may not turn).  Near the pole φ and ψ
    turn about the same axis, the fields get steep and the basis order stops converging: on the
    main job's post the order 16/24/32 shapes differed by 1–2 cm with the pole 28° from a
    tangent, by 0.6 mm/0.03 mm with it 46° away.
    """
    inner, state = snap.inner, snap.state
    if inner.nlp.director:  # no pole
        return None
    if state is None or has_point_moments(snap.problem):  # moments are modelled about the pole
        return None
    return float(pole_angle_deg(inner.model.node_tangents(state.z).T, inner.nlp.r0[:, 2]))


def farthest_pole(snap: CheckSnapshot) -> tuple[np.ndarray, float]:
    """Return the direction farthest from every tangent of the checked shape, and its angle [°]."""
    assert snap.state is not None
    normal, best = rotations.farthest_pole(snap.inner.model.node_tangents(snap.state.z).T)
    return normal, float(best)


def turned_frame(pool: ModelPool, snap: CheckSnapshot, normal: np.ndarray) -> ModelChoice:
    """Return the checked model with its Euler-angle pole turned to ``normal``; build it.

    The new model is built and warm-started here (worker thread), so the switch builds nothing.
    """
    r0 = frame_with_pole(normal, snap.inner.nlp.r0[:, 0])
    choice = replace(
        snap.choice,
        frame=tuple(np.round(r0.ravel(), 12)),
        estimated_error_m=float("nan"),
        order_error_m=float("nan"),
        reasons=list(snap.choice.reasons),
    )
    pool.solver_for(choice, snap.problem, stream=False, source=snap.inner, state=snap.state)
    return choice


def penetration(snap: CheckSnapshot) -> tuple[float, str]:
    """Return (depth [m], obstacle name): how far the checked shape enters its obstacles.

    Measured between the samples where they are enforced, over PENETRATION_OVERSAMPLING × as many
    points (the string's radius included).  The sampled constraints cannot see it, the order
    shadows neither (they share the samples); it is the sampling part of the error estimate.
    (0, '') without obstacles.
    """
    inner, state = snap.inner, snap.state
    if state is None or not inner.problem.obstacles:
        return 0.0, ""
    s = np.linspace(
        0.0, inner.nlp.length, PENETRATION_OVERSAMPLING * (snap.choice.samples - 1) + 1
    )
    x = inner.model.positions(state.z, s)
    radius = inner.problem.string.radius
    depths = [(float(np.max(ob.h_many(x))) + radius, ob.name) for ob in inner.problem.obstacles]
    depth, name = max(depths)
    return max(depth, 0.0), name
