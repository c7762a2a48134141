"""A data set on disk: Parquet shards written atomically, a JSON manifest, and the reader.

Layout of an output folder::

    DIR/manifest.json            what was asked and what is there (``manifest.py``)
    DIR/shards/part-000000.parquet   samples [0, chunk), one row each (``rows.SCHEMA``)
    DIR/shards/part-000001.parquet   samples [chunk, 2·chunk) …

A shard is written to a temporary file in the same folder, fsynced and renamed into place, so a
shard either holds all its rows or is not there: an interrupted run (Ctrl-C, a killed worker, a
full disk) loses at most the shards in flight, and ``--resume`` writes only the missing ones.
"""

from __future__ import annotations

import json
import os
import secrets
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from .rows import SCHEMA

SHARDS = "shards"
MANIFEST = "manifest.json"


def shard_path(out: Path, k: int) -> Path:
    """Return where chunk ``k``'s shard lives."""
    return out / SHARDS / f"part-{k:06d}.parquet"


def shard_done(out: Path, k: int, rows: int) -> bool:
    """Tell whether chunk ``k``'s shard is there with its ``rows`` rows (a damaged one is not)."""
    path = shard_path(out, k)
    try:
        return path.is_file() and pq.ParquetFile(path).metadata.num_rows == rows
    except (OSError, pa.ArrowException):
        return False


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a fsynced temporary file renamed into place."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_shard(out: Path, k: int, table: pa.Table) -> None:
    """Store chunk ``k``'s rows (an Arrow table of ``rows.SCHEMA``) atomically."""
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    write_atomic(shard_path(out, k), sink.getvalue().to_pybytes())


def write_manifest(out: Path, manifest: dict[str, Any]) -> None:
    """Store the manifest atomically (``manifest.json``, indented JSON)."""
    write_atomic(out / MANIFEST, (json.dumps(manifest, indent=1, allow_nan=False) + "\n").encode())


def read_manifest(out: Path) -> dict[str, Any]:
    """Return the manifest of the data set in ``out`` (FileNotFoundError if there is none)."""
    return json.loads((Path(out) / MANIFEST).read_text())


def shard_files(out: Path) -> list[Path]:
    """Return the data set's shards, in sample order."""
    return sorted((Path(out) / SHARDS).glob("part-*.parquet"))


def load(out: Path | str, columns: list[str] | None = None) -> pa.Table:
    """Return the data set in ``out`` as one Arrow table, one row per sample, by ``sample``.

    ``columns``: only these (default all, ``rows.SCHEMA``).  ``table.to_pandas()`` gives a data
    frame where pandas is installed; :func:`load_arrays` gives numpy arrays.
    """
    files = shard_files(Path(out))
    if not files:
        return SCHEMA.empty_table().select(columns or SCHEMA.names)
    table = pa.concat_tables(pq.read_table(f, columns=columns, schema=SCHEMA) for f in files)
    if "sample" in table.column_names:
        table = table.sort_by("sample")
    return table


def load_arrays(out: Path | str) -> dict[str, np.ndarray]:
    """Return the data set in ``out`` as numpy arrays, one entry per column, rows by sample.

    List columns of one length per row come back 2-D, and ``points``, ``targets``,
    ``grip_force``, ``grip_torque`` and ``obstacle_force`` as (samples, items, 3 or 7), with NaN
    rows where a sample has no shape (failed, infeasible); text and JSON columns as object
    arrays; nulls as NaN (numbers) or None (flags).
    """
    table = load(out)
    arrays: dict[str, np.ndarray] = {}
    widths = {"points": 3, "grip_force": 3, "grip_torque": 3, "obstacle_force": 3, "targets": 7}
    for name in table.column_names:
        column = table.column(name)
        if pa.types.is_list(column.type):
            values = column.to_pylist()
            lengths = {len(v) for v in values if v}
            if len(lengths) <= 1:  # a sample without a shape (failed, infeasible): NaN rows
                length = lengths.pop() if lengths else 0
                a = np.array([v if v else [np.nan] * length for v in values], dtype=float)
                a = a.reshape(len(values), length)
                width = widths.get(name)
                arrays[name] = a.reshape(len(a), -1, width) if width and length else a
            else:
                arrays[name] = np.array(values, dtype=object)
        elif pa.types.is_floating(column.type):
            arrays[name] = column.to_numpy(zero_copy_only=False).astype(float)
        elif pa.types.is_integer(column.type) and column.null_count == 0:
            arrays[name] = column.to_numpy()
        else:
            arrays[name] = np.array(column.to_pylist(), dtype=object)
    return arrays
