"""ROS domain ids for nodes that run side by side: one lease per node, and its environment.

:func:`allocate_domain_id` reserves a ROS_DOMAIN_ID no other process on this machine uses (lock
files), so several nodes (demos, benchmarks, tests) can run side by side; :func:`ros_env` is the
environment of a node process in that domain, with discovery limited to this machine.
"""

from __future__ import annotations

import errno
import fcntl
import os
import tempfile
from pathlib import Path

#: Domain ids that keep Fast DDS's UDP ports valid (0 is left to interactive use).
DOMAIN_IDS = tuple(range(1, 102)) + tuple(range(215, 233))
LOCK_DIR = Path(tempfile.gettempdir()) / "dlo_ros_domains"
_counter = 0  # leases taken by this process (spreads the start of the search)


class DomainLease:
    """A reserved ROS_DOMAIN_ID; ``release()`` (or process exit) frees it."""

    def __init__(self, domain_id: int, fd: int):
        self.domain_id = domain_id
        self._fd: int | None = fd

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> "DomainLease":
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def allocate_domain_id() -> DomainLease:
    """Reserve a free domain id (an flock on a lock file per id).

    The search starts at a pid- and counter-derived offset, so concurrent processes rarely even
    contend.
    """
    global _counter
    LOCK_DIR.mkdir(parents=True, exist_ok=True)
    _counter += 1
    start = (os.getpid() * 7 + _counter * 13) % len(DOMAIN_IDS)
    for k in range(len(DOMAIN_IDS)):
        domain = DOMAIN_IDS[(start + k) % len(DOMAIN_IDS)]
        fd = os.open(LOCK_DIR / f"{domain}.lock", os.O_CREAT | os.O_RDWR, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno in (errno.EAGAIN, errno.EACCES):
                continue
            raise
        return DomainLease(domain, fd)
    raise RuntimeError("no free ROS_DOMAIN_ID (all are reserved by other processes)")


def ros_env(domain_id: int, base: dict | None = None) -> dict:
    """Return the environment of a node process in ``domain_id`` (discovery on this machine)."""
    env = dict(os.environ if base is None else base)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env["PYTHONUNBUFFERED"] = "1"
    env.pop("ROS_LOCALHOST_ONLY", None)  # deprecated in Jazzy; conflicts with the setting above
    return env
