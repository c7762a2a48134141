"""The element mesh of one NLP: the scene's a-priori breakpoints, or a refinement's layout.

A scene fixes breakpoints in advance (``structure.breakpoints``: interior grips, point loads,
relative positions' ends, material knots).  A refinement (adaptive h/p) may add breakpoints where
the solution turns out to have a kink and choose the LGL nodes of each element; it says so with a
:class:`MeshSpec`, which is part of the NLP's structure (a new spec is a new NLP).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model.elements import ElementMesh
from ...model.problem import Problem
from ..options import SolverOptions
from .structure import breakpoints

#: breakpoints closer than this fraction of L are one (as in ``ElementMesh``)
MERGE = 1e-9


@dataclass(frozen=True)
class MeshSpec:
    """A mesh chosen by a refinement: every interior breakpoint [m] and each element's nodes.

    ``breakpoints`` must hold the scene's own (``structure.breakpoints``); ``counts`` has one
    entry per element (len(breakpoints) + 1), each at least 3, or is None for the default share-out
    of ``solver.order`` by element length.
    """

    breakpoints: tuple[float, ...] = ()
    counts: tuple[int, ...] | None = None


def quadrature_extra(options: SolverOptions) -> int:
    """Return the Clenshaw–Curtis nodes per element beyond its LGL nodes.

    n_e + 8 quadrature nodes resolve the normalised director fields to the accuracy of the basis;
    collocated LGL does not (bench/results/director_convergence.md).
    """
    return max(2, min(8, options.quadrature_nodes - options.order))


def element_mesh(
    problem: Problem, options: SolverOptions, spec: MeshSpec | None = None
) -> ElementMesh:
    """Return the element mesh of ``problem`` with ``options``, or the one ``spec`` chose.

    Raise ValueError when ``spec`` leaves out one of the scene's breakpoints (a refinement made for
    another scene structure) or its counts do not match its elements.
    """
    L = problem.string.length
    extra = quadrature_extra(options)
    own = breakpoints(problem)
    if spec is None:
        return ElementMesh(L, own, options.order, extra)
    chosen = np.asarray(spec.breakpoints, dtype=float)
    missing = [s for s in own if not np.any(np.abs(chosen - s) <= MERGE * L)]
    if missing:
        raise ValueError(
            f"mesh: the refinement's breakpoints leave out the scene's at s = {missing} m"
        )
    return ElementMesh(L, chosen, options.order, extra, counts=spec.counts)


def mesh_spec(mesh: ElementMesh) -> MeshSpec:
    """Return the spec that rebuilds ``mesh`` exactly (its interior breakpoints and counts)."""
    return MeshSpec(
        tuple(float(b) for b in mesh.breakpoints[1:-1]), tuple(int(n) for n in mesh.counts)
    )
