"""A node in its own process group, always stopped with everything it started.

:class:`NodeProcess` starts ``python -m dlo_ros.node`` (or another module that stands in for it)
as a subprocess in its own process group and always stops it (SIGINT, then SIGTERM, then SIGKILL
of the group).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Sequence

from .domains import ros_env


class NodeProcess:
    """Run ``python -m <module> <args>`` (default ``dlo_ros.node``) in a new process group.

    Output goes to ``log_path``.  ``env``: the base environment (default this process's) that
    :func:`ros_env` completes.
    """

    def __init__(
        self,
        args: Sequence[str],
        domain_id: int,
        *,
        log_path: str | os.PathLike | None = None,
        env: dict | None = None,
        module: str = "dlo_ros.node",
    ):
        self.args = list(args)
        self.domain_id = domain_id
        if log_path is None:
            fd, log_path = tempfile.mkstemp(prefix="dlo_node_", suffix=".log")
            os.close(fd)
            self._own_log = True
        else:
            self._own_log = False
        self.log_path = Path(log_path)
        self._log = open(self.log_path, "wb")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", module, *self.args],
            stdin=subprocess.DEVNULL,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            env=ros_env(domain_id, env),
            start_new_session=True,
        )
        self.returncode: int | None = None

    @property
    def pid(self) -> int:
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc.poll() is None

    def rss_bytes(self) -> int:
        """Resident set size of the node process (VmRSS from /proc)."""
        with open(f"/proc/{self.proc.pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
        raise RuntimeError("no VmRSS")

    def output(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def send_signal(self, sig: int) -> None:
        if self.alive():
            self.proc.send_signal(sig)

    def wait(self, timeout: float) -> int | None:
        try:
            self.returncode = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            return None
        return self.returncode

    def stop(self, timeout: float = 15.0, sig: int = signal.SIGINT) -> int:
        """Stop the node and return its exit code.

        ``sig`` first, then SIGTERM, then SIGKILL of its process group.
        """
        if self.alive():
            self.send_signal(sig)
            if self.wait(timeout) is None:
                self._killpg(signal.SIGTERM)
                if self.wait(5.0) is None:
                    self._killpg(signal.SIGKILL)
                    self.wait(5.0)
        self.returncode = self.proc.wait()
        self._killpg(signal.SIGKILL)  # anything the node started (none expected) goes too
        self._log.close()
        return self.returncode

    def _killpg(self, sig: int) -> None:
        try:
            os.killpg(self.proc.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass

    def close(self) -> None:
        if self.returncode is None or not self._log.closed:
            self.stop()
        if self._own_log:
            self.log_path.unlink(missing_ok=True)

    def __enter__(self) -> "NodeProcess":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
