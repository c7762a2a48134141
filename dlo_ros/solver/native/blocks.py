"""What the compiled Newton drivers are handed from Python.

What the compiled Newton drivers are handed from Python: SciPy's LAPACK and BLAS by address, and
the node map E as dense blocks for the Hessian's per-node part (``NodeBlocks``; ``WithNodePart``
adds the same part in numpy around a compiled split function called from Python).
"""

from __future__ import annotations

import ctypes

import numpy as np
from scipy.linalg import cython_blas, cython_lapack

from ..state import Inertia
from .settings import EIGEN_FOUND, EIGEN_INERTIA_STABLE


def driver_head(node_map) -> tuple[int, int, int, int, int, int]:
    """Return the first arguments of every compiled driver: dgetrf, dgetrs, dgemm, the node map.

    The LAPACK/BLAS addresses (``lapack_pointer``), the address of ``node_map``'s struct, its
    W rows and buffer size (``NodeBlocks``: the caller keeps ``node_map`` alive for the calls).
    """
    return (
        lapack_pointer("dgetrf"),
        lapack_pointer("dgetrs"),
        lapack_pointer("dgemm"),
        ctypes.addressof(node_map.struct),
        node_map.rows_w,
        node_map.buf_size,
    )


def lapack_pointer(name: str) -> int:
    """Return the address of SciPy's LAPACK (or BLAS) routine ``name``.

    The address of SciPy's LAPACK (or, for dgemm, BLAS) routine ``name`` (from the PyCapsules
    scipy.linalg.cython_lapack and cython_blas export).
    """
    capsule = (cython_blas if name == "dgemm" else cython_lapack).__pyx_capi__[name]
    get_name = ctypes.pythonapi.PyCapsule_GetName
    get_name.restype, get_name.argtypes = ctypes.c_char_p, [ctypes.py_object]
    get_pointer = ctypes.pythonapi.PyCapsule_GetPointer
    get_pointer.restype, get_pointer.argtypes = (
        ctypes.c_void_p,
        [ctypes.py_object, ctypes.c_char_p],
    )
    return int(get_pointer(capsule, get_name(capsule)))


class EigenLapackStruct(ctypes.Structure):
    """dlo_eigen_lapack in the drivers' C (native/dlo_eigen.h)."""

    _fields_ = [
        ("geqp3", ctypes.c_void_p),
        ("orgqr", ctypes.c_void_p),
        ("syevr", ctypes.c_void_p),
        ("gemm", ctypes.c_void_p),
        ("sytrf", ctypes.c_void_p),
        ("chunk", ctypes.c_int),
        ("inertia", ctypes.c_int),
    ]


def eigen_lapack(inertia: bool = True) -> EigenLapackStruct:
    """Return SciPy's routines the drivers' stability verdict calls.

    SciPy's routines the drivers' stability verdict calls (the eigenpair's and dsytrf for the
    inertia), its dgemm chunk, and whether the inertia is tried first (``dlo_stability``; False:
    the eigenpair always, as before the inertia, for comparisons).
    """
    names = ("dgeqp3", "dorgqr", "dsyevr", "dgemm", "dsytrf")
    return EigenLapackStruct(*(lapack_pointer(name) for name in names), CHUNK_WORK, int(inertia))


def verdict(
    code: int, value: float, direction: np.ndarray
) -> tuple[float, np.ndarray] | Inertia | None:
    """Return what a loop's stability verdict says (``SolverState.reduced_eigen``).

    ``code`` from ``dlo_stability``: the eigenpair (``value``, a copy of ``direction``) it found,
    ``Inertia.STABLE`` when the inertia settled it, None otherwise (no freedom, LAPACK failed).
    """
    if code == EIGEN_FOUND:
        return value, direction.copy()
    return Inertia.STABLE if code == EIGEN_INERTIA_STABLE else None


class _NodeMapStruct(ctypes.Structure):
    """dlo_node_map in the drivers' C (native/dlo_common.h)."""

    _fields_ = [
        ("groups", ctypes.c_int),
        ("chunk", ctypes.c_int),
        ("count", ctypes.c_void_p),
        ("row", ctypes.c_void_p),
        ("col", ctypes.c_void_p),
        ("block", ctypes.c_void_p),
        ("contact_blocks", ctypes.c_int),
        ("contact_rows", ctypes.c_int),
        ("contact_wsize", ctypes.c_int),
        ("contact_size", ctypes.c_void_p),
    ]


class NodeBlocks:
    """The node map E as dense blocks for the drivers' ``dlo_add_node_part``.

    The node map E (d·M × n, ``StringNLP.node_map``) as dense blocks for the drivers'
    ``dlo_add_node_part`` (H += Eᵀ W): E's columns grouped by the per-node components (row mod d)
    they reach, each group with the rows any of its columns reaches.  For the default 3D model,
    four groups (one per quaternion component) of 16 columns and 48 rows: a quarter of the
    multiplications of Eᵀ W as one dense product. ``chunk``: the most rows one dgemm call takes, so
    that OpenBLAS runs it on the calling thread.
    """

    def __init__(self, node_map: np.ndarray, width: int):
        E = np.asarray(node_map, dtype=float)
        n = E.shape[1]
        groups: dict[tuple, list[int]] = {}
        for c in range(n):
            support = np.flatnonzero(E[:, c])
            if support.size:
                groups.setdefault(tuple(sorted(set((support % width).tolist()))), []).append(c)
        #: (rows, columns, E[rows, columns]) of each group
        self.groups = []
        for members in groups.values():
            reached = np.flatnonzero(np.any(E[:, members] != 0, axis=1))
            self.groups.append((reached, np.array(members), E[np.ix_(reached, np.array(members))]))
        rows, cols, blocks = ([group[i] for group in self.groups] for i in range(3))
        self.count = np.array([(r.size, c.size) for r, c, _ in self.groups], dtype=np.intc).ravel()
        self.row = np.ascontiguousarray(np.concatenate(rows), dtype=np.intc)
        self.col = np.ascontiguousarray(np.concatenate(cols), dtype=np.intc)
        self.block = np.concatenate([b.ravel(order="F") for b in blocks])
        widest, deepest = max(len(c) for c in cols), max(r.size for r in rows)
        self.rows_w = E.shape[0]
        self.chunk = max(1, min(deepest, CHUNK_WORK // (widest * n)))
        self.buf_size = (self.chunk + widest) * n
        self.struct = _NodeMapStruct(
            len(groups),
            self.chunk,
            self.count.ctypes.data,
            self.row.ctypes.data,
            self.col.ctypes.data,
            self.block.ctypes.data,
            0,
            0,
            0,
            None,
        )
        #: the split full KKT function's curvature blocks' sizes (``attach_contact``)
        self.contact_sizes: tuple[int, ...] | None = None
        self._contact_size: np.ndarray = np.zeros(1, dtype=np.intc)

    def attach_contact(self, sizes: tuple[int, ...]) -> None:
        """Tell the drivers the sizes of the split full KKT function's curvature blocks.

        (``StringNLP.contact_sizes``, ``assembled_contact.contact_blocks``.)  Once per NLP,
        before a driver of that function runs (``functions`` installs its library); later calls
        change nothing, so that no driver ever reads the struct while it is written.
        """
        if self.contact_sizes is not None:
            return
        self._contact_size = np.ascontiguousarray(np.array(sizes or (0,), dtype=np.intc))
        self.struct.contact_size = self._contact_size.ctypes.data
        self.struct.contact_rows = int(sum(sizes))
        self.struct.contact_wsize = int(sum(b * b for b in sizes))
        self.struct.contact_blocks = len(sizes)
        self.contact_sizes = tuple(sizes)


def add_contact_part(h: np.ndarray, d: np.ndarray, w: np.ndarray, sizes) -> None:
    """Add the rows' curvature term Σ_j D_jᵀ W_j D_j to ``h`` (n × n) in place.

    Over the blocks j whose W_j is not zero (``assembled_contact.contact_blocks``: D (R × n),
    w the b_j × b_j blocks column-major, b_j = ``sizes[j]``), as ``dlo_add_contact_part`` in C.
    """
    if not len(sizes):
        return
    b = np.asarray(sizes)
    at = np.concatenate(([0], np.cumsum(b * b)))
    row = np.concatenate(([0], np.cumsum(b)))
    carrying = np.flatnonzero(np.add.reduceat(np.abs(w), at[:-1]) > 0)
    for j in carrying.tolist():
        k = int(b[j])
        dj = d[row[j] : row[j] + k]
        h += dj.T @ (w[at[j] : at[j + 1]].reshape(k, k, order="F") @ dj)


class WithNodePart:
    """A compiled split function called as the whole one: Eᵀ W added back.

    A compiled split function (``StringNLP.kkt_free_split_fn``, ``kkt_split_fn``) called as the
    whole one: its output W dropped and Eᵀ W added to the top-left n × n block of output
    ``target`` (K, ∇²L), one product per ``NodeBlocks`` group, and the full one's curvature
    blocks of sizes ``contact`` (``add_contact_part``) (numpy: each below OpenBLAS's
    threshold for threads), so that the evaluations Python makes (a saddle's escape, the
    derivatives at an adopted start, the stability check of a state without them) take the same
    shortcut as the compiled loops.  Not re-entrant (the split function's buffers): callers
    serialise calls, as for ``compiled.NativeFunction``.
    """

    def __init__(self, split, blocks: NodeBlocks, target: int, contact: tuple[int, ...] = ()):
        self._split, self._target, self._contact = split, target, contact
        self._groups = [
            (rows, cols, np.ascontiguousarray(block.T)) for rows, cols, block in blocks.groups
        ]

    def __call__(self, *args: np.ndarray) -> list[np.ndarray]:
        out = self._split(*args)
        if len(out) == 8:  # the full one (``kkt_split_fn``): its rows' curvature blocks last
            *out, weighted, d, w = out
        else:
            *out, weighted = out
            d = None
        h = out[self._target]
        n = weighted.shape[1]
        for rows, cols, block_t in self._groups:
            h[cols, :n] += block_t @ weighted[rows]
        if d is not None and d.size:
            add_contact_part(h[:n, :n], d, w.ravel(), self._contact)
        return out


#: the most multiplications (m·n·k) of one dgemm in ``dlo_add_node_part``: below OpenBLAS's
#: threshold for threads (65536 · 4), whose workers would spin on the other core between calls
CHUNK_WORK = 150_000
