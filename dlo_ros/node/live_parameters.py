"""The node's run-time parameter changes: checked before they are set, then applied to the solver.

``ros2 param set`` (and the fitter's estimates) go through two callbacks:
:meth:`LiveParameters.check` refuses a value with the reason (read-only, out of range, or a string
the model cannot take), and :meth:`LiveParameters.apply` hands the accepted change to the solver
thread (new string properties re-solve; a new ``output_points`` rebuilds the solver) and records
it.
"""

from __future__ import annotations

from concurrent.futures import Future
from dataclasses import replace
from typing import Callable, Sequence

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..model.problem import Problem, StringProperties
from ..solver.options import SolverOptions
from . import params as P
from .engine import ShapeEngine, options_with_output_points
from .health import Health
from .shape_outputs import ShapeOutputs
from .stream_log import StreamLog
from .validation import safe_text


class LiveParameters:
    """Check and apply changes of the node's live parameters (executor thread).

    ``problem``: the problem the checks run against, with the string properties as the
    parameters hold them now (the solver thread may not have applied the newest change yet).
    """

    def __init__(
        self,
        node: Node,
        problem: Problem,
        engine: ShapeEngine,
        log: StreamLog,
        health: Health,
        outputs: ShapeOutputs,
        closing: Callable[[], bool],
    ) -> None:
        self.node = node
        self.problem = problem
        self.engine = engine
        self.log = log
        self.health = health
        self.outputs = outputs
        self.closing = closing
        node.add_on_set_parameters_callback(self.check)
        node.add_post_set_parameters_callback(self.apply)

    def close(self) -> None:
        """Stop checking and applying parameter changes (a managed node's cleanup)."""
        self.node.remove_on_set_parameters_callback(self.check)
        self.node.remove_post_set_parameters_callback(self.apply)

    @property
    def string(self) -> StringProperties:
        """Return the string's properties as the parameters hold them now."""
        return self.problem.string

    def check(self, parameters: Sequence[Parameter]) -> SetParametersResult:
        """Accept or refuse a set of parameter values together (changes nothing)."""
        strings = {}
        for p in parameters:
            reason = P.check_live(p.name, p.value, self.problem)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
            if p.name in P.STRING_FIELDS:
                strings[p.name] = p.value
        if strings:  # the combination must be valid too
            try:
                replace(
                    self.problem, string=P.apply_string(self.problem.string, strings)
                ).validate()
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def apply(self, parameters: Sequence[Parameter]) -> None:
        """Hand the accepted changes to the solver thread, the health and the markers."""
        names = {p.name for p in parameters}
        if names & set(P.STRING_FIELDS):
            self._apply_string(names)
        if "output_points" in names:
            self._apply_output_points()
        if "warn_throttle" in names:
            self.health.throttle_s = self.node.get_parameter("warn_throttle").value
        if names & {"markers.force_scale", "markers.energy_scale"}:
            self.outputs.redraw()

    def _apply_string(self, names: set[str]) -> None:
        value = self.node.get_parameter
        values = {n: value(n).value for n in P.STRING_FIELDS}
        self.problem = replace(self.problem, string=P.apply_string(self.problem.string, values))
        text = "string properties changed: " + ", ".join(
            f"{n}={value(n).value:g}" for n in sorted(names & set(P.STRING_FIELDS))
        )

        def edit(problem: Problem) -> Problem:  # solver thread, before the re-solve it triggers
            new = replace(problem, string=P.apply_string(problem.string, values))
            self.log.model_change(text, problem=new)
            return new

        self.engine.change_problem(edit).add_done_callback(self._job_done("string properties"))
        self.node.get_logger().info(text)

    def _apply_output_points(self) -> None:
        n = self.node.get_parameter("output_points").value

        def edit(options: SolverOptions) -> SolverOptions:  # solver thread, before the rebuild
            new = options_with_output_points(options, n)
            if new != options:
                self.log.model_change(f"output_points={n}: solver rebuilt", options=new)
            return new

        self.engine.change_options(edit).add_done_callback(self._job_done("output_points"))
        self.node.get_logger().info(
            f"output_points={n}: rebuilding the solver (the next solve is cold)"
        )

    def _job_done(self, what: str) -> Callable[[Future], None]:
        """Return a done-callback that logs a change the solver thread could not apply."""

        def done(future: Future) -> None:
            if future.cancelled() or self.closing():
                return
            exc = future.exception()
            if exc is not None:
                self.node.get_logger().error(
                    f"applying {what} failed: {type(exc).__name__}: {safe_text(exc)}"
                )

        return done
