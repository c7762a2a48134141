"""The node's stop signal never lands in a finaliser (CI: "Exception ignored in: Future.__del__ …
KeyboardInterrupt: SIGINT" printed by `dlo node`, the stop dropped).  No ROS here: the handler is
called as the interpreter calls it, with the frame the signal interrupted."""

from __future__ import annotations

import signal
import sys
import time

import pytest

from dlo_ros.node import signals


class Finalised:
    def __init__(self, probe):
        self.probe = probe

    def __del__(self):
        self.probe(sys._getframe())


@pytest.fixture
def started(monkeypatch):
    monkeypatch.setattr(signals, "_node_started", True)
    monkeypatch.setattr(signals, "_exit_code", None)
    monkeypatch.setattr(signals, "exit_on_second_signal", lambda code: None)
    sent = []
    monkeypatch.setattr(signals.os, "kill", lambda pid, signum: sent.append(signum))
    return sent


def test_a_signal_in_a_finaliser_is_delivered_again_outside_it(started):
    raised = []

    def probe(frame):
        try:
            signals._interrupt(signal.SIGINT, frame)
        except KeyboardInterrupt:  # pragma: no cover - the bug: dropped by the interpreter
            raised.append(True)

    Finalised(probe)  # collected at once: __del__ runs the handler on its own frame
    deadline = time.monotonic() + 2
    while not started and time.monotonic() < deadline:
        time.sleep(0.005)
    assert not raised and started == [signal.SIGINT]


def test_anywhere_else_it_interrupts_at_once(started):
    with pytest.raises(KeyboardInterrupt, match="SIGTERM"):
        signals._interrupt(signal.SIGTERM, sys._getframe())
    assert started == []
