"""What a converged compiled Newton loop evaluates in the same call beyond the loop.

What a converged compiled Newton loop evaluates in the same call beyond the loop: the obstacle
rows' values and the outputs' function (``UpdateOutputs``), and those outputs as a result uses them
(``ComputedOutputs``).
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass

import numpy as np


@dataclass
class ComputedOutputs:
    """The outputs' function's values as a converged loop evaluated them.

    The outputs' function's values (``output_function.OutputFunction``: points, orientations,
    grip forces and torques, contact forces, residual, flip) as a converged loop evaluated them,
    with the inputs it evaluated them at: a result uses them only for the same (z, p, λ_SI, prof)
    (``matches``).
    """

    z: np.ndarray
    p: np.ndarray
    lam_si: np.ndarray
    prof: np.ndarray
    values: list[np.ndarray]

    def matches(self, z: np.ndarray, p: np.ndarray, lam_si: np.ndarray, prof: np.ndarray) -> bool:
        """Whether these are the outputs at (z, p, λ_SI, prof) (``same`` arrays each)."""
        return (
            same(self.z, z)
            and same(self.p, p)
            and same(self.lam_si, lam_si)
            and (self.prof is prof or np.array_equal(self.prof, prof))
        )


def same(a: np.ndarray, b: np.ndarray) -> bool:
    """``np.array_equal`` of two arrays (nan unequal), without its conversions: one of them."""
    return a is b or (a.shape == b.shape and bool((a == b).all()))


class _AfterStruct(ctypes.Structure):
    """dlo_after in the drivers' C (native/dlo_common.h)."""

    _fields_ = [
        ("obstacle", ctypes.c_void_p),
        ("outputs", ctypes.c_void_p),
        ("obstacle_work", ctypes.c_void_p),
        ("outputs_work", ctypes.c_void_p),
        ("rows", ctypes.c_int),
        ("free_rows", ctypes.c_int),
        ("ub", ctypes.c_void_p),
        ("lam_div", ctypes.c_void_p),
        ("prof", ctypes.c_void_p),
        ("g", ctypes.c_void_p),
        ("lam_si", ctypes.c_void_p),
        ("out", ctypes.c_void_p * 8),
        ("done", ctypes.c_int),
    ]


class UpdateOutputs:
    """What a converged loop evaluates in the same call, beyond the loop.

    What a converged loop evaluates in the same call, so that a warm update is one compiled
    call: the obstacle rows' values (``StringNLP.obstacle_g_fn``; the contact-free loop, whose
    system leaves them out) and, when none is violated, the outputs' function
    (``output_function.py``) at the answer, with λ_SI = λ / (row_scale · σ) and the string's
    profiles ``prof``.  Both are generated functions of their own libraries
    (``compiled.NativeFunction``), called by address: neither loop's library is rebuilt when they
    arrive.  Either may be None (not compiled yet): the caller then evaluates what is missing.  Not
    re-entrant: the loops' callers serialise calls.
    """

    def __init__(self, nlp, obstacle, outputs):
        rows = int(nlp.lbg.size)
        self.rows = rows
        self._ub = np.ascontiguousarray(nlp.ubg, dtype=float)
        # λ_SI = λ / (row_scale · σ), divided as ShapeOutputs divides (the same rounding:
        # ComputedOutputs.matches)
        self._div = (
            np.ascontiguousarray(nlp.row_scale * nlp.sigma, dtype=float) if rows else np.zeros(0)
        )
        self._g, self._lam_si = np.zeros(max(rows, 1)), np.zeros(max(rows, 1))
        self._prof: np.ndarray | None = None
        # (the prof last given, its address) when it is itself contiguous floats (no copy read
        # instead): a stream's profiles are one array (``OutputFunction.profiles``, per string)
        self._prof_given: tuple | None = None
        self._shapes = outputs.out_shapes if outputs is not None else []
        self._out = [np.zeros(max(r * c, 1)) for r, c in self._shapes]
        self._struct = _AfterStruct()
        st = self._struct
        st.rows, st.free_rows = rows, nlp.n_free_rows
        st.ub, st.lam_div, st.g, st.lam_si = (
            a.ctypes.data for a in (self._ub, self._div, self._g, self._lam_si)
        )
        for i, a in enumerate(self._out):
            st.out[i] = a.ctypes.data
        self._functions = (obstacle, outputs)  # kept alive for the addresses
        self.obstacle = obstacle.address() if obstacle is not None else None
        self.outputs = outputs.address() if outputs is not None else None
        if self.obstacle is not None:
            st.obstacle, st.obstacle_work = self.obstacle
        self.address = ctypes.addressof(st)

    def prepare(self, prof: np.ndarray | None) -> int:
        """Prepare a call: evaluate the outputs when ``prof`` is given; the struct's address.

        Before a call: the outputs are evaluated when ``prof`` is given (the profiles of the
        string being solved for); the struct's address.
        """
        st = self._struct
        st.done = 0
        if prof is None or self.outputs is None:
            st.outputs = st.outputs_work = None
            self._prof = None
        else:
            st.outputs, st.outputs_work = self.outputs
            given = self._prof_given
            if given is None or given[0] is not prof:
                held = np.ascontiguousarray(prof, dtype=float)
                given = (held, held.ctypes.data)
                self._prof_given = given if held is prof else None
            self._prof = given[0]
            st.prof = given[1]
        return self.address

    def collect(
        self, z: np.ndarray, p: np.ndarray
    ) -> tuple[np.ndarray | None, ComputedOutputs | None]:
        """Collect after a converged call at (z, p): (every row's value, the outputs).

        After a converged call at (z, p): (every row's value, the outputs), each None if not
        evaluated (the values only from the contact-free loop, which evaluates its obstacle
        rows).
        """
        done = self._struct.done
        g = self._g[: self.rows].copy() if done & 1 else None
        if not done & 2:
            return g, None
        assert self._prof is not None  # the outputs are evaluated only when prof was given
        values = [
            out[: r * c].reshape((r, c), order="F").copy()
            for out, (r, c) in zip(self._out, self._shapes)
        ]
        return g, ComputedOutputs(
            z.copy(),
            np.array(p, dtype=float),
            self._lam_si[: self.rows].copy(),
            self._prof,
            values,
        )
