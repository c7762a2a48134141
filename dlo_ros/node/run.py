"""Run the dlo node from the command line: check the arguments, start rclpy, spin, stop cleanly.

``python -m dlo_ros.node``, ``dlo node`` and ``ros2 run dlo_ros dlo_node`` end here
(dlo_ros.node.main).  Every params file and ``-p`` value is checked in Python before rcl reads
them (params.prepare_node_args); an unusable one, or a StartupError of the node, is one line on
stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

from ..paths import config_path
from ..scene import SceneError, load_scene
from ..text import one_line_warnings
from . import params as P
from .dlo_node import DloNode, StartupError
from .managed import ManagedDloNode
from .signals import exit_on_second_signal, node_starting, terminate_children
from .validation import safe_text

STOP_TIMEOUT_S = 5.0  # how long shutdown waits for the solve in progress
#: how long a managed node keeps spinning after its 'shutdown' transition [s]
FINAL_LINGER_S = 0.3


def argument_parser() -> argparse.ArgumentParser:
    """Return the parser of the node's options (``--params-file``, ``--scene``, ``--check``)."""
    return P.node_argument_parser("python -m dlo_ros.node")


def default_params_file() -> str | None:
    """Return the shipped config/dlo_node.yaml if it is installed, else None."""
    try:
        path = config_path("dlo_node.yaml")
    except (FileNotFoundError, OSError):
        return None
    return str(path) if path.is_file() else None


def new_executor(context: rclpy.context.Context | None = None) -> SingleThreadedExecutor:
    """Build the node's executor (on ``context``, default rclpy's).

    A SIGINT or SIGTERM during rclpy's constructor (which shuts the context down under it) leaves
    a half-built executor whose ``__del__`` reads an attribute the constructor had not set yet:
    "Exception ignored ... AttributeError: ... '_sigint_gc'" with a traceback at exit.  The
    attribute is set first, so a failed construction leaves nothing for ``__del__`` to trip on.
    """
    executor = SingleThreadedExecutor.__new__(SingleThreadedExecutor)
    # ignore: rclpy types the attribute as a guard condition; None is what its __del__ tolerates
    executor._sigint_gc = None  # type: ignore[assignment]
    executor.__init__(context=context)  # type: ignore[misc]  # __init__ called on purpose
    return executor


def check_only(prepared: P.NodeArgs) -> int:
    """Load the scene of ``prepared`` and report whether the node would start (``--check``)."""
    try:
        scene = load_scene(prepared.scene)
    except (SceneError, FileNotFoundError) as exc:
        print(
            f"dlo_node: error: parameter scene={safe_text(prepared.scene)!r}: "
            f"{safe_text(exc, 1000)}",
            file=sys.stderr,
        )
        return 2
    files = ", ".join(safe_text(f) for f in prepared.params_files) or "none"
    print(
        f"dlo_node: ok: params files {files}; scene '{safe_text(scene.name)}' "
        f"({safe_text(scene.source)}), grips {[safe_text(g.name) for g in scene.problem.grips]}; "
        "the node would start"
    )
    return 0


def main(argv: list[str] | None = None, prog: str = "python -m dlo_ros.node") -> int:
    """Run the node until Ctrl-C / SIGINT / SIGTERM / shutdown; return the exit code.

    argv: command-line arguments without the program name (default: sys.argv[1:]); ROS arguments
    (--ros-args ...) are passed through to rclpy after :func:`params.prepare_node_args` checked
    them (exit code 2 and one line naming the file / parameter when they are unusable).
    ``--check`` stops after those checks and loading the scene.  ``prog``: the name in usage
    messages.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    one_line_warnings()
    # Every params file and -p value is checked here, in Python, before rcl reads them: rcl reports
    # a broken file only as "Failed to parse global arguments", ignores misspelt names and accepts
    # any frame.
    try:
        prepared = P.prepare_node_args(argv, default_params_file(), prog=prog)
    except P.ParamsError as exc:
        print(f"dlo_node: error: {safe_text(exc, 1000)}", file=sys.stderr)
        return 2
    if prepared.check:
        return check_only(prepared)
    return spin(prepared, argv)


def spin(prepared: P.NodeArgs, argv: list[str]) -> int:
    """Start rclpy and the node, spin until stopped, then stop both; return the exit code."""
    node: DloNode | ManagedDloNode | None = None
    executor = None
    code = 0
    try:
        node_starting()
        try:
            rclpy.init(args=prepared.ros_args)
        except Exception as exc:  # noqa: BLE001 - rcl refused the ROS arguments (files checked)
            print(
                f"dlo_node: error: ROS arguments {safe_text(' '.join(argv), 300)!r}: "
                f"{safe_text(exc)}",
                file=sys.stderr,
            )
            return 2
        node = ManagedDloNode() if prepared.managed else DloNode()
        # One thread for the main node: it only converts and checks messages (the solver has its
        # own thread, the services await it as coroutines, and the target subscriptions have
        # their own small node, executor and thread: hot_path.py, stopped by node.close).  rclpy's
        # MultiThreadedExecutor is slower per message here and competes with the solver thread
        # for the GIL. rclpy.experimental.EventsExecutor (rclpy 7.1.6 wheels) cannot serve this
        # node: its spin() livelocks before dispatching anything (a steady-clock deadline of max()
        # overflows in the wheel's pthread_cond_timedwait), coroutine services fail
        # (ros2/rclpy#1473, not in Jazzy) and guard conditions are refused
        # (bench/results/events_executor_raw.md); the target node has none of these and runs on
        # one (hot_path.py).
        executor = new_executor()
        executor.add_node(node)
        if isinstance(node, ManagedDloNode):
            while not node.finished.is_set():  # until the 'shutdown' transition
                executor.spin_once(timeout_sec=0.2)
            # a little longer, so that DDS can still resend the shutdown's response and event
            linger = time.monotonic() + FINAL_LINGER_S
            while time.monotonic() < linger:
                executor.spin_once(timeout_sec=0.05)
        else:
            executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except StartupError as exc:
        print(f"dlo_node: error: {safe_text(exc, 1000)}", file=sys.stderr)
        code = 2
    except Exception:
        if rclpy.ok():
            raise
        # SIGINT/SIGTERM during start-up shut the context down under the node's constructor: a
        # clean stop
    finally:
        exit_on_second_signal(code)  # a second Ctrl-C while stopping: leave at once
        stop(node, executor, code)
    return code


def stop(
    node: DloNode | ManagedDloNode | None, executor: SingleThreadedExecutor | None, code: int
) -> None:
    """Close the node and rclpy; leave at once (``os._exit``) if the solver thread is stuck."""
    stuck = False
    try:
        if node is not None:
            stuck = not node.close(STOP_TIMEOUT_S)
            if stuck:
                print(
                    f"dlo_node: warning: the solver thread is still busy after "
                    f"{STOP_TIMEOUT_S:g} s (a long solve or a compile); exiting without waiting "
                    "for it",
                    file=sys.stderr,
                )
            if executor is not None:
                executor.shutdown(timeout_sec=2.0)
            node.destroy_node()
        rclpy.try_shutdown()
    except KeyboardInterrupt:  # a second Ctrl-C while shutting down
        pass
    # e.g. a background compile's gcc: nothing the node started outlives it
    terminate_children()
    if stuck:
        # Interpreter finalisation with a thread still inside CasADi/IPOPT (C++) can abort the
        # process ("terminate called without an active exception"); leave without it, and take
        # our own children (a gcc compiling the solver's derivatives) along.
        terminate_children()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
