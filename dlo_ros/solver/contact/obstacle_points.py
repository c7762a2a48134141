"""Where the obstacle rows sit along s, and the quadrature weight each row stands for.

``solver.obstacle_points`` chooses the arc lengths σ_j of the rows h_i(x(σ_j)) + r ≤ 0:

* 'samples': ``obstacle_samples`` uniformly spaced arc lengths (spacing L/(S − 1)), whatever the
  model's discretisation;
* 'nodes': the element mesh's own global LGL nodes (``ElementMesh.nodes``).  A mesh refined near a
  contact (``build/mesh.py`` ``MeshSpec``) then resolves the contact as finely as it resolves the
  shape, and no row is wasted where nothing touches.

Why the LGL nodes and not the quadrature nodes.  The unknowns of the element model are the nodal
values of the rotation field at the LGL nodes; an element with n nodes has n of them, and its
centreline x(s) is a polynomial of degree n fixed by x at the element's start and those n values.
Rows at its n LGL nodes are then as many as the element's unknowns, independent (LICQ holds on a
strip lying flat: x is fixed there by its node values and nothing more), and a breakpoint (a grip,
a load, a refinement's lift-off point) is a node, so a row sits exactly where an element ends.  The
n + 8 Clenshaw–Curtis quadrature nodes of the energy would be more rows than unknowns on an
element in contact along its length: dependent rows, whose multipliers are not unique.

The weights.  With x of degree n on an element, the element's LGL rule (exact to degree 2n − 3)
integrates any line load times a virtual displacement δx of the element's polynomial space
exactly, so on elements lying in contact along their whole length the multipliers are λ_j = q w_j
with q the line load [N/m] and w_j the global LGL weight of node j (the sum of both elements'
weights at a breakpoint).  ``row_weights`` returns those (for 'samples': the trapezoid rule's,
the first-order line load their multipliers stand for).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from ...model.elements import ElementMesh, element_mesh_of
from ...model.problem import Problem
from ..options import SolverOptions


def obstacle_arc_lengths(problem: Problem, options: SolverOptions, model: Any) -> np.ndarray:
    """Return the arc lengths [m] of the obstacle rows (empty without obstacles).

    'samples': ``obstacle_samples`` points over [0, L]; 'nodes': the model's element mesh nodes.
    Raise ValueError naming ``solver.obstacle_points`` when 'nodes' meets a model without a mesh.
    """
    if not problem.obstacles:
        return np.zeros(0)
    if options.obstacle_points == "samples":
        return np.linspace(0.0, problem.string.length, options.obstacle_samples)
    mesh = element_mesh_of(model)
    if mesh is None:
        raise ValueError(
            "solver.obstacle_points: 'nodes' needs an element model (model 'full' with rotation "
            f"'director', or basis 'elements'); the {type(model).__name__} has no element mesh"
        )
    return np.asarray(mesh.nodes, dtype=float).copy()


def lgl_weights(mesh: ElementMesh) -> np.ndarray:
    """Return the global LGL quadrature weight [m] of each mesh node (Σ = L).

    A breakpoint's weight is the sum of the end weights of the two elements it joins.
    """
    w = np.zeros(mesh.count)
    for first, el in zip(mesh.first, mesh.elements):
        w[first : first + el.count] += el.weights
    return w


def trapezoid_weights(s: np.ndarray) -> np.ndarray:
    """Return the composite trapezoid rule's weights [m] on the ascending arc lengths ``s``."""
    s = np.asarray(s, dtype=float)
    if s.size < 2:
        return np.zeros(s.size)
    h = np.diff(s)
    w = np.zeros(s.size)
    w[:-1] += 0.5 * h
    w[1:] += 0.5 * h
    return w


def row_weights(s: np.ndarray, options: SolverOptions, model: Any) -> np.ndarray:
    """Return the quadrature weight [m] of each obstacle row at arc lengths ``s``.

    'nodes': the mesh's LGL weights (exact line loads on elements in contact along their
    length, see the module docstring); 'samples': the trapezoid rule's.
    """
    mesh = element_mesh_of(model)
    if options.obstacle_points == "nodes" and mesh is not None and len(s) == mesh.count:
        return lgl_weights(mesh)
    return trapezoid_weights(s)


def row_spacing(s: np.ndarray) -> float:
    """Return the spacing [m] the slot placement measures in: the widest gap between rows.

    For uniform samples, exactly the first gap (the samples' spacing, as before the rows could
    sit on nodes); for nodes, the widest (a slot looks for a dip at least half of it wide).
    """
    return _row_spacing(np.asarray(s, dtype=float).tobytes())


@functools.lru_cache(maxsize=32)
def _row_spacing(s_bytes: bytes) -> float:
    """``row_spacing`` of the rows ``np.frombuffer(s_bytes)``: an NLP's rows ask every update."""
    s = np.frombuffer(s_bytes)
    if s.size < 2:
        return 0.0
    gaps = np.diff(s)
    first = float(gaps[0])
    return first if np.allclose(gaps, first, rtol=1e-9, atol=0.0) else float(gaps.max())


def nearest_row(s: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Return, for each arc length in ``sigma``, the index of the nearest row of ``s``."""
    s = np.asarray(s, dtype=float)
    sigma = np.atleast_1d(np.asarray(sigma, dtype=float))
    return np.argmin(np.abs(s[None, :] - sigma[:, None]), axis=1).astype(int)


#: consecutive pressing rows that carry a line load (``results/contacts.py``'s rule: two
#: neighbours may share one point contact that sits between them, three cannot)
LINE_RUN = 3
#: a row presses when its force exceeds this share of the largest: an interior-point answer
#: leaves ~1e-10 N of barrier multipliers on rows that do not touch
PRESSING_SHARE = 1e-6
#: rows that do not press between two that do, within one line load: a coarse mesh's shape
#: lying on a surface lifts off it between some nodes (the paper's Fig. 3 strip on 4 elements:
#: the rows of its run pressed with gaps of one or two)
LINE_GAP = 2


def carried_forces(
    src_s: np.ndarray,
    src_forces: np.ndarray,
    dst_s: np.ndarray,
    src_weights: np.ndarray | None = None,
    dst_weights: np.ndarray | None = None,
) -> np.ndarray:
    """Return the rows ``dst_s``' forces [N] when the rows ``src_s`` hand theirs on.

    A contact force stays where it acts when the rows move, as the rows on the nodes do between
    two meshes.  A point force (a run of fewer than LINE_RUN pressing rows, and a row that does
    not press) goes to the destination row nearest along s; forces landing on one row add up.
    A run of LINE_RUN or more pressing rows (with gaps of up to LINE_GAP rows that do not) is a
    line load q_j = f_j / w_j [N/m] at its pressing rows (w_j: the rows' quadrature weights,
    ``row_weights``; the trapezoid rule's on ``src_s`` / ``dst_s`` when not given): each
    destination row from the run's first to its last gets q, interpolated linearly along s
    between pressing rows, times its own weight, scaled so that the run's total force is kept
    (none inside: all of it to the row nearest the run's middle).  On a finer mesh every row of
    the run then holds its share of the load, not only the rows nearest the coarser mesh's
    (the paper's Fig. 3 strip on its floor: Newton from the refined mesh's start added the
    missing rows five at a time and gave up).
    Rows at the same arc lengths with the same weights copy their forces.
    """
    src_s, dst_s = np.asarray(src_s, dtype=float), np.asarray(dst_s, dtype=float)
    out = np.zeros(dst_s.size)
    forces = np.asarray(src_forces, dtype=float)
    if not out.size or not np.any(forces != 0.0):
        return out
    same_weights = (
        src_weights is None
        if dst_weights is None
        else src_weights is not None and np.array_equal(src_weights, dst_weights)
    )
    if same_weights and np.array_equal(src_s, dst_s):
        return forces.copy()
    pressing = forces > PRESSING_SHARE * max(float(forces.max()), 0.0)
    runs = [r for r in index_runs(np.flatnonzero(pressing), LINE_GAP) if r.size >= LINE_RUN]
    line = np.zeros(forces.size, dtype=bool)
    for run in runs:
        line[run[0] : run[-1] + 1] = True  # its gaps' tiny forces are part of the load
    points = np.flatnonzero((forces != 0.0) & ~line)
    if points.size:
        np.add.at(out, nearest_row(dst_s, src_s[points]), forces[points])
    if runs:
        w_src = trapezoid_weights(src_s) if src_weights is None else np.asarray(src_weights)
        w_dst = trapezoid_weights(dst_s) if dst_weights is None else np.asarray(dst_weights)
        for run in runs:
            total = forces[run[0] : run[-1] + 1].sum()
            _carry_line(out, src_s[run], forces[run] / w_src[run], total, dst_s, w_dst)
    return out


def _carry_line(
    out: np.ndarray,
    s: np.ndarray,
    q: np.ndarray,
    total: float,
    dst_s: np.ndarray,
    dst_weights: np.ndarray,
) -> None:
    """Add to ``out`` the line load q [N/m] at the run's rows ``s``, as ``carried_forces`` does."""
    span = 1e-12 * max(abs(float(s[-1])), 1.0)
    inside = np.flatnonzero((dst_s >= s[0] - span) & (dst_s <= s[-1] + span))
    share = np.interp(dst_s[inside], s, q) * dst_weights[inside]
    if not inside.size or not share.sum() > 0.0:
        out[nearest_row(dst_s, np.array([0.5 * (s[0] + s[-1])]))[0]] += total
        return
    out[inside] += share * (total / share.sum())


def index_runs(indices: np.ndarray, gap: int = 0) -> list[np.ndarray]:
    """Split ascending ``indices`` into runs with at most ``gap`` integers missing between two."""
    if not indices.size:
        return []
    return np.split(indices, np.flatnonzero(np.diff(indices) > 1 + gap) + 1)
