"""A service response lost on the way: ``DloClient.call`` stops at other evidence that the call
took effect, and ``LifecycleClient.change`` takes the node's transition event into the goal state
as that evidence (a node that shuts down can leave before its response is delivered: a loaded
machine lost the 'shutdown' response of test_node_managed.py once, and the call waited out its
60 s).  Without a ROS graph: a fake rclpy client whose future never completes."""
from __future__ import annotations

import threading
import time

import pytest
from rclpy.task import Future

from dlo_ros.node.client.dlo_client import DloClient
from dlo_ros.node.client.lifecycle import GOALS, TRANSITIONS, LifecycleClient


class SilentService:
    """An rclpy client stand-in: the service is there, and its answer never comes."""

    srv_name = "/dlo/change_state"

    def __init__(self) -> None:
        self.requests: list = []
        self.removed: list = []

    def wait_for_service(self, timeout_sec: float) -> bool:
        return True

    def call_async(self, request) -> Future:
        self.requests.append(request)
        return Future()

    def remove_pending_request(self, future: Future) -> None:
        self.removed.append(future)


class FakeDloClient:
    """What DloClient.call reads of its instance: the clients already settled."""

    def __init__(self, service: SilentService) -> None:
        self._settled = {service}

    call = DloClient.call


def test_call_returns_none_once_other_evidence_says_it_took_effect():
    service = SilentService()
    client = FakeDloClient(service)
    flips = time.monotonic() + 0.1
    t0 = time.monotonic()
    assert client.call(service, "request", 10.0, answered=lambda: time.monotonic() > flips) is None
    assert time.monotonic() - t0 < 2.0  # not the timeout
    assert len(service.removed) == 1  # the pending request is dropped


def test_without_evidence_a_lost_response_is_a_timeout():
    service = SilentService()
    with pytest.raises(TimeoutError, match="no response within"):
        FakeDloClient(service).call(service, "request", 0.2, answered=lambda: False)
    assert len(service.removed) == 1


def lifecycle_with(service: SilentService, events: list) -> LifecycleClient:
    """A LifecycleClient on the silent change_state service, holding ``events`` as received."""
    lc = LifecycleClient.__new__(LifecycleClient)
    lc.client = FakeDloClient(service)
    lc._change_state = service
    lc.events = events
    lc._lock = threading.Lock()
    return lc


def test_a_transition_event_into_the_goal_state_answers_a_lost_response():
    service = SilentService()
    events: list = [("unconfigured", "finalized")]  # an older event does not count
    lc = lifecycle_with(service, events)

    def event_arrives(request):
        events.append(("shuttingdown", "finalized"))
        return Future()

    service.call_async = event_arrives  # type: ignore[method-assign]
    t0 = time.monotonic()
    assert lc.change("shutdown", timeout=10.0) is True
    assert time.monotonic() - t0 < 2.0


def test_an_event_into_another_state_is_not_success():
    service = SilentService()
    events: list = []
    lc = lifecycle_with(service, events)

    def other_event(request):
        events.append(("configuring", "unconfigured"))  # configure failed
        return Future()

    service.call_async = other_event  # type: ignore[method-assign]
    with pytest.raises(TimeoutError):
        lc.change("configure", timeout=0.3)


def test_every_transition_has_its_goal_state():
    assert set(GOALS) == set(TRANSITIONS)
