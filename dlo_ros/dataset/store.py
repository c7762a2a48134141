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


def shard_name(k: int) -> str:
    """Return the file name of chunk ``k``'s shard."""
    return f"part-{k:06d}.parquet"


def shard_path(out: Path, k: int) -> Path:
    """Return where chunk ``k``'s shard lives."""
    return out / SHARDS / shard_name(k)


def shard_names(out: Path) -> set[str]:
    """Return the names of the files in ``out``'s shard folder (empty when there is none)."""
    try:
        return set(os.listdir(out / SHARDS))
    except FileNotFoundError:
        return set()


def shard_statuses(out: Path, k: int, a: int, b: int) -> list[str] | None:
    """Return the statuses stored in chunk ``k``'s shard, or None unless it holds samples [a, b).

    None for a missing, damaged or foreign shard (another chunk's samples): it is done again.
    """
    try:
        table = pq.read_table(shard_path(out, k), columns=["sample", "status"])
    except (OSError, pa.ArrowException):
        return None
    if table.column("sample").to_pylist() != list(range(a, b)):
        return None
    return [str(v) for v in table.column("status").to_pylist()]


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
    folder = os.open(path.parent, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(folder)  # the rename itself survives a crash
    finally:
        os.close(folder)


def write_shard(out: Path, k: int, table: pa.Table) -> None:
    """Store chunk ``k``'s rows (an Arrow table of ``rows.SCHEMA``) atomically."""
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    write_atomic(shard_path(out, k), sink.getvalue().to_pybytes())


def write_manifest(out: Path, manifest: dict[str, Any]) -> None:
    """Store the manifest atomically (``manifest.json``, indented JSON)."""
    write_atomic(out / MANIFEST, (json.dumps(manifest, indent=1, allow_nan=False) + "\n").encode())


def read_manifest(out: Path) -> dict[str, Any]:
    """Return the manifest of the data set in ``out``.

    FileNotFoundError when there is none; ValueError when it is not valid JSON.
    """
    return json.loads((Path(out) / MANIFEST).read_text())


def shard_files(out: Path) -> list[Path]:
    """Return the data set's shards, in sample order."""
    return sorted((Path(out) / SHARDS).glob("part-*.parquet"))


def load(out: Path | str, columns: list[str] | None = None) -> pa.Table:
    """Return the data set in ``out`` as one Arrow table, one row per sample, by ``sample``.

    ``columns``: only these (default all, ``rows.SCHEMA``).  ``table.to_pandas()`` gives a data
    frame where pandas is installed; :func:`load_arrays` gives numpy arrays.  Raises
    FileNotFoundError when ``out`` holds no data set, ValueError naming a damaged shard.
    """
    out = Path(out)
    if not (out / MANIFEST).is_file():
        raise FileNotFoundError(f"{out}: no data set here (no {MANIFEST})")
    tables = []
    for f in shard_files(out):
        try:
            tables.append(pq.read_table(f, columns=columns, schema=SCHEMA))
        except (OSError, pa.ArrowException) as exc:
            raise ValueError(f"{f}: damaged shard ({exc}); `dlo dataset --resume` rewrites it")
    if not tables:
        return SCHEMA.empty_table().select(columns or SCHEMA.names)
    table = pa.concat_tables(tables)
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
    manifest = read_manifest(Path(out))
    solver = manifest["scene"].get("solver", {})
    points = int(manifest["plan"].get("resolution") or solver.get("output_points") or 0)
    arrays: dict[str, np.ndarray] = {}
    widths = {
        "points": 3,
        "unstable_points": 3,
        "grip_force": 3,
        "grip_torque": 3,
        "obstacle_force": 3,
        "targets": 7,
    }
    for name in table.column_names:
        column = table.column(name)
        if pa.types.is_list(column.type):
            values = column.to_pylist()
            lengths = {len(v) for v in values if v}
            if len(lengths) <= 1:  # a sample without a shape (failed, infeasible): NaN rows
                width = widths.get(name, 0)
                shaped = name in ("s", "points", "unstable_points")
                known = points * max(width, 1) if shaped else 0
                length = lengths.pop() if lengths else known
                a = np.array([v if v else [np.nan] * length for v in values], dtype=float)
                a = a.reshape(len(values), length)
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
