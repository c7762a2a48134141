"""Point files of an observation: ``.npy`` (an N × 3 float array) and ``.ply`` (the x, y, z of the
``vertex`` element; ASCII or binary, little or big endian; the vertex element must come first, as
point clouds written by common tools have it; other properties and elements are ignored)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

#: PLY scalar types → numpy
PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
             "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
             "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
#: the longest PLY header read
MAX_HEADER = 64 * 1024


def read_points(path: Path) -> np.ndarray:
    """The points of a .npy or .ply file as an (N, 3) float array.  Raises ValueError (why) or OSError."""
    suffix = path.suffix.lower()
    if suffix == ".npy":
        return np.asarray(np.load(path, allow_pickle=False), dtype=float)
    if suffix == ".ply":
        return read_ply(path)
    raise ValueError(f"only .npy and .ply point files are read, got {suffix or 'no suffix'!r}")


def read_ply(path: Path) -> np.ndarray:
    """x, y, z of the vertex element of a PLY file (module docstring)."""
    with open(path, "rb") as f:
        head = f.read(MAX_HEADER)
        end = head.find(b"end_header")
        if not head.startswith(b"ply") or end < 0:
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
                seen_vertex, count = True, int(words[2])
            elif words[0] == "property" and seen_vertex:
                if words[1] == "list":
                    raise ValueError("list properties in the vertex element are not supported")
                if words[1] not in PLY_TYPES:
                    raise ValueError(f"unknown PLY property type {words[1]!r}")
                props.append((words[2], PLY_TYPES[words[1]]))
        names = [n for n, _ in props]
        if count is None or not all(a in names for a in "xyz"):
            raise ValueError("no vertex element with x, y, z properties")
        if fmt == "ascii":
            f.seek(body_start)
            text = f.read().decode("ascii", errors="replace").split("\n")[:count]
            rows = np.array([line.split()[:len(props)] for line in text if line.strip()], dtype=float)
            if rows.shape != (count, len(props)):
                raise ValueError(f"expected {count} vertex rows of {len(props)} values")
            return rows[:, [names.index(a) for a in "xyz"]]
        order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
        if order is None:
            raise ValueError(f"unknown PLY format {fmt!r}")
        dtype = np.dtype([(n, order + t) for n, t in props])
        f.seek(body_start)
        data = np.fromfile(f, dtype=dtype, count=count)
        if data.size != count:
            raise ValueError(f"expected {count} vertices, the file holds {data.size}")
        return np.stack([data[a].astype(float) for a in "xyz"], axis=1)
