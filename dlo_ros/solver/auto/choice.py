"""The model ladder: what auto may choose, and its first choice for a scene.

A :class:`ModelChoice` names one reduced model (planar or 3D, twist, stretch, gravity, basis order,
the obstacles in the NLP, the reference frame, the obstacle samples, self-contact).  The ladder's
rungs are :data:`ORDERS` (basis orders) and the obstacle samples up to :data:`MAX_SAMPLES`;
:func:`initial_choice` is the smallest model the scene allows a priori, :func:`full_choice` the 3D
model of a choice.  The checks (:mod:`.checks`) move along the ladder a posteriori.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ...model.problem import Problem
from ..build.mesh import MeshSpec
from ..build.nlp import choose_reference_frame
from ..options import SolverOptions
from .reach import in_plane_obstacles, not_planar, reachable_obstacles, stretch_needed

#: the basis orders auto chooses among, lowest first
ORDERS = (8, 12, 16, 24, 32)
#: the first order: the first answer is within 1e-3·L for typical scenes; checks go up, or to 8
START_ORDER = 12
#: a 3D model turns its Euler-angle pole away when a tangent comes closer than this [degrees]
POLE_MIN_DEG = 40.0
#: obstacle samples auto may go up to (each step 2n − 1: the old samples stay, one between each
#: pair)
MAX_SAMPLES = 641
#: self-contact slots of the model auto switches to when a shape comes within reach of itself
#: (``solver.self_contact_pairs`` when set)
AUTO_SELF_CONTACT_PAIRS = 16
#: obstacle contact slots per obstacle of auto's element models (``solver.obstacle_slots`` when
#: set): a point contact touches where the shape does, not at the mesh node nearest it
AUTO_OBSTACLE_SLOTS = 2


@dataclass
class ModelChoice:
    """The reduced model in use and why.

    ``obstacles``: indices into the scene's obstacles that are in the NLP.  ``frame``: R0
    (row-major 9) of a 3D model turned away from its Euler-angle pole (None: the default frame).
    ``samples``: obstacle_samples, the points along s where the obstacles are enforced.
    ``self_contact``: self-contact rows in the NLP (3D director models only).  ``mesh``: the
    element mesh a refinement chose (``build/mesh.py``; None: ``order`` shared out by element
    length over the scene's breakpoints).
    ``plane_kept``: ``solver.plane: keep``, the model stays planar (no switch to 3D is made).
    ``estimated_error_m`` is the last check's estimate, ``order_error_m`` its basis-order part (the
    rest: sampling), ``sampling_error_m`` the samples shadow's estimate (nan: not measured).
    """

    planar: bool
    twist: bool
    stretch: bool
    gravity: bool
    order: int
    obstacles: tuple[int, ...]
    estimated_error_m: float = float("nan")
    reasons: list[str] = field(default_factory=list)
    frame: tuple | None = None
    samples: int = 41
    self_contact: bool = False
    mesh: MeshSpec | None = None
    order_error_m: float = float("nan")
    sampling_error_m: float = float("nan")
    plane_kept: bool = False

    @property
    def may_leave_plane(self) -> bool:
        """Tell whether this planar model may be switched to 3D (not with the plane kept)."""
        return self.planar and not self.plane_kept

    def key(self) -> tuple:
        """Return what identifies the model built for this choice (its pool key, untagged)."""
        return (
            self.planar,
            self.stretch,
            self.gravity,
            self.order,
            self.obstacles,
            self.frame,
            self.samples,
            self.self_contact,
            self.mesh,
        )

    def reference_frame(self) -> np.ndarray | None:
        """Return R0 as a 3×3 matrix, or None for the model's default frame."""
        return None if self.frame is None else np.array(self.frame, dtype=float).reshape(3, 3)


def initial_choice(problem: Problem, options: SolverOptions, tolerance: float) -> ModelChoice:
    """Return the smallest model the scene allows a priori, with its reasons.

    Obstacles out of reach (L/4 margin) are left out; the planar model when the scene lies in one
    plane (``options.frame == 'auto'`` only), without the obstacles clear of it; gravity dropped
    when the sag bound D_max L⁴ / (8 Rf_min) is below ``tolerance``/10; the stretch field when the
    grips stretch the string or hold it taut within ``tolerance``/2
    (:func:`.reach.stretch_needed`); order :data:`START_ORDER`.
    """
    L, tol = problem.string.length, tolerance
    reasons = []
    obstacles = reachable_obstacles(problem, L / 4)
    if len(obstacles) < len(problem.obstacles):
        reasons.append(f"{len(problem.obstacles) - len(obstacles)} obstacle(s) out of reach")
    planar = False
    if options.frame == "auto":
        r0 = choose_reference_frame(problem, "auto")
        in_plane = in_plane_obstacles(problem, obstacles, r0)
        why = not_planar(problem, in_plane, r0)
        planar = not why
        reasons.append("planar: scene lies in one plane" if planar else f"3D: {why}")
        if planar and len(in_plane) < len(obstacles):
            reasons.append(f"{len(obstacles) - len(in_plane)} obstacle(s) clear of the plane")
            obstacles = in_plane
    if options.plane == "keep":
        if not planar:
            raise ValueError(
                "solver.plane: 'keep' needs a scene in one plane ("
                + (why if options.frame == "auto" else "solver.frame is 'paper'")
                + ")"
            )
        reasons.append("plane kept (solver.plane: keep)")
    sag = (
        problem.string.weight_per_length.maximum
        * L**4
        / (8 * problem.string.bend_stiffness.minimum)
    )
    gravity = sag >= tol / 10
    reasons.append(
        f"gravity {'kept' if gravity else 'dropped'}: sag bound {sag:.3g} m vs {tol / 10:.3g} m"
    )
    # taut within δ/2: the inextensible model would hold the string to the straight line
    why_stretch = stretch_needed(problem, tol / 2)
    stretch = bool(why_stretch)
    if stretch:
        reasons.append(why_stretch)
    return ModelChoice(
        planar,
        False,
        stretch,
        gravity,
        START_ORDER,
        obstacles,
        reasons=reasons,
        samples=options.obstacle_samples,
        plane_kept=options.plane == "keep",
    )


def full_choice(choice: ModelChoice, problem: Problem) -> ModelChoice:
    """Return the 3D model of ``choice``: every obstacle within reach (L/4) is in it."""
    reach = set(reachable_obstacles(problem, problem.string.length / 4)) | set(choice.obstacles)
    return replace(
        choice, planar=False, obstacles=tuple(sorted(reach)), reasons=list(choice.reasons)
    )
