"""A node and a client together: the node in its own domain, a client, its first centreline."""

from __future__ import annotations

import contextlib
import os
import signal
import time
from typing import Any, Iterator

from .dlo_client import DloClient
from .domains import allocate_domain_id
from .node_process import NodeProcess


class NodeStartError(RuntimeError):
    """The node published no centreline in time; the message carries its output."""


@contextlib.contextmanager
def running_node(
    *node_args: str,
    startup_timeout: float = 60.0,
    log_path: str | os.PathLike | None = None,
    client_name: str = "dlo_test_client",
    stop_signal: int = signal.SIGINT,
    module: str = "dlo_ros.node",
    env: dict | None = None,
    **client_kwargs: Any,
) -> Iterator[tuple[NodeProcess, DloClient]]:
    """Start the node in its own domain and a client; yield both once the first centreline came.

    On exit the client is closed and the node stopped with ``stop_signal`` (then SIGTERM/SIGKILL of
    its process group); ``proc.returncode`` and ``proc.output()`` stay readable afterwards when
    ``log_path`` is given.  ``module`` and ``env`` go to :class:`NodeProcess` (a stand-in for the
    node, e.g. the benchmark's echo, started the same way).
    """
    lease = allocate_domain_id()
    proc = client = None
    try:
        proc = NodeProcess(
            list(node_args), lease.domain_id, log_path=log_path, env=env, module=module
        )
        client = DloClient(lease.domain_id, client_name=client_name, **client_kwargs)
        deadline = time.monotonic() + startup_timeout
        first = None
        while first is None and proc.alive() and time.monotonic() < deadline:
            first = client.wait_for_path(0.25)
        if first is None:
            raise NodeStartError(
                f"the node published no centreline within {startup_timeout:.0f} s "
                f"(alive: {proc.alive()}); output:\n{proc.output()}"
            )
        if not client.wait_for_subscribers(10.0):
            raise NodeStartError(
                f"the node's target subscriptions did not match; output:\n{proc.output()}"
            )
        yield proc, client
    finally:
        if client is not None:
            client.close()
        if proc is not None:
            proc.stop(sig=stop_signal)
            if log_path is None:
                proc.close()
        lease.release()
