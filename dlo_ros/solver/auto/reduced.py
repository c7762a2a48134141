"""A scene as a :class:`~.choice.ModelChoice` models it: the reduced problem and its options."""

from __future__ import annotations

from dataclasses import replace

from ...model.problem import Problem
from ...model.profile import Profile
from ..options import SolverOptions
from .choice import AUTO_OBSTACLE_SLOTS, AUTO_SELF_CONTACT_PAIRS, ModelChoice


class ReducedModels:
    """The reduced problem and options of each choice, cached so that a stream reuses them.

    The reduced string and obstacle tuple are reused while the scene's are the same objects, so
    that a stream of new grip poses keeps the inner solver's cached parameters.  The options are
    made once per model (a frozen dataclass's replace costs more than the lookup).
    """

    def __init__(self, options: SolverOptions) -> None:
        """Reduce with the scene's solver ``options`` (``model: auto``) as the base."""
        self.options = options
        self._string_cache: tuple | None = None
        self._options: dict[tuple, SolverOptions] = {}

    def reduce(self, choice: ModelChoice, problem: Problem) -> tuple[Problem, SolverOptions]:
        """Return ``problem`` as ``choice`` models it, and the options of that model.

        Gravity is zeroed when dropped, the stretch stiffness removed when inextensible, and only
        ``choice.obstacles`` are kept; the options name the planar model (basis 'elements' unless
        the scene set another than the default) or the full model with the choice's order,
        quadrature (≥ 2·order + 8), obstacle rows (:meth:`obstacle_points`), obstacle samples,
        obstacle contact slots (AUTO_OBSTACLE_SLOTS on element models) and self-contact slots.
        """
        key = (choice.gravity, choice.stretch, choice.obstacles)
        hit = self._string_cache
        if (
            hit is not None
            and hit[0] == key
            and hit[1] is problem.string
            and hit[2] is problem.obstacles
        ):
            st, obstacles = hit[3], hit[4]
        else:
            st = problem.string
            if not choice.gravity:
                st = replace(st, weight_per_length=Profile.constant(0.0))
            if not choice.stretch:
                st = replace(st, stretch_stiffness=None)
            obstacles = tuple(problem.obstacles[i] for i in choice.obstacles)
            self._string_cache = (key, problem.string, problem.obstacles, st, obstacles)
        reduced = replace(problem, string=st, obstacles=obstacles)
        model = (choice.planar, choice.order, choice.samples, choice.self_contact)
        opts = self._options.get(model)
        if opts is None:
            # the planar model on spectral elements split at grips, loads and material knots (a
            # kink there converges spectrally, not algebraically as in one polynomial), unless the
            # scene chose another basis than the default
            default = self.options.basis == SolverOptions.basis
            planar = {"basis": "elements"} if choice.planar and default else {}
            points = self.obstacle_points(choice)
            # an element model's point contact in a slot where the shape touches: at the
            # node nearest it, it carries an error the mesh could only chase (#37)
            slots = self.options.obstacle_slots or (
                AUTO_OBSTACLE_SLOTS if points == "nodes" else 0
            )
            opts = self.options.with_model(
                "planar" if choice.planar else "full",
                **planar,
                obstacle_points=points,
                obstacle_slots=slots,
                # auto's own slots on half-spaces and spheres (a scene's obstacle_slots keep its
                # slotted_obstacles): on the main job's post they held the shape to 1e-6 m cold
                # in 2 s (rows: 1e-5 m in 19 s), and a contact sliding inside an element is
                # bounded by a mesh with a breakpoint moved onto it (mesh_check.moved_verdict);
                # not on a bar: a cable draped over one (a line contact) cycled its slot rounds at
                # every held update (2.8 s each, rows 6-15 ms)
                slotted_obstacles="points"
                if points == "nodes" and not self.options.obstacle_slots
                else self.options.slotted_obstacles,
                order=choice.order,
                quadrature_nodes=max(self.options.quadrature_nodes, 2 * choice.order + 8),
                obstacle_samples=choice.samples,
                self_contact_pairs=(self.options.self_contact_pairs or AUTO_SELF_CONTACT_PAIRS)
                if choice.self_contact
                else 0,
            )
            self._options = {**self._options, model: opts}
        return reduced, opts

    def obstacle_points(self, choice: ModelChoice) -> str:
        """Return where the obstacle rows of ``choice``'s model sit: 'nodes' on element models.

        An element model (the director model; the planar one of basis 'elements') enforces its
        obstacles at its mesh nodes and refines the mesh where contact needs it
        (``mesh_check.py``); the others keep the scene's ``obstacle_samples`` uniform samples.
        """
        if choice.planar:
            elements = self.options.basis in (SolverOptions.basis, "elements")
        else:
            elements = self.options.rotation == "director"
        return "nodes" if elements else "samples"

    def poses(self, choice: ModelChoice, problem: Problem) -> dict:
        """Return the grip poses the reduced model of ``choice`` takes (by grip name)."""
        return {g.name: g.pose for g in self.reduce(choice, problem)[0].grips}
