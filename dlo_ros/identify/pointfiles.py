"""Point files of an observation: ``.npy`` and ``.ply``.

Point files of an observation: ``.npy`` (an N × 3 real array) and ``.ply`` (the x, y, z of the
``vertex`` element; ASCII or binary, little or big endian; the vertex element must come first, as
point clouds written by common tools have it; other properties and elements are ignored).

What reading one may cost is bounded before anything is allocated (msg_docs/fitting.md, "Limits"):
a regular file only (a FIFO or device is refused without blocking, ``scene.read_regular_file``), at
most :data:`FILE_BYTES`; at most :data:`MAX_POINTS` points; a ``.npy`` header's shape × item size
must equal the bytes that follow it, and its dtype must be real (no complex, object or structured
arrays); a PLY's vertex count and property count are checked against the limits and the file's size
before its body is parsed.  Every refusal is a ValueError with one line (no traceback).
"""

from __future__ import annotations

import ast
import io
from typing import Literal
from pathlib import Path

import numpy as np

from ..scene import FileLimitError, read_regular_file

#: PLY scalar types → numpy
PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
#: the longest PLY header read
MAX_HEADER = 64 * 1024
#: the largest point file [bytes]: 200,000 points of 3 doubles are 4.8 MB; an ASCII or colour PLY
#: more
FILE_BYTES = 64 << 20
#: the largest point cloud read per observation
MAX_POINTS = 200_000
#: the most properties of a PLY vertex
MAX_PLY_PROPERTIES = 64
#: the longest .npy header (numpy's own default bound)
MAX_NPY_HEADER = 10_000
DOC = "msg_docs/fitting.md, Limits"


def read_points(path: Path) -> np.ndarray:
    """Read the points of a .npy or .ply file.

    The points of a .npy or .ply file as an (N, 3) float array.  Raises ValueError (one line:
    why).
    """
    suffix = path.suffix.lower()
    if suffix not in (".npy", ".ply"):
        raise ValueError(f"only .npy and .ply point files are read, got {suffix or 'no suffix'!r}")
    try:
        data = read_regular_file(path, str(path), FILE_BYTES, "point file", DOC)
    except FileLimitError as exc:
        raise ValueError(str(exc).removeprefix(f"{path}: ")) from None
    return read_npy(data) if suffix == ".npy" else read_ply(data)


def read_npy(data: bytes) -> np.ndarray:
    """Read the (N, 3) points of a .npy file's bytes.

    The (N, 3) points of a .npy file's bytes; the header is validated before any array is
    made.
    """
    f = io.BytesIO(data)
    try:
        major, _ = np.lib.format.read_magic(f)
        if major not in (1, 2, 3):
            raise ValueError(f"unsupported .npy version {major}")
        size = int.from_bytes(f.read(2 if major == 1 else 4), "little")
        if size > MAX_NPY_HEADER:
            raise ValueError(f"a .npy header of {size} bytes (at most {MAX_NPY_HEADER})")
        header = ast.literal_eval(f.read(size).decode("latin1" if major < 3 else "utf-8"))
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError) as exc:
        raise ValueError(f"not a valid .npy file ({type(exc).__name__})") from None
    if not isinstance(header, dict) or set(header) != {"descr", "fortran_order", "shape"}:
        raise ValueError("not a valid .npy file (its header lacks descr, fortran_order or shape)")
    shape = header["shape"]
    if (
        not isinstance(shape, tuple)
        or len(shape) != 2
        or not all(type(n) is int and n >= 0 for n in shape)
        or shape[1] != 3
    ):
        raise ValueError(f"expected an N × 3 array, the header says shape {str(shape)[:60]}")
    if shape[0] > MAX_POINTS:
        raise ValueError(f"{shape[0]} points, over the limit of {MAX_POINTS} ({DOC})")
    descr = header["descr"]
    try:
        dtype = np.dtype(descr) if isinstance(descr, str) else None
    except TypeError:
        dtype = None
    if (
        dtype is None
        or dtype.kind not in "fiu"
        or dtype.fields is not None
        or dtype.subdtype is not None
    ):
        kind = "complex" if dtype is not None and dtype.kind == "c" else "non-real"
        raise ValueError(
            f"the array's dtype is {kind} ({str(descr)[:40]!r}): points must be real numbers"
        )
    offset = f.tell()
    expected = shape[0] * 3 * dtype.itemsize
    if len(data) - offset != expected:
        raise ValueError(
            f"the header promises {shape[0]} × 3 values of {dtype.itemsize} bytes "
            f"({expected} "
            f"bytes), the file holds {len(data) - offset} after the header"
        )
    arr = np.frombuffer(data, dtype=dtype, count=shape[0] * 3, offset=offset)
    order: Literal["C", "F"] = "F" if header["fortran_order"] else "C"
    return arr.reshape(shape, order=order).astype(float)


def read_ply(data: bytes) -> np.ndarray:
    """x, y, z of the vertex element of a PLY file's bytes (module docstring)."""
    head = data[:MAX_HEADER]
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0 or head.find(b"\n", end) < 0:
        raise ValueError("not a PLY file (no 'ply' magic or no end_header in the first 64 KiB)")
    body_start = head.index(b"\n", end) + 1
    lines = head[:end].decode("ascii", errors="replace").splitlines()
    fmt, count, props, seen_vertex = "", None, [], False
    for line in lines[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format":
            fmt = words[1] if len(words) > 1 else ""
        elif words[0] == "element":
            if seen_vertex:
                break  # the vertex element's properties are complete
            if len(words) < 3 or words[1] != "vertex":
                raise ValueError("the first element must be 'vertex'")
            if not words[2].isdigit() or len(words[2]) > 9:
                raise ValueError(
                    f"the vertex count {words[2][:20]!r} is not an integer below 10^9"
                )
            seen_vertex, count = True, int(words[2])
            if count > MAX_POINTS:
                raise ValueError(
                    f"{count} vertices, over the limit of {MAX_POINTS} points ({DOC})"
                )
        elif words[0] == "property" and seen_vertex:
            if len(words) < 3:
                raise ValueError("a property line needs a type and a name")
            if words[1] == "list":
                raise ValueError("list properties in the vertex element are not supported")
            if words[1] not in PLY_TYPES:
                raise ValueError(f"unknown PLY property type {words[1][:20]!r}")
            props.append((words[2], PLY_TYPES[words[1]]))
            if len(props) > MAX_PLY_PROPERTIES:
                raise ValueError(f"more than {MAX_PLY_PROPERTIES} vertex properties")
    names = [n for n, _ in props]
    if count is None or not all(a in names for a in "xyz") or len(set(names)) != len(names):
        raise ValueError("no vertex element with x, y, z properties (each once)")
    columns = [names.index(a) for a in "xyz"]
    if fmt == "ascii":
        text = data[body_start:].decode("ascii", errors="replace").split("\n", count)[:count]
        try:
            rows = np.array(
                [line.split()[: len(props)] for line in text if line.strip()], dtype=float
            )
        except ValueError:
            raise ValueError("a vertex row holds something that is not a number") from None
        if rows.shape != (count, len(props)):
            raise ValueError(f"expected {count} vertex rows of {len(props)} values")
        return rows[:, columns]
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
    if order is None:
        raise ValueError(f"unknown PLY format {fmt[:30]!r}")
    dtype = np.dtype([(n, order + t) for n, t in props])
    if len(data) - body_start < count * dtype.itemsize:
        raise ValueError(
            f"expected {count} vertices of {dtype.itemsize} bytes, the file holds "
            f"{(len(data) - body_start) // max(dtype.itemsize, 1)}"
        )
    rows = np.frombuffer(data, dtype=dtype, count=count, offset=body_start)
    return np.stack([rows[a].astype(float) for a in "xyz"], axis=1)
