"""Solver options (the ``solver`` section of a scene file)."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any

FRAMES = ("auto", "paper")
MODELS = ("auto", "full", "planar")
ROTATIONS = ("director", "euler")
#: the Euler-angle models' bases ('elements' is also what the director model is built on)
BASES = ("chebyshev", "fourier", "elements")
#: where the obstacle rows sit: uniform samples, or the element mesh's own nodes
OBSTACLE_POINTS = ("samples", "nodes")
SLOTTED_OBSTACLES = ("all", "flat", "points")
#: whether model 'auto' may leave the scene's plane ('keep': a string held in it)
PLANES = ("auto", "keep")


@dataclass(frozen=True)
class SolverOptions:
    """How the Ritz NLP is built and solved.

    basis/order: Ritz basis ('chebyshev' default, the paper's 'fourier', or 'elements': nodal
    values on spectral elements split at grips, loads and material knots, as the director model)
    and number of functions per field (for 'elements' and 'director': Legendre–Gauss–Lobatto nodes
    shared out by element length, at least 3; the director model is always on elements, so model
    'full' with rotation 'director' refuses 'fourier' and frame 'paper', which it would ignore).
    quadrature_nodes: Chebyshev–Lobatto nodes for the energy integrals and the centreline (for
    'elements' and 'director': per element, at most order + 8). obstacle_samples: points along s,
    uniformly spaced (spacing L/(samples−1)), where h(x(s)) + r ≤ 0 is imposed.  obstacle_slots:
    per obstacle, rows whose arc lengths are parameters, placed at the string's closest approaches
    to the obstacle and moved with them (solver/contact/obstacle_slots.py); 0 (default): the
    samples alone.  slotted_obstacles: which obstacles get them: 'all' (default), 'flat' (only
    those without curvature, such as a table) or 'points' (those and the ones a string touches at
    points, such as a sphere, not along a line as a bar: auto's element models, which follow a
    contact along a bar by refining the mesh about it).  obstacle_points: where the obstacle rows
    sit:
    'samples' (default: the ``obstacle_samples`` uniform arc lengths) or 'nodes' (the element
    mesh's LGL nodes, so a mesh refined near a contact resolves it finer; element models only:
    model 'full' with rotation 'director', or basis 'elements'; solver/contact/obstacle_points.py).
    frame: 'auto' rotates the Euler-angle reference so the straight string sits at θ = π/2 (away
    from the singularity); 'paper' is the paper's frame (singular at the straight state).
    rotation: how a 3D model represents the material frame: 'director' (default: nodal unit
    quaternions, or unit tangents when the twist is not held, on spectral elements split at
    interior grips, point loads and material kinks; no singular direction, see model/director.py)
    or 'euler' (the paper's Euler angles in one Ritz basis over [0, L], with ``frame``; kept for
    the benchmark).  Planar models always use the in-plane angle φ.
    model: 'auto' (default: the smallest model the scene needs, checked a posteriori against
    error_tolerance, see solver/auto/auto_solver.py), 'full' (3D: φ, θ and, when two clamps hold
    it, ψ) or 'planar' (φ only, θ ≡ π/2: the string stays in the working plane; requires a planar
    scene and frame 'auto'). plane: 'auto' (default: model 'auto' leaves the scene's plane when the
    targets, an obstacle, self-contact or a 3D instability need it) or 'keep' (the string is held
    in the scene's plane, as the paper's wide strips are: model 'auto' chooses among planar models
    only, its stability verdict is for in-plane perturbations, and a target out of the plane is
    refused as 'invalid'; needs a planar scene, model 'auto' or 'planar').
    error_tolerance [m]: what 'auto' guarantees on the centreline; 0 means 1e-3·L (1 mm on 1 m).
    recheck_every: 'auto' repeats its a-posteriori checks every this many streamed updates.
    output_points: centreline samples in a result.
    tolerance: IPOPT's (scaled) convergence tolerance. max_continuation_steps: the largest number
    of equal steps a failed warm update is split into. update_time_limit [s]: how long a streamed
    update (a warm solve from a committed shape that commits) may try: no IPOPT attempt starts
    after it, and each attempt within it stops at it (IPOPT's ``max_wall_time``); the update then
    answers ``failed`` and names this limit.  0: no limit.  A cold solve, a ``check_now`` re-solve
    and a query are never limited, nor auto's re-solves and checks inside them
    (``update/time_limit.py``).
    self_contact_pairs: capacity of the self-contact pair list (director 3D models only; 0:
    self-contact is not modelled).  Each slot is one inequality row |x(s_a) − x(s_b)|² ≥ D² whose
    pair of arc lengths is a parameter, refreshed from the current shape before every solve
    (solver/contact/self_contact.py).
    self_contact_samples: points along s where self-contact is checked (0: from the radius, see
    ``self_contact.contact_geometry``).
    """

    basis: str = "chebyshev"
    order: int = 16
    quadrature_nodes: int = 40
    obstacle_samples: int = 41
    obstacle_slots: int = 0
    slotted_obstacles: str = "all"
    obstacle_points: str = "samples"
    frame: str = "auto"
    output_points: int = 51
    tolerance: float = 1e-10
    max_iterations: int = 500
    max_continuation_steps: int = 8
    max_strain: float = 0.2
    model: str = "auto"
    plane: str = "auto"
    rotation: str = "director"
    error_tolerance: float = 0.0
    recheck_every: int = 10
    update_time_limit: float = 2.0
    self_contact_pairs: int = 0
    self_contact_samples: int = 0

    def validate(self) -> None:
        if self.basis not in BASES:
            raise ValueError(f"solver.basis: must be one of {BASES}, got {self.basis!r}")
        if not (2 <= self.order <= 60):
            raise ValueError(f"solver.order: must be in [2, 60], got {self.order}")
        if self.basis == "elements" and self.order < 3:
            raise ValueError(
                f"solver.order: must be at least 3 for solver.basis 'elements', got {self.order}"
            )
        if not (max(8, self.order + 2) <= self.quadrature_nodes <= 400):
            raise ValueError(
                "solver.quadrature_nodes: must be in [max(8, order+2), 400], "
                f"got {self.quadrature_nodes}"
            )
        if not (2 <= self.obstacle_samples <= 1000):
            raise ValueError(
                f"solver.obstacle_samples: must be in [2, 1000], got {self.obstacle_samples}"
            )
        if not (0 <= self.obstacle_slots <= 256):
            raise ValueError(
                f"solver.obstacle_slots: must be in [0, 256], got {self.obstacle_slots}"
            )
        self._validate_obstacle_points()
        self._validate_frame_and_plane()
        if not (2 <= self.output_points <= 10000):
            raise ValueError(
                f"solver.output_points: must be in [2, 10000], got {self.output_points}"
            )
        if not (0 < self.tolerance < 1e-2):
            raise ValueError(f"solver.tolerance: must be in (0, 1e-2), got {self.tolerance}")
        if not (1 <= self.max_iterations <= 100000):
            raise ValueError(
                f"solver.max_iterations: must be in [1, 100000], got {self.max_iterations}"
            )
        if not (1 <= self.max_continuation_steps <= 1024):
            raise ValueError("solver.max_continuation_steps: must be in [1, 1024]")
        if self.model not in MODELS:
            raise ValueError(f"solver.model: must be one of {MODELS}, got {self.model!r}")
        if self.rotation not in ROTATIONS:
            raise ValueError(f"solver.rotation: must be one of {ROTATIONS}, got {self.rotation!r}")
        if self.model == "planar" and self.frame != "auto":
            raise ValueError("solver.model: 'planar' needs solver.frame 'auto'")
        ignored = self._ignored_by_director()
        if ignored:
            name = ignored[0]
            raise ValueError(
                f"solver.{name}: {getattr(self, name)!r} belongs to the Euler-angle model; "
                "the 3D model (solver.rotation 'director', the default) has neither a Ritz basis "
                "nor a reference frame: set solver.rotation 'euler' to use it"
            )
        if not (self.error_tolerance >= 0 and self.error_tolerance < 1e3):
            raise ValueError(
                f"solver.error_tolerance: must be >= 0 m (0 = 1e-3·L), got {self.error_tolerance}"
            )
        if not (0 <= self.update_time_limit <= 3600):
            raise ValueError(
                "solver.update_time_limit: must be in [0, 3600] s (0: no limit), "
                f"got {self.update_time_limit}"
            )
        if not (1 <= self.recheck_every <= 100000):
            raise ValueError(
                f"solver.recheck_every: must be in [1, 100000], got {self.recheck_every}"
            )
        if not (0 <= self.self_contact_pairs <= 400):
            raise ValueError(
                f"solver.self_contact_pairs: must be in [0, 400], got {self.self_contact_pairs}"
            )
        if self.self_contact_samples != 0 and not (3 <= self.self_contact_samples <= 4000):
            raise ValueError(
                "solver.self_contact_samples: must be 0 (auto) or in [3, 4000], "
                f"got {self.self_contact_samples}"
            )
        if self.self_contact_pairs and (self.model == "planar" or self.rotation != "director"):
            raise ValueError(
                "solver.self_contact_pairs: self-contact needs the 3D director model "
                "(solver.model 'full' or 'auto', solver.rotation 'director')"
            )
        if not (0 < self.max_strain < 10):
            raise ValueError("solver.max_strain: must be in (0, 10)")

    def _validate_frame_and_plane(self) -> None:
        """Refuse an unknown ``frame`` or ``plane``, and plane 'keep' with model 'full'."""
        if self.frame not in FRAMES:
            raise ValueError(f"solver.frame: must be one of {FRAMES}, got {self.frame!r}")
        if self.plane not in PLANES:
            raise ValueError(f"solver.plane: must be one of {PLANES}, got {self.plane!r}")
        if self.plane == "keep" and self.model == "full":
            raise ValueError(
                "solver.plane: 'keep' holds the string in the scene's plane, which model 'full' "
                "does not: use model 'auto' or 'planar'"
            )

    def _validate_obstacle_points(self) -> None:
        """Refuse unknown ``obstacle_points``/``slotted_obstacles``, 'nodes' without elements."""
        if self.slotted_obstacles not in SLOTTED_OBSTACLES:
            raise ValueError(
                f"solver.slotted_obstacles: must be one of {SLOTTED_OBSTACLES}, "
                f"got {self.slotted_obstacles!r}"
            )
        if self.obstacle_points not in OBSTACLE_POINTS:
            raise ValueError(
                f"solver.obstacle_points: must be one of {OBSTACLE_POINTS}, "
                f"got {self.obstacle_points!r}"
            )
        elements = self.rotation == "director" if self.model == "full" else False
        elements = elements or (self.model in ("planar", "full") and self.basis == "elements")
        if self.obstacle_points == "nodes" and self.model != "auto" and not elements:
            raise ValueError(
                "solver.obstacle_points: 'nodes' puts the obstacle rows on the element mesh's "
                "nodes, which only the element models have (solver.model 'full' with "
                "solver.rotation 'director', or solver.basis 'elements'); got model "
                f"{self.model!r}, rotation {self.rotation!r}, basis {self.basis!r}"
            )

    def with_model(self, model: str, **changes) -> "SolverOptions":
        """Return these options for the fixed ``model`` ('planar' or 'full') built from them.

        These options for the fixed ``model`` ('planar' or 'full') that auto or a fit builds
        from them: a 3D director model takes the default basis and frame, which it does not have
        (the scene's may be meant for the planar model).
        """
        if model == "full" and self.rotation == "director":
            changes = {"basis": SolverOptions.basis, "frame": SolverOptions.frame, **changes}
        return replace(self, model=model, **changes)

    def _ignored_by_director(self) -> list[str]:
        """Return the Euler-angle options set where the 3D director model ignores them.

        The Euler-angle options set away from their defaults where the 3D director model is
        built (model 'full', rotation 'director'): it has nodal elements and no singular frame, and
        would ignore them.
        """
        if self.model != "full" or self.rotation != "director":
            return []
        return [
            name
            for name in ("basis", "frame")
            if getattr(self, name) != getattr(SolverOptions, name)
            # the director model is built on spectral elements: 'elements' describes it
            and not (name == "basis" and self.basis == "elements")
        ]

    @classmethod
    def from_dict(cls, d: dict) -> "SolverOptions":
        known = {f.name: f.type for f in fields(cls)}
        unknown = set(d) - set(known)
        if unknown:
            raise ValueError(
                f"solver.{sorted(unknown)[0]}: unknown option (known: {sorted(known)})"
            )
        # One value per field, each converted to that field's type (str, int or float).
        kwargs: dict[str, Any] = {}
        for key, value in d.items():
            default = getattr(cls, key)
            try:
                if isinstance(default, bool) or isinstance(default, str):
                    kwargs[key] = str(value)
                elif isinstance(default, int):
                    if isinstance(value, float) and not value.is_integer():
                        raise ValueError
                    kwargs[key] = int(value)
                else:
                    kwargs[key] = float(value)
            except (TypeError, ValueError):
                raise ValueError(
                    f"solver.{key}: expected a {type(default).__name__}, got {value!r}"
                ) from None
        opts = cls(**kwargs)
        opts.validate()
        return opts
