"""Typed cells of a rerun chunk's columns, checked and converted without Python lists of numbers.

A component column of a chunk (``Chunk.to_record_batch()``) is ``list<T>``: one cell per row, each
a list of instances.  :class:`Columns` reads one column at a time, checks its arrow type and
returns the cells as ``str`` / ``bool`` / float64 numpy arrays, counting what it keeps against a
byte budget.  A wrong type, a non-finite number where a finite one is needed or a budget overrun
is a :class:`ColumnError` (a ValueError) with one line naming the entity and the column.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import paths as P


class ColumnError(ValueError):
    """A column is not what dlo_ros writes (the message names the entity and the column)."""


class Budget:
    """The bytes kept from a recording file so far, against a limit.

    Bytes kept from the file so far (numbers 8 bytes each, text 1 byte per character; the
    reader adds its rows' overhead).
    """

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.used = 0

    def take(self, n: int, where: str) -> None:
        self.used += n
        if self.used > self.limit:
            raise ColumnError(
                f"{where}: the recording holds more than {self.limit} bytes of "
                "data to read back (msg_docs/recording.md, Limits)"
            )


class Columns:
    """The columns of one chunk of ``entity`` (a pyarrow RecordBatch), read by name and type."""

    def __init__(self, batch: Any, entity: str, budget: Budget) -> None:
        self.batch = batch
        self.entity = entity
        self.budget = budget
        self.names = set(batch.schema.names)
        self.rows = batch.num_rows

    def _where(self, name: str) -> str:
        return f"{self.entity} column {name}"

    def _column(self, name: str):
        return self.batch.column(name) if name in self.names else None

    def _list(self, name: str):
        """Return the ``list<T>`` column ``name`` (None if absent)."""
        import pyarrow as pa  # optional: rerun-sdk (Python >= 3.11), with pyarrow

        col = self._column(name)
        if col is None:
            return None
        if not (pa.types.is_list(col.type) or pa.types.is_large_list(col.type)):
            raise ColumnError(f"{self._where(name)} has type {col.type}, expected a list column")
        return col

    def index(self, name: str) -> list[int | None]:
        """Read an index column (``update``, ``ros_time``): ints, None where null."""
        import pyarrow as pa  # optional: rerun-sdk (Python >= 3.11), with pyarrow

        col = self._column(name)
        if col is None:
            return [None] * self.rows
        if pa.types.is_timestamp(col.type) or pa.types.is_duration(col.type):
            col = col.cast(pa.int64())
        if not pa.types.is_integer(col.type):
            raise ColumnError(
                f"{self._where(name)} has type {col.type}, expected an integer index"
            )
        return col.to_pylist()

    def row_ids(self) -> list[bytes]:
        col = self._column("rerun.controls.RowId")
        return [b""] * self.rows if col is None else [v or b"" for v in col.to_pylist()]

    def texts(self, name: str, *, first: bool = True) -> list[Any]:
        """Read a string column: per row its first string or the list of strings.

        A string column: per row its first string (``first``) or the list of strings; None where
        null or empty.
        """
        import pyarrow as pa  # optional: rerun-sdk (Python >= 3.11), with pyarrow

        col = self._list(name)
        if col is None:
            return [None] * self.rows
        vt = col.type.value_type
        if not (pa.types.is_string(vt) or pa.types.is_large_string(vt)):
            raise ColumnError(f"{self._where(name)} has type {col.type}, expected text")
        self.budget.take(col.nbytes, self._where(name))
        cells = col.to_pylist()
        if first:
            return [c[0] if c else None for c in cells]
        return [c if c else None for c in cells]

    def flags(self, name: str) -> list[bool | None]:
        """Read a boolean column: per row its first value, None where null or empty."""
        import pyarrow as pa  # optional: rerun-sdk (Python >= 3.11), with pyarrow

        col = self._list(name)
        if col is None:
            return [None] * self.rows
        if not pa.types.is_boolean(col.type.value_type):
            raise ColumnError(f"{self._where(name)} has type {col.type}, expected booleans")
        return [c[0] if c else None for c in col.to_pylist()]

    def numbers(
        self, name: str, *, finite: bool = True, per_row: int | None = None
    ) -> list[np.ndarray | None]:
        """Read a numeric column: per row a float64 array (None where null).

        A numeric column: per row a float64 array (None where null).  ``finite``: NaN or inf is
        an error; ``per_row``: the largest number of values a cell may have.
        """
        import pyarrow as pa  # optional: rerun-sdk (Python >= 3.11), with pyarrow

        col = self._list(name)
        if col is None:
            return [None] * self.rows
        vt = col.type.value_type
        if not (pa.types.is_floating(vt) or pa.types.is_integer(vt)):
            raise ColumnError(f"{self._where(name)} has type {col.type}, expected numbers")
        values = col.flatten().to_numpy(zero_copy_only=False).astype(np.float64, copy=False)
        self.budget.take(8 * len(values), self._where(name))
        if finite and len(values) and not np.all(np.isfinite(values)):
            raise ColumnError(
                f"{self._where(name)}: NaN or infinite value where a number is expected"
            )
        offsets = col.offsets.to_numpy(zero_copy_only=False)
        offsets = offsets - offsets[0]
        valid = col.is_valid().to_numpy(zero_copy_only=False)
        out: list[np.ndarray | None] = []
        for i in range(self.rows):
            if not valid[i]:
                out.append(None)
                continue
            cell = values[offsets[i] : offsets[i + 1]]
            if per_row is not None and len(cell) > per_row:
                raise ColumnError(
                    f"{self._where(name)}: {len(cell)} values in one row, at most "
                    f"{per_row} (msg_docs/recording.md, Limits)"
                )
            out.append(cell.copy())
        return out

    def strips(self, name: str, per_row: int) -> list[np.ndarray | None]:
        """Read ``LineStrips3D:strips`` as the centreline it draws, per row.

        ``LineStrips3D:strips`` as the centreline it draws: the first point of each strip and
        the last point of the last one, (n, 3) float64 per row (None where null or empty).
        """
        import pyarrow as pa  # optional: rerun-sdk (Python >= 3.11), with pyarrow

        col = self._list(name)
        if col is None:
            return [None] * self.rows
        inner = col.type.value_type
        if not (
            (pa.types.is_list(inner) or pa.types.is_large_list(inner))
            and pa.types.is_fixed_size_list(inner.value_type)
            and inner.value_type.list_size == 3
            and pa.types.is_floating(inner.value_type.value_type)
        ):
            raise ColumnError(
                f"{self._where(name)} has type {col.type}, expected line strips of 3D points"
            )
        strips = col.flatten()  # one entry per strip
        points = strips.flatten().flatten().to_numpy(zero_copy_only=False)
        self.budget.take(8 * len(points), self._where(name))
        points = points.astype(np.float64).reshape(-1, 3)
        row_off = col.offsets.to_numpy(zero_copy_only=False) - col.offsets[0].as_py()
        strip_off = strips.offsets.to_numpy(zero_copy_only=False) - strips.offsets[0].as_py()
        valid = col.is_valid().to_numpy(zero_copy_only=False)
        out: list[np.ndarray | None] = []
        for i in range(self.rows):
            a, b = row_off[i], row_off[i + 1]
            if not valid[i] or b <= a:
                out.append(None)
                continue
            if b - a + 1 > per_row:
                raise ColumnError(
                    f"{self._where(name)}: {b - a} strips in one row, at most "
                    f"{per_row} (msg_docs/recording.md, Limits)"
                )
            starts, ends = strip_off[a:b], strip_off[a + 1 : b + 1]
            if np.any(ends <= starts):
                raise ColumnError(f"{self._where(name)}: an empty line strip")
            out.append(np.vstack([points[starts], points[ends[-1] - 1][None, :]]))
        return out


def updates_of(cols: Columns, required: bool) -> list[int | None]:
    """Return the ``update`` index per row; ``required``: a row without one is an error."""
    ups = cols.index(P.TIMELINE_UPDATE)
    if required and any(u is None for u in ups):
        raise ColumnError(f"{cols.entity}: a row without an '{P.TIMELINE_UPDATE}' index")
    return ups
