"""The pool of built models auto switches among, checks with and answers queries on.

Building a ShapeSolver costs up to seconds, so auto keeps the models it built, keyed by
``(tag,) + ModelChoice.key()`` (tag '' for a model a stream may switch to or a check measures
with, the 3D model of a planar stream included; 'query' for a refined query's copy), newest last,
at most :attr:`ModelPool.SIZE`.  The least recently used idle one is dropped first; the streaming
model, the running job's models (:class:`.background.CheckWorker`), the 3D model a planar stream
switches to and the two newest are never dropped.
"""

from __future__ import annotations

import threading

from ...model.mesh_geometry import MeshTopology
from ...model.problem import Problem
from ..build.mesh import element_mesh
from ..shape_solver import ShapeSolver
from ..update.ipopt import IPOPT_LOCK
from .background import CheckWorker
from .choice import ModelChoice
from .reduced import ReducedModels


class ModelPool:
    """Built ShapeSolvers by pool key, and the streaming one (:attr:`streaming`)."""

    #: models kept built
    SIZE = 6

    def __init__(self, reduced: ReducedModels, compile: str, worker: CheckWorker) -> None:
        """Build models of ``reduced``'s options; a stream compiles as ``compile`` says."""
        self.reduced = reduced
        self.compile = compile
        self.worker = worker
        #: the model the stream solves on (None until the first is built)
        self.streaming: ShapeSolver | None = None
        #: pool key of the 3D model a planar stream switches to (kept built; () when none)
        self.full_key: tuple = ()
        #: a checked solve escalates (``stream_checks.check_now``): the models it streams on
        #: meanwhile only load cached libraries; the one it answers with compiles at its end (a
        #: background compile per pass held the paper's Fig. 3 back by a sixth)
        self.hold_compiles = False
        self._models: dict[tuple, ShapeSolver] = {}
        self._lock = threading.Lock()  # guards the dict only (builds run outside it)

    def __len__(self) -> int:
        """Return how many models are built."""
        return len(self._models)

    def solvers(self) -> list[ShapeSolver]:
        """Return a copy of the pooled models' solvers, oldest first."""
        with self._lock:
            return list(self._models.values())

    def pooled(self, choice: ModelChoice, tag: str = "") -> ShapeSolver | None:
        """Return the pooled model of ``choice`` (with ``tag``), or None when it is not built."""
        with self._lock:
            return self._models.get((tag,) + choice.key())

    def solver_for(
        self,
        choice: ModelChoice,
        problem: Problem,
        *,
        stream: bool,
        source: ShapeSolver | None = None,
        state=None,
        tag: str = "",
        built: ShapeSolver | None = None,
        once: bool = False,
    ) -> ShapeSolver:
        """Return the pooled ShapeSolver of ``choice`` set to ``problem`` (built if new).

        It is warm-started from ``source`` (its ``state`` snapshot if given) and reset when that
        maps nothing.  Helpers (order shadow, 3D checker) never start a compile and create IPOPT
        lazily; a solver that streams compiles as ``compile`` says.  ``tag`` keeps a separate copy
        (a refined query's).  Sets ``choice.twist``
        from the model built.  ``built``: a solver of ``choice`` holding its own warm start (a
        mesh's lead-in, ``lead_in.py``), pooled under that key instead of the one there (give
        no ``source``).  ``once``: a model built here is expected to be solved once (a check's
        shadow, the model a verdict names): its outputs' function is built only if it is solved
        again or compiled (``ShapeSolver``'s ``lazy_outputs``).
        """
        reduced, opts = self.reduced.reduce(choice, problem)
        key = (tag,) + choice.key()
        with self._lock:
            solver = self._models.pop(key, None)
        if built is not None:
            solver = built
        helper = "off" if self.compile == "off" else "cached"
        # a model of a checked solve's escalations compiles once that solve has its answer
        holding = stream and self.hold_compiles
        mode = self.compile if stream and not holding else helper
        # one expected to be solved once, or streamed during those escalations, looks into the
        # cache only as a clone (build/mesh_clone.py), whose functions' keys are known: a new
        # model's libraries, keyed by its own mesh, are almost never there, and their keys cost
        # two evaluations of each function (the paper's Fig. 3: a seventh of its cold solve)
        quiet = (once or holding) and mode == "cached"
        if solver is None:
            solver = ShapeSolver(
                reduced,
                opts,
                compile="off" if quiet else mode,
                lazy_ipopt=not stream,
                reference_frame=choice.reference_frame(),
                mesh=choice.mesh,
                template=self._template(opts, reduced, choice.mesh),
                lazy_outputs=once and not stream,
            )
            if quiet and not getattr(solver.nlp, "own_symbols", True):
                solver.start_compile("cached")
        else:
            solver.set_problem(reduced)
        self._insert(key, solver)
        if stream and not quiet:
            solver.start_compile(mode)
        choice.twist = solver.model.layout.twist
        if source is not None and not solver.adopt_warm_start(source, state):
            solver.reset()  # nothing to map: never keep an older, unrelated warm start
        return solver

    def _template(self, options, problem: Problem, mesh) -> ShapeSolver | None:
        """Return the newest pooled model whose functions serve ``mesh`` too, or None.

        Built with ``options`` on a mesh of ``mesh``'s topology; ``ShapeSolver`` clones it where
        the structure matches too (``build/mesh_clone.py``) and builds anew otherwise.
        """
        if mesh is None or options.model == "planar" or options.rotation != "director":
            return None
        topology = MeshTopology.of(element_mesh(problem, options, mesh))
        with self._lock:
            built = [s for s in self._models.values() if s.options == options]
        for solver in reversed(built):
            if MeshTopology.of(solver.nlp.model.mesh) == topology:
                return solver
        return None

    def _insert(self, key: tuple, solver: ShapeSolver) -> None:
        """Pool ``solver`` as the newest under ``key``; drop the least recently used idle ones."""
        evicted = []
        with self._lock:
            self._models[key] = solver
            keep = set(self.worker.keys) | {key, self.full_key} | set(list(self._models)[-2:])
            while len(self._models) > self.SIZE:
                old = next(
                    (
                        k
                        for k, s in self._models.items()
                        if s is not self.streaming and k not in keep
                    ),
                    None,
                )
                if old is None:
                    break
                evicted.append(self._models.pop(old))
        with (
            IPOPT_LOCK
        ):  # freeing IPOPT/MUMPS instances must not overlap a solve in another thread
            evicted.clear()

    def compile_ahead(self, solver: ShapeSolver, switch: bool = False) -> None:
        """Compile in the background a model that a switch, the queries or a check will use.

        It starts once the streaming model's own compile is done (the stream reaches full speed
        first), and only if the stream compiles at all ('on_query': at the model's first query).
        Its libraries land in the cache, where the query workers find them.  ``switch``: a held
        verdict's model, which the stream switches to: compiled even if it was built not to look
        into the cache (``solver_for``'s ``once``), so that the switch neither builds the compile's
        functions nor looks up its libraries on the stream's thread.
        """
        if switch and solver.compile_mode == "off" and self.compile in ("background", "blocking"):
            solver.compile_mode = "cached"
        if self.compile == "on_query" and solver.compile_mode == "cached":
            # a query worker's: compiled once a query uses it, not a one-off refinement's copy
            solver.compile_mode = "on_query"
            return
        if (
            self.compile not in ("background", "blocking")
            or solver.all_compiled
            or solver.compile_pending
        ):
            return
        streaming = self.streaming

        def start() -> None:
            if streaming is not None:
                streaming.wait_for_compile()
            if solver.compile_mode == "cached":  # not streaming meanwhile (a stream compiles)
                solver.start_compile("background")
            solver.compile_pending = False

        solver.compile_pending = True
        threading.Thread(target=start, name="dlo-compile-ahead", daemon=True).start()
