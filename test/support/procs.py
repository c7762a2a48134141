"""Linux /proc helpers for the tests of worker processes (test_pool_recovery, test_node_children)."""
from __future__ import annotations

import os


def _stat(pid: int) -> str | None:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read()
    except OSError:
        return None


def ended(pid: int) -> bool:
    """Whether process ``pid`` has exited: a zombie, or reaped.  (Its cmdline empties earlier: the
    kernel drops the memory map before it closes the process's files, pipes included.)"""
    stat = _stat(pid)
    return stat is None or stat[stat.rindex(")") + 2] in "ZX"


def children(pid: int) -> list[int]:
    """Process ids whose parent is ``pid``."""
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            stat = _stat(int(entry))
            if stat is not None and int(stat[stat.rindex(")") + 2:].split()[1]) == pid:
                out.append(int(entry))
    return out
