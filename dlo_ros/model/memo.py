"""A memo of matrices per array of arc lengths, bounded by the bytes it holds.

A running solver asks a model for the same arc lengths again (its output grid, its obstacle rows),
so their basis and integration matrices are worth keeping.  The bound is in bytes, not entries:
a fine element mesh's matrices at a residual grid take ~20 MB per entry, and every check of a
sliding contact asks at a new grid (a count of 256 entries let one stream hold 5 GB).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from typing import Generic, TypeVar

import numpy as np

T = TypeVar("T")

#: the bytes one model's memo may hold (least recently used entries go first)
MEMO_BYTES = 64 * 2**20


def _frozen(value: T) -> T:
    """Return ``value`` with its arrays made read-only.

    An entry is shared by every caller: one that wrote into it would change what later callers
    read, so a write raises instead.
    """
    if isinstance(value, np.ndarray):
        value.flags.writeable = False
    elif isinstance(value, tuple):
        for v in value:
            _frozen(v)
    return value


def _nbytes(value: object) -> int:
    if isinstance(value, np.ndarray):
        return value.nbytes
    if isinstance(value, tuple):
        return sum(_nbytes(v) for v in value)
    return 0


class ArrayMemo(Generic[T]):
    """``get(kind, s, make)`` = ``make(s)``, remembered per (kind, s), least recently used out."""

    def __init__(self, limit: int = MEMO_BYTES):
        self.limit = limit
        self._entries: OrderedDict[bytes, tuple[T, int]] = OrderedDict()
        self._bytes = 0

    def get(self, kind: str, s: np.ndarray, make: Callable[[np.ndarray], T]) -> T:
        """Return ``make(s)`` for the flattened float array s, from the memo when it is there."""
        s = np.ascontiguousarray(s, dtype=float).ravel()
        key = kind.encode() + b"\0" + s.tobytes()
        hit = self._entries.get(key)
        if hit is not None:
            self._entries.move_to_end(key)
            return hit[0]
        value = _frozen(make(s))
        size = _nbytes(value)
        if size <= self.limit:
            self._entries[key] = (value, size)
            self._bytes += size
            while self._bytes > self.limit:
                _, (_, dropped) = self._entries.popitem(last=False)
                self._bytes -= dropped
        return value

    @property
    def nbytes(self) -> int:
        """The bytes held now."""
        return self._bytes
