"""The node's hot path: the target subscriptions on a small hidden node, spun in their own thread.

Why: rclpy's SingleThreadedExecutor rebuilds its wait set in Python, holding the GIL, on every
wake-up, at a cost that grows with what it waits on.  The main node's executor waits on about 18
entities (parameter and shape services, timers, guard conditions, QoS-event handlers); a target
that woke it paid that before its callback ran, and the solver thread the target woke waited for
the GIL through the next rebuild (bench/results/events_executor_raw.md).  Here a target wakes only
a node that holds the target subscriptions, spun in its own thread; the callback hands the checked
poses straight to the engine's slot (a condition variable, no executor in between).  Parameters,
services and timers stay on the main node and its executor.

The small node is spun by ``rclpy.experimental.EventsExecutor``: it dispatches from C++ without
building a wait set, and measured lower latencies than a SingleThreadedExecutor on the same small
node (bench/results/node_latency_hot.md).  The main node cannot use it (coroutine services, guard
conditions); this node has neither.  Its ``spin()`` livelocks on the Jazzy PyPI wheels, so the
thread calls ``spin_once`` with a timeout (``SPIN_TIMEOUT_S``), which is also how soon it notices
:meth:`HotPath.close`.

Names: each topic is resolved on the main node (its namespace, name and remappings), and the small
node subscribes to that absolute name, so the node's interface is unchanged.  The small node is
hidden (``_<node>_hot`` in the main node's namespace: ``ros2 node list`` leaves out names with a
leading underscore), reads no command-line arguments (the remappings are already applied, and a
``__node:=`` remap must not give it the main node's name), declares no parameters and serves
nothing.

Lifetime: :meth:`HotPath.start` starts the thread; :meth:`HotPath.close` stops it and destroys the
small node (bounded, idempotent).  A shut-down context (SIGINT, SIGTERM) ends the thread as well.
"""

from __future__ import annotations

import threading
import traceback
from typing import Any, Callable

from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile

from .validation import TEXT_LIMIT, safe_text

#: the thread that spins the small node
THREAD_NAME = "dlo-targets"
#: rclpy starts a ~/get_type_description service on every node unless this parameter is false
TYPE_DESCRIPTION_PARAMETER = "start_type_description_service"
#: the longest wait of one ``spin_once`` [s]: how soon the thread sees a stop (an event arriving
#: returns at once)
SPIN_TIMEOUT_S = 0.1


def hidden_name(node_name: str) -> str:
    """Return the small node's name for a main node named ``node_name`` (hidden: ``_`` first)."""
    return f"_{node_name}_hot"


class HotPath:
    """A small hidden node beside ``node`` for raw subscriptions, with its executor and thread.

    Create the subscriptions with :meth:`subscribe`, then :meth:`start`.  Callbacks run in the
    thread ``THREAD_NAME``, beside the main executor's thread: they must only touch what is safe
    from any thread (the engine's slot, the health, the recorder, the diagnostics publisher are).
    An exception escaping a callback (a bug) is logged with its traceback on the main node's
    logger, and the thread goes on serving.
    """

    def __init__(self, node: Node) -> None:
        self.main = node
        self.node = Node(
            hidden_name(node.get_name()),
            namespace=node.get_namespace(),
            context=node.context,
            use_global_arguments=False,
            enable_rosout=False,
            start_parameter_services=False,
            parameter_overrides=[Parameter(TYPE_DESCRIPTION_PARAMETER, value=False)],
        )
        try:
            self.executor = EventsExecutor(context=node.context)
        except BaseException:  # a signal shut the context down under it: nothing left behind
            self.node.destroy_node()
            raise
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name=THREAD_NAME, daemon=True)
        self._closed = False

    def subscribe(
        self, msg_type: type, topic: str, callback: Callable[[bytes], None], qos: QoSProfile
    ) -> Any:
        """Subscribe raw (serialised bytes) to ``topic`` as the main node names it.

        ``topic`` may be relative or private (``~/grips/targets``): it is expanded and remapped by
        the main node, and the small node subscribes to the absolute result.
        """
        name = self.main.resolve_topic_name(topic)
        return self.node.create_subscription(msg_type, name, callback, qos, raw=True)

    @property
    def alive(self) -> bool:
        """Return whether the thread is running."""
        return self._thread.is_alive()

    def start(self) -> None:
        """Start spinning the small node (and the subscriptions made so far) in its own thread."""
        self.executor.add_node(self.node)
        self._thread.start()

    def _spin(self) -> None:
        context = self.node.context
        while not self._stop.is_set() and context.ok():
            try:
                # never spin(): it livelocks on these wheels (module docstring)
                self.executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
            except ExternalShutdownException:
                return  # SIGINT / SIGTERM shut the context down: the node is stopping
            except Exception:  # noqa: BLE001 - a bug in a callback must not end the stream
                if self._stop.is_set() or not context.ok():
                    return
                self.main.get_logger().error(
                    f"target callback failed: {safe_text(traceback.format_exc(), 20 * TEXT_LIMIT)}"
                )

    def close(self, timeout: float = 2.0) -> bool:
        """Stop the thread (after the callback in progress), then destroy the small node.

        Returns whether the thread ended within ``timeout`` [s]; if it did not, the node is left
        alive (destroying it under a running callback would fail that callback).
        """
        if self._closed:
            return not self._thread.is_alive()
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout)
        if self._thread.is_alive():
            return False
        self._closed = True
        self.executor.shutdown(timeout_sec=0.0)
        self.node.destroy_node()
        return True
