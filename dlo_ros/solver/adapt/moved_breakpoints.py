"""A mesh of the same topology with breakpoints moved onto contact points inside elements.

A point contact inside an element is a jump of the internal force that the element's polynomial
cannot follow.  Splitting there (``rule.py``) adds an element, hence a new NLP to build; moving
the nearer end of that element onto the contact keeps every element's node count, so the NLP's
functions serve the moved mesh too (``build/mesh_clone.py``: a clone, no build).  A contact that
slides along an obstacle is followed this way, one move per check.

A breakpoint may move when it is interior, not one of the scene's own (grips, loads, relative
positions' ends, material knots) and not moved already in this pass, and when both elements it
bounds stay at least ``min_size`` long.
"""

from __future__ import annotations

import numpy as np

from ..build.mesh import MERGE, MeshSpec


def moved_onto(
    spec: MeshSpec, length: float, points, fixed=(), min_size: float = 0.0
) -> MeshSpec | None:
    """Return ``spec`` with a breakpoint moved onto each of ``points`` [m] inside an element.

    For each point, the nearer end of the element holding it that may move (module docstring);
    the same counts.  None when a point has no such end (the caller splits instead) or when no
    point lies inside an element.
    """
    bounds = np.concatenate([[0.0], np.asarray(spec.breakpoints, dtype=float), [length]])
    locked = np.zeros(bounds.size, dtype=bool)
    locked[[0, -1]] = True
    for s in fixed:  # the scene's own breakpoints stay
        locked |= np.abs(bounds - s) <= MERGE * length
    moved = False
    for c in sorted(float(s) for s in points):
        k = int(np.searchsorted(bounds, c)) - 1  # the element [b_k, b_k+1] holding c
        k = min(max(k, 0), bounds.size - 2)
        if min(c - bounds[k], bounds[k + 1] - c) <= MERGE * length:
            continue  # on a breakpoint already
        ends = sorted((k, k + 1), key=lambda i: abs(bounds[i] - c))
        for i in ends:
            if locked[i]:
                continue
            lo, hi = bounds[i - 1], bounds[i + 1]
            if c - lo >= min_size and hi - c >= min_size:
                bounds[i], locked[i], moved = c, True, True
                break
        else:
            return None
    if not moved:
        return None
    return MeshSpec(tuple(float(b) for b in bounds[1:-1]), spec.counts)
