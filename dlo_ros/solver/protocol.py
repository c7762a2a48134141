"""The ``Solver`` protocol: what the node, the CLI, replay and the recording use of a shape solver.

Both ``ShapeSolver`` (one fixed model) and ``AutoShapeSolver`` (``solver.model: auto``) implement
it; ``make_solver`` returns either.  Callers outside ``dlo_ros/solver`` use nothing else of a
solver.

* ``solve(poses, warm=, commit=, check_now=)``: the equilibrium with the given grip poses (GripPose
  or (position [m], quaternion (x, y, z, w)) per grip name; missing grips keep their target),
  warm-started from the last committed one unless ``warm`` is False; ``commit=False`` answers a
  query without changing the solver; ``check_now`` runs every a-posteriori check before the answer
  returns (auto's background checks included).  Never raises for bad input: the ShapeResult's
  status says so.
* ``query_many(targets, executor=None)``: one answer per ``{grip: pose}`` mapping, in order, solved
  in worker processes (dlo_ros.solver.parallel.batch); the solver itself is untouched.
* ``set_problem(problem)``: new scene values (raises ValueError naming the field); ``reset()``: the
  next solve is cold; ``close()``: stop helper threads (later solves still work).
* ``problem`` (the committed scene), ``options``, ``has_warm_start``, ``kkt_compiled`` (derivatives
  run compiled C) and ``model_summary()`` (the model of the next answer).

``SolverFactory`` is what builds one (``make_solver``, or a solver class): the worker processes of
``dlo_ros.solver.parallel.batch`` are handed one.  ``structure_key`` says when two scenes can share
one solver: with equal keys, ``set_problem`` keeps the solver's NLP.
"""

from __future__ import annotations

from concurrent.futures import Executor
from typing import Callable, Mapping, Protocol, Sequence, runtime_checkable

from ..model.problem import GripPose, Problem
from .options import SolverOptions
from .results.result import ShapeResult
from .results.summary import ModelSummary


@runtime_checkable
class Solver(Protocol):
    """A warm-started static-shape solver of one scene (see the module docstring)."""

    problem: Problem
    options: SolverOptions

    def solve(
        self,
        poses: Mapping[str, GripPose | tuple] | None = None,
        *,
        warm: bool = True,
        commit: bool = True,
        check_now: bool = False,
    ) -> ShapeResult: ...

    def query_many(
        self, targets: Sequence[Mapping[str, GripPose | tuple]], executor: Executor | None = None
    ) -> list[ShapeResult]: ...

    def set_problem(self, problem: Problem) -> None: ...

    def reset(self) -> None: ...

    def close(self) -> None: ...

    @property
    def has_warm_start(self) -> bool: ...

    @property
    def kkt_compiled(self) -> bool: ...

    def model_summary(self) -> ModelSummary: ...


#: What builds a solver of a scene: ``make_solver``, ``AutoShapeSolver`` or ``ShapeSolver``, called
#: as ``factory(problem, options, compile=...)``, plus ``checks=`` when its signature has that
#: parameter (auto's a-posteriori checks; a fixed model has none).  Worker processes receive it
#: pickled, so it must be a module-level function or class (pickled by reference).
SolverFactory = Callable[..., Solver]
