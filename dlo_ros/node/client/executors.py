"""The rclpy executors a client can spin: rclpy's single-threaded one or its events executor."""

from __future__ import annotations

from rclpy.context import Context
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.experimental import EventsExecutor


def make_executor(kind: str, context: Context | None = None) -> Executor:
    """Build a new rclpy executor in ``context`` (default: the default context).

    ``kind``: 'single' (SingleThreadedExecutor, what the node uses) or 'events'
    (rclpy.experimental.EventsExecutor).
    """
    if kind == "single":
        return SingleThreadedExecutor(context=context)
    if kind == "events":
        return EventsExecutor(context=context)
    raise ValueError(f"executor {kind!r}: expected 'single' or 'events'")
