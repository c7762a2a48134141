"""The node's services: ``~/query_shape`` (a what-if solve) and ``~/reset`` (a cold restart).

Both are coroutines that await the solver without blocking the executor: the executor keeps
serving targets, timers and parameters meanwhile.  A query never touches the stream.  With
``query_workers`` > 0 it is answered by worker processes, each holding the scene's solver at the
current targets; else by the solver thread between stream updates.  The reply's status is in
``plan.header.frame_id`` (query_reply.py, msg_docs/node.md).
"""

from __future__ import annotations

from concurrent.futures import Future
from typing import Any, Callable

from nav_msgs.msg import Path
from nav_msgs.srv import GetPlan
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.task import Future as RclpyFuture
from std_srvs.srv import Trigger

from ..model.problem import GripPose, Problem
from ..solver.auto import make_solver
from ..solver.parallel.batch import scene_payload, solve_chunk
from ..solver.parallel.worker_pool import WorkerPool, stop_pool
from . import conversions as conv
from . import query_reply
from .engine import ShapeEngine, target_miss
from .health import Health
from .target_inputs import PoseReader
from .validation import TargetError, safe_text

#: ~/query_shape calls pending per query worker before new ones are refused ("busy")
QUERIES_PER_WORKER = 2


async def await_job(node: Node, job: Future) -> Any:
    """Await a ShapeEngine job from a service coroutine; return its result (or raise its error).

    The executor keeps spinning meanwhile (targets, timers, parameters): the coroutine is resumed
    when the solver thread completes the job, which wakes the executor through an rclpy Future.
    """
    done = RclpyFuture(executor=node.executor)
    done.add_done_callback(
        lambda _f: None
    )  # completing it schedules a task: that wakes the executor
    job.add_done_callback(lambda _job: done.set_result(None))
    await done
    return job.result(timeout=0)


class ShapeServices:
    """Serve ``~/query_shape`` and ``~/reset``; own the query workers (if any).

    ``worker_compile``: the compile mode of the query workers (they never start gcc).
    """

    def __init__(
        self,
        node: Node,
        poses: PoseReader,
        grip_names: list[str],
        engine: ShapeEngine,
        health: Health,
        worker_compile: str,
        refusal: Callable[[], str] = lambda: "",
    ) -> None:
        self.node = node
        self.refusal = refusal  # why services are refused now ('' = served): a lifecycle state
        self.poses = poses
        self.frame_id = poses.frame_id
        self.grip_names = grip_names
        self.engine = engine
        self.health = health
        self.worker_compile = worker_compile
        self.workers = int(node.get_parameter("query_workers").value)
        self.pending = 0
        self.query_pool: WorkerPool | None = None
        # The services get their own callback group: a pending coroutine keeps its group busy,
        # and the default (mutually exclusive) group must stay free for the subscriptions, timers
        # and parameter services meanwhile.  Queries answered by worker processes may be pending
        # side by side (up to QUERIES_PER_WORKER each).
        services = MutuallyExclusiveCallbackGroup()
        queries = ReentrantCallbackGroup() if self.workers else services
        self._query_srv = node.create_service(
            GetPlan, "~/query_shape", self.on_query, callback_group=queries
        )
        self._reset_srv = node.create_service(
            Trigger, "~/reset", self.on_reset, callback_group=services
        )

    def start_workers(self) -> None:
        """Start the query worker processes (replaced when one dies or is stuck)."""
        if self.workers:
            self.query_pool = WorkerPool(self.workers, background=True)

    def warm_workers(self) -> None:
        """Have each query worker build its solver and the held shape now.

        Called after the node's own first shape, so that they do not compete with its start-up.
        """
        if self.query_pool is None:
            return
        for _ in range(self.workers):
            self.to_query_worker([])

    def close(self, timeout: float) -> None:
        """Stop the query workers (bounded by ``timeout`` [s])."""
        if self.query_pool is not None:
            stop_pool(self.query_pool, timeout)

    async def on_query(
        self, request: GetPlan.Request, response: GetPlan.Response
    ) -> GetPlan.Response:
        """Answer ~/query_shape: the verified shape for the start/goal grip poses, or why not."""
        now = self.node.get_clock().now().nanoseconds
        response.plan = Path(header=conv.header(self.frame_id, now))
        try:
            poses = {}
            for name, ps, label in zip(
                self.grip_names, (request.start, request.goal), ("start", "goal")
            ):
                poses[name] = self.poses.checked(
                    ps.pose, ps.header.frame_id, f"query_shape.{label} ({name})"
                )
        except TargetError as exc:
            return self.failed(response, f"{exc}", "invalid")
        if self.refusal():
            return self.failed(response, self.refusal(), "inactive")
        if not self.engine.ready:
            return self.failed(
                response, f"the solver is not ready ({self.engine.state})", "not_ready"
            )
        if self.pending >= QUERIES_PER_WORKER * max(self.workers, 1):
            return self.failed(
                response, f"busy: {self.pending} queries are being answered; try again", "busy"
            )  # bounded: a flood never builds a queue
        self.pending += 1
        try:
            result = await await_job(self.node, self.query_job(poses))
        except Exception as exc:  # noqa: BLE001 - cancelled at shutdown, or a solver exception
            return self.failed(response, f"{type(exc).__name__}: {exc}", "failed")
        finally:
            self.pending -= 1
        kind = query_reply.result_kind(result)
        if kind == "unstable":
            return self.failed(
                response,
                f"the equilibrium found is unstable (min eigenvalue {result.min_eigenvalue:.3g})",
                kind,
            )
        if kind != query_reply.VERIFIED:
            if query_reply.carries_shape(kind):  # the shape, marked as not verified
                response.plan = conv.result_to_path(
                    result, query_reply.reply_frame(self.frame_id, kind), now
                )
            return self.failed(response, f"{kind} ({result.status}): {result.message}", kind)
        response.plan = conv.result_to_path(result, self.frame_id, now)
        self.health.query(True)
        return response

    def query_job(self, poses: dict[str, GripPose]) -> Future:
        """Return the query's ShapeResult as a Future.

        From a worker process when there are query workers (the scene is the solver's at the
        current targets), else from the solver thread.
        """
        if self.query_pool is None:
            return self.engine.query(poses)
        problem, job = self.to_query_worker([poses])
        answer: Future = Future()

        def done(f: Future) -> None:
            try:
                result = f.result()[0]
            except BaseException as exc:  # noqa: BLE001 - handed to the service coroutine
                answer.set_exception(exc)
                return
            miss = target_miss(
                result, problem, {**{g.name: g.pose for g in problem.grips}, **poses}
            )
            if miss:
                result.status, result.message = "failed", miss
            answer.set_result(result)

        job.add_done_callback(done)
        return answer

    def to_query_worker(self, queries: list[dict[str, GripPose]]) -> tuple[Problem, Future]:
        """Submit ``queries`` to the query workers in the engine's current scene.

        Returns that scene's problem and the Future of the queries' ShapeResults.
        """
        scene, pool = self.engine.query_scene(), self.query_pool
        if scene is None or pool is None:  # callers check engine.ready and the pool first
            raise RuntimeError(f"no query workers or no solver ({self.engine.state})")
        problem, options = scene
        # checks beside the queries: the workers' held shape follows the stream, and auto's check
        # due on one of its updates, run in front of a query, made that query wait 0.2–0.6 s
        # (CHANGELOG).  The warm-up (no queries) builds the solver: not limited.  A query is a
        # pure function of its scene and targets: one whose worker died under it (or just
        # before) runs once more.
        timeout = (
            (float(self.node.get_parameter("query_timeout").value) or None) if queries else None
        )
        return problem, pool.submit(
            solve_chunk,
            scene_payload(make_solver, problem, options),
            queries,
            self.worker_compile,
            "background",
            timeout=timeout,
            retries=1,
        )

    def failed(self, response: GetPlan.Response, reason: str, kind: str) -> GetPlan.Response:
        """Complete a reply that is not a verified shape.

        ``plan.header.frame_id`` gets the ``#<kind>`` suffix (query_reply.py); its poses, if any,
        are already in ``response.plan``.
        """
        response.plan.header.frame_id = query_reply.reply_frame(self.frame_id, kind)
        reason = safe_text(reason)
        self.health.query(False, reason)
        # throttled per call site by rclpy (a client can call the service in a loop); counted in
        # the diagnostics
        what = "unverified plan" if response.plan.poses else "empty plan"
        self.node.get_logger().warning(
            f"query_shape: {what}: {reason}",
            throttle_duration_sec=max(float(self.health.throttle_s), 1e-9),
        )
        return response

    async def on_reset(
        self, request: Trigger.Request, response: Trigger.Response
    ) -> Trigger.Response:
        """Answer ~/reset: forget the warm start and solve cold; report that solve."""
        if self.refusal():
            response.success, response.message = False, self.refusal()
            return response
        if not self.engine.ready:
            response.success = False
            response.message = f"the solver is not ready ({self.engine.state})"
            return response
        try:
            result = await await_job(self.node, self.engine.reset())
        except Exception as exc:  # noqa: BLE001 - reported in the reply
            response.success, response.message = False, f"{type(exc).__name__}: {exc}"
            return response
        if result is None:
            response.success = False
            response.message = "warm start cleared; the cold solve raised (see the log)"
        else:
            response.success = result.ok
            response.message = (
                f"warm start cleared; cold solve: {result.status}: {result.message}"
                + ("" if result.ok else " (the last good shape stays published)")
            )
        self.node.get_logger().info(f"reset: {safe_text(response.message)}")
        return response
