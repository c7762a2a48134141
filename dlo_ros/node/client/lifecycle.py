"""Drive a managed dlo node's lifecycle over ROS: its state, transitions and transition events.

:class:`LifecycleClient` uses a :class:`DloClient`'s node and spinning thread; it calls the
standard services (``~/get_state``, ``~/change_state``, ``~/get_available_transitions``) and keeps
every ``~/transition_event`` it receives.  It is what a lifecycle manager (nav2's) does, in a few
lines, for tests and scripts without one.
"""

from __future__ import annotations

import threading

from lifecycle_msgs.msg import Transition, TransitionEvent
from lifecycle_msgs.srv import ChangeState, GetAvailableTransitions, GetState

from .dlo_client import DloClient

#: transition labels -> lifecycle_msgs/Transition ids (the ones a manager sends)
TRANSITIONS = {
    "configure": Transition.TRANSITION_CONFIGURE,
    "cleanup": Transition.TRANSITION_CLEANUP,
    "activate": Transition.TRANSITION_ACTIVATE,
    "deactivate": Transition.TRANSITION_DEACTIVATE,
    "shutdown": Transition.TRANSITION_UNCONFIGURED_SHUTDOWN,
    "inactive_shutdown": Transition.TRANSITION_INACTIVE_SHUTDOWN,
    "active_shutdown": Transition.TRANSITION_ACTIVE_SHUTDOWN,
}
#: the state each transition ends in when it succeeds
GOALS = {
    "configure": "inactive",
    "cleanup": "unconfigured",
    "activate": "active",
    "deactivate": "inactive",
    "shutdown": "finalized",
    "inactive_shutdown": "finalized",
    "active_shutdown": "finalized",
}


class LifecycleClient:
    """Lifecycle calls to ``client``'s node (e.g. '/dlo'); events in ``events`` (label pairs)."""

    def __init__(self, client: DloClient) -> None:
        self.client = client
        node, base = client.node, client.node_name
        self._get_state = node.create_client(GetState, f"{base}/get_state")
        self._change_state = node.create_client(ChangeState, f"{base}/change_state")
        self._transitions = node.create_client(
            GetAvailableTransitions, f"{base}/get_available_transitions"
        )
        self.events: list[tuple[str, str]] = []  # (start state, goal state) labels, in order
        self._lock = threading.Lock()
        self._sub = node.create_subscription(
            TransitionEvent, f"{base}/transition_event", self._on_event, 10
        )

    def _on_event(self, msg: TransitionEvent) -> None:
        with self._lock:
            self.events.append((msg.start_state.label, msg.goal_state.label))

    def state(self, timeout: float = 10.0) -> str:
        """Return the node's lifecycle state label ('unconfigured', 'inactive', 'active', ...)."""
        return str(
            self.client.call(self._get_state, GetState.Request(), timeout).current_state.label
        )

    def change(self, transition: str, timeout: float = 60.0) -> bool:
        """Ask for ``transition`` (a key of TRANSITIONS); return whether it succeeded.

        The node's transition event into the transition's goal state also counts as success: a
        node that shuts down can leave before its response is delivered (a loaded machine lost
        one in CI), and a manager must not wait out the timeout for it.
        """
        request = ChangeState.Request()
        request.transition.id = TRANSITIONS[transition]
        with self._lock:
            seen = len(self.events)

        def reached() -> bool:
            with self._lock:
                return any(goal == GOALS[transition] for _, goal in self.events[seen:])

        reply = self.client.call(self._change_state, request, timeout, answered=reached)
        return True if reply is None else bool(reply.success)

    def available(self, timeout: float = 10.0) -> list[str]:
        """Return the labels of the transitions available from the current state."""
        reply = self.client.call(self._transitions, GetAvailableTransitions.Request(), timeout)
        return [t.transition.label for t in reply.available_transitions]
