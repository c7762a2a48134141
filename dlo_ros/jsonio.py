"""Helpers for commands that print one JSON document.

Small helpers for commands that print one JSON document: strict JSON values, and keeping stray
output (e.g. from C code) off stdout while it is produced.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
from typing import Any, Iterator

import numpy as np


@contextlib.contextmanager
def stdout_to_stderr() -> Iterator[None]:
    """Send everything written to file descriptor 1 (also by C code: IPOPT, CasADi) to stderr.

    Keeps ``--json`` output exactly one JSON document.
    """
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError):  # no real stdout (e.g. closed): nothing to protect
        yield
        return
    try:
        os.dup2(2, 1)
        yield
    finally:
        with contextlib.suppress(OSError, ValueError):
            sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def json_safe(value: Any) -> Any:
    """Non-finite floats -> None (strict JSON), numpy scalars/arrays -> Python."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value) + 0.0  # + 0.0 turns -0.0 into 0.0
        return v if math.isfinite(v) else None
    return value
