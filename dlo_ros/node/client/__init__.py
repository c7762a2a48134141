"""Drive a running dlo node from another process: the demo, the benchmark and the tests use this.

* :func:`allocate_domain_id` (:mod:`.domains`) reserves a ROS_DOMAIN_ID no other process on this
  machine uses (lock files), so several nodes (demos, benchmarks, tests) can run side by side.
* :class:`NodeProcess` (:mod:`.node_process`) starts ``python -m dlo_ros.node`` (or another module
  that stands in for it) as a subprocess in its own process group and always stops it (SIGINT,
  then SIGTERM, then SIGKILL of the group).
* :class:`DloClient` (:mod:`.dlo_client`) is an rclpy node in its own context (its own domain)
  with a spinning thread: it publishes targets, records every centreline with its arrival time,
  keeps the latest diagnostics and wrenches, and calls the services and the parameter service.
* :func:`running_node` (:mod:`.session`) does all three: the node in its own domain, a client, the
  first centreline.

The tests' own harness (which scene and model they run on, process-group checks) is in
test/support/.
"""

from __future__ import annotations

from .dlo_client import SERVICE_SETTLE_S, DloClient, PathEvent
from .domains import DOMAIN_IDS, DomainLease, allocate_domain_id, ros_env
from .executors import make_executor
from .node_process import NodeProcess
from .session import NodeStartError, running_node

__all__ = [
    "DOMAIN_IDS",
    "SERVICE_SETTLE_S",
    "DloClient",
    "DomainLease",
    "NodeProcess",
    "NodeStartError",
    "PathEvent",
    "allocate_domain_id",
    "make_executor",
    "ros_env",
    "running_node",
]
