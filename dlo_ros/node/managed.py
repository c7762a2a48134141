"""The managed (lifecycle) dlo node: the same interfaces, built and released by transitions.

``dlo node --managed`` (or the parameter ``managed: true``) starts :class:`ManagedDloNode` under
the plain node's name, with rclpy's standard lifecycle services (``~/get_state``,
``~/change_state``, ``~/get_available_states``, ``~/get_available_transitions``,
``~/get_transition_graph``) and ``~/transition_event``.  It declares nothing but rclpy's
lifecycle interfaces until configured.

=================  =========================================================================
transition         what it does (bound)
=================  =========================================================================
configure          declare the parameters, load the scene, build the solver (compiled code
                   as ``compile`` says) and solve the first shape, which is held, not
                   published; fails naming the reason on a bad scene or parameter, or when no
                   first shape came within ``configure_timeout`` (everything built is released)
activate           targets and queries are accepted; the held shape is published at once
deactivate         targets and queries are refused with the reason; the latched centreline
                   stays (immediate)
cleanup            the target thread (and its small node, ``hot_path``), the engine, query and
                   fit workers and the recording are stopped, every interface the node made is
                   destroyed, memory is returned to the system (bounded by ``STOP_TIMEOUT_S``
                   for the solve in progress, plus the workers')
shutdown           as cleanup, from any state; ``run`` then leaves with exit code 0
=================  =========================================================================

The target subscriptions live on the core's hidden small node with its own executor and thread
(``hot_path``), made on ``configure`` and destroyed with the core; while inactive their callbacks
refuse every target.  A transition callback runs on the main executor's thread; ``configure``
blocks it until the first shape (the lifecycle service answers then), the solver's own thread
keeps working meanwhile.
"""

from __future__ import annotations

import ctypes
import gc
import threading
import time
from typing import Any, Callable

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from .dlo_node import NODE_NAME, DloCore, StartupError
from .validation import safe_text

RCLError = _rclpy.RCLError
STOP_TIMEOUT_S = 5.0  # how long cleanup / shutdown wait for the solve in progress [s]
#: the entities a core makes, and how each is destroyed (a guard condition left behind would keep
#: its callback's object, and with it the old core and solver, alive)
KINDS = {
    "publishers": "destroy_publisher",
    "subscriptions": "destroy_subscription",
    "services": "destroy_service",
    "clients": "destroy_client",
    "timers": "destroy_timer",
    "guards": "destroy_guard_condition",
}


class ManagedDloNode(LifecycleNode):
    """The dlo node as a lifecycle node (module docstring); ``core`` exists while configured.

    Keyword arguments go to rclpy's LifecycleNode (context, namespace, parameter_overrides, ...).
    ``finished`` is set once the node reached 'finalized' (``run`` then stops spinning).
    """

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.core: DloCore | None = None
        self.finished = threading.Event()
        self.configured = 0  # successful configure transitions (each records to its own file)
        self._stuck: DloCore | None = None  # a core whose solver thread outlived its release
        self._own = self._entities()  # rclpy's lifecycle interfaces: never destroyed by cleanup
        # rclpy 7.1 raises out of the change_state service for a transition the current state
        # does not have (ros2/rclpy#1209), which ends spin(): answer it with success = False
        service = self._service_change_state
        service.callback = refusing_unknown_transitions(service.callback, self.get_logger())
        name = self.get_fully_qualified_name()
        self.get_logger().info(
            f"managed node {name}: unconfigured; configure and activate it (e.g. ros2 lifecycle "
            f"set {name} configure)"
        )

    # ---- transitions (executor thread) ----------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Build the core inactive and wait for its first shape (module docstring)."""
        log = self.get_logger()
        if self._stuck is not None and self._stuck.engine.alive:
            log.error(
                "configure failed: the previous solver thread is still running (a long solve or "
                "a compile); try again when it has ended"
            )
            return TransitionCallbackReturn.FAILURE
        log.info("configure: reading the scene and parameters, building the solver")
        try:
            self.core = DloCore(self, active=False, recording=self.configured + 1)
            self.core.health.set_lifecycle("configuring")
        except StartupError as exc:
            log.error(f"configure failed: {safe_text(exc, 1000)}")
            self._release()
            return TransitionCallbackReturn.FAILURE
        except Exception as exc:  # noqa: BLE001 - a bug: reported, the node stays unconfigured
            log.error(f"configure failed: {type(exc).__name__}: {safe_text(exc, 1000)}")
            self._release()
            return TransitionCallbackReturn.FAILURE
        reason = self._wait_for_first_shape(float(self.get_parameter("configure_timeout").value))
        if reason:
            log.error(f"configure failed: {reason}")
            self._release()
            return TransitionCallbackReturn.FAILURE
        self.core.health.set_lifecycle("inactive")
        self.configured += 1
        log.info("configured: the first shape is held; activate to stream")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Accept targets and publish shapes, starting with the held one."""
        if self.core is None:  # pragma: no cover - rclpy activates only a configured node
            return TransitionCallbackReturn.FAILURE
        self.core.activate()
        self.get_logger().info("activated: streaming shapes")
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Refuse targets and queries; the latched centreline stays."""
        if self.core is not None:
            self.core.deactivate()
        self.get_logger().info("deactivated: targets are refused; the last shape stays latched")
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release the solver, the workers and every interface the node made."""
        if self._release():
            self.get_logger().info("cleaned up: solver and workers released")
        else:
            self.get_logger().warning(
                f"cleaned up, but the solver thread is still busy after {STOP_TIMEOUT_S:g} s (a "
                "long solve or a compile): it is released when it ends; configure waits for it"
            )
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release everything (from any state); the process then ends."""
        self._release()
        self.finished.set()
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release everything after an error in a transition: back to 'unconfigured'."""
        self.get_logger().error(f"lifecycle error in state '{state.label}': releasing the solver")
        self._release()
        return TransitionCallbackReturn.SUCCESS

    # ---- helpers --------------------------------------------------------------------------------
    def _wait_for_first_shape(self, timeout: float) -> str:
        """Wait until the core holds a first shape; return why not ('' once it does)."""
        assert self.core is not None
        core = self.core
        deadline = time.monotonic() + timeout
        while core.outputs.latest is None:
            if core.health.state.startswith("failed"):
                return f"the solver could not be built: {core.health.state}"
            if core.health.failures:  # the first solve failed: no shape to hold
                return f"the first solve failed: {core.health.last_error}"
            if time.monotonic() > deadline:
                return (
                    f"no first shape within configure_timeout = {timeout:g} s (solver state: "
                    f"{safe_text(core.engine.state)}); raise configure_timeout for a slow build"
                )
            time.sleep(0.02)
        return ""

    def close(self, timeout: float = STOP_TIMEOUT_S) -> bool:
        """Release the core (SIGINT / SIGTERM); return whether every solver thread has ended.

        False also after an earlier cleanup or shutdown whose solver thread did not end in time
        (``run.stop`` then leaves without finalising the interpreter around it).
        """
        released = self._release(timeout)
        return released and (self._stuck is None or not self._stuck.engine.alive)

    def _release(self, timeout: float = STOP_TIMEOUT_S) -> bool:
        """Stop the core, destroy what it made, return memory; True if its thread ended."""
        core, self.core = self.core, None
        stopped = True
        if core is not None:
            core.withdraw()  # planners must not keep a cable this node no longer tracks
            stopped = core.close(timeout)
            if not stopped:
                self._stuck = core
        for kind, destroy in KINDS.items():
            for entity in list(getattr(self, kind)):
                if id(entity) not in self._own:
                    getattr(self, destroy)(entity)
        del core
        gc.collect()
        trim_heap()
        return stopped

    def _entities(self) -> set[int]:
        return {id(e) for kind in KINDS for e in getattr(self, kind)}


def refusing_unknown_transitions(callback: Callable, log: Any) -> Callable:
    """Wrap rclpy's change_state callback: a transition it cannot take answers success = False."""

    def change_state(request: Any, response: Any) -> Any:
        try:
            return callback(request, response)
        except RCLError as exc:  # "Transition is not registered": not one of this state's
            log.warning(
                f"change_state: transition {request.transition.id} "
                f"'{safe_text(request.transition.label, 60)}' refused: {safe_text(exc, 200)}"
            )
            response.success = False
            return response

    return change_state


def trim_heap() -> None:
    """Give freed heap memory back to the system (glibc ``malloc_trim``; elsewhere nothing)."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass
