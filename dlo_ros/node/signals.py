"""How the node process answers SIGINT and SIGTERM.

No ROS here, so it can run before rclpy is imported.

Contract (msg_docs/node.md, "Exit codes"): the first SIGINT or SIGTERM at any time — while Python
imports rclpy and CasADi, while the node starts, or while it runs — stops the node cleanly with
exit code 0.  A second one while it is stopping ends the process at once, also with 0, after
terminating the process's children (a gcc compiling the solver); the recording may then be cut
short.  Once the node has stopped, the process ignores both while Python finalises.  (A signal in
the first few milliseconds, before Python runs the entry point, still has the default action.)

rclpy installs its own handlers in ``rclpy.init`` (they shut the context down, which ends the
spin). Before that, :func:`stop_on_first_signal` replaces Python's defaults (SIGTERM killed the
process with −15): while the modules are still imported a first signal leaves at once with 0
(nothing is open yet, and unwinding an import could escape as an uncaught interrupt, −2); from
:func:`node_starting` on it raises ``KeyboardInterrupt``, so that the node closes its solver and
recording.
"""

from __future__ import annotations

import os
import signal
import sys
import threading

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_exit_code: int | None = None  # set once the process is stopping: the next signal leaves with it


# set just before rclpy.init: from then on a stop unwinds (the node closes its recording)
_node_started = False


def node_starting() -> None:
    """Mark that the node is about to start (rclpy.init).

    A first signal now unwinds through KeyboardInterrupt, so that the node stops cleanly; before,
    there is nothing to close and the process leaves at once.
    """
    global _node_started
    _node_started = True


def _interrupt(signum, frame) -> None:
    if (
        _exit_code is not None
    ):  # rclpy restores this handler at its shutdown; the process is stopping
        _leave(signum, frame)
    if (
        not _node_started
    ):  # still importing: unwinding an import can escape as an uncaught interrupt (−2)
        exit_on_second_signal(0)
        _leave(signum, frame)
    if in_finaliser(frame):  # raised there it would be printed and dropped: the stop was lost
        _again_soon(signum)
        return
    exit_on_second_signal(0)  # whatever catches this interrupt, a second signal leaves at once
    raise KeyboardInterrupt(signal.Signals(signum).name)


def in_finaliser(frame) -> bool:
    """Tell whether ``frame`` runs inside a ``__del__`` (a garbage collection the signal hit).

    Python prints an exception raised in a finaliser as "Exception ignored in …" with its
    traceback and drops it: a KeyboardInterrupt raised there neither stops the node nor stays
    silent (CI saw it in rclpy's ``Future.__del__``).
    """
    while frame is not None:
        if frame.f_code.co_name == "__del__":
            return True
        frame = frame.f_back
    return False


def _again_soon(signum: int) -> None:
    """Deliver ``signum`` to this process again in a moment, outside the finaliser it hit."""
    timer = threading.Timer(0.01, os.kill, (os.getpid(), signum))
    timer.daemon = True
    timer.start()


def _leave(signum, frame) -> None:
    terminate_children()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(_exit_code or 0)


def stop_on_first_signal() -> None:
    """Raise KeyboardInterrupt in the main thread on SIGINT or SIGTERM (until rclpy's handlers)."""
    for sig in STOP_SIGNALS:
        signal.signal(sig, _interrupt)


def exit_on_second_signal(code: int) -> None:
    """Make SIGINT or SIGTERM end the process at once from now on (the process is stopping).

    The children are terminated and the process exits with ``code`` without unwinding (a thread
    may be inside CasADi/IPOPT).
    """
    global _exit_code
    _exit_code = code
    for sig in STOP_SIGNALS:
        signal.signal(sig, _leave)


def ignore_signals_at_exit() -> None:
    """Ignore SIGINT and SIGTERM from now on: the process is about to exit.

    CPython's finalisation resets every signal with a Python handler to its default action, and a
    Ctrl-C during it (it can take a second: DDS and CasADi teardown) killed the process with −2.
    """
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)


def terminate_children() -> None:
    """Send SIGTERM to every descendant of this process (e.g. gcc and its cc1), deepest first.

    Linux /proc; best effort, silent elsewhere.
    """
    parents: dict[int, int] = {}
    try:
        entries = os.listdir("/proc")
    except OSError:
        return
    for entry in entries:
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                stat = f.read()
            parents[int(entry)] = int(stat[stat.rindex(")") + 2 :].split()[1])
        except (OSError, ValueError, IndexError):
            continue
    found, frontier = [], [os.getpid()]
    while frontier:
        children = [pid for pid, ppid in parents.items() if ppid in frontier]
        found.extend(children)
        frontier = children
    for pid in reversed(found):
        try:
            os.kill(pid, signal.SIGTERM)
        except OSError:
            pass
