"""Where a shape on an element mesh cuts into its obstacles between the rows, and where it touches.

With ``solver.obstacle_points: nodes`` the rows h_i(x(s_j)) + r ≤ 0 hold at the mesh's nodes
s_j only; the centreline between them is the model's own interpolant, which may pass through an
obstacle (a post between two nodes).  :func:`contact_survey` evaluates that interpolant
(``model.positions``) at ``OVERSAMPLING`` points per node interval of every element and returns,
per element, the deepest cut h_i(x(s)) + r > 0 and the arc length where it is; and the contact
intervals: runs of rows within ``ACTIVE`` · L of an obstacle, with their first and last row (the
touch-down and lift-off points the rows resolve).

Both are where the curvature has a kink (a point force's jump of the internal force, or the ends
of a distributed contact): ``kinks`` lists them for the refinement rule (``adapt/rule.py``), which
splits an element there, so that a node lands where the contact is.  The cut's depth is an error
of the centreline of about its depth (``auto/mesh_check.py`` adds it to the estimate).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model.elements import ElementMesh

#: evaluation points per node interval of an element (the rows sit at the interval ends)
OVERSAMPLING = 8
#: a row within this fraction of L of an obstacle's surface is in contact
ACTIVE = 1e-6


@dataclass(frozen=True)
class ContactSurvey:
    """What :func:`contact_survey` found on one shape.

    depth_m (E,) [m]: per element the deepest cut h + r over its obstacles (≤ 0: none);
    deepest_s (E,) [m]: where it is; obstacle: the name of the obstacle of the deepest cut of all
    ('' without one); intervals: (s_start, s_end) [m] of each run of active rows, per obstacle
    in order (a point contact at one row has s_start == s_end).
    """

    depth_m: np.ndarray
    deepest_s: np.ndarray
    obstacle: str
    intervals: tuple[tuple[float, float], ...]

    @property
    def depth(self) -> float:
        """The deepest cut over all elements [m] (0 when the shape cuts nowhere)."""
        return float(max(np.max(self.depth_m, initial=0.0), 0.0))

    def kinks(self, mesh: ElementMesh) -> tuple[float, ...]:
        """Return the arc lengths [m] of the contact's kinks strictly inside an element.

        The deepest cut of each element that cuts, and the ends of each contact interval; those
        at a breakpoint (already a node between elements) are left out.
        """
        found = [float(s) for d, s in zip(self.depth_m, self.deepest_s) if d > 0]
        found += [float(s) for run in self.intervals for s in run]
        edge = 1e-9 * mesh.length
        inner = [
            s for s in found if np.min(np.abs(mesh.breakpoints - s)) > edge
        ]  # at a breakpoint it is a node between elements already
        return tuple(sorted(set(inner)))


def _runs(active: np.ndarray, s: np.ndarray) -> list[tuple[float, float]]:
    """Return (first, last) arc length of each run of consecutive True in ``active``."""
    out, start = [], None
    for j, on in enumerate(active):
        if on and start is None:
            start = j
        if start is not None and (not on or j == active.size - 1):
            last = j if on else j - 1
            out.append((float(s[start]), float(s[last])))
            start = None
    return out


def contact_survey(model, z: np.ndarray, mesh: ElementMesh, obstacles, radius: float):
    """Return the :class:`ContactSurvey` of the shape ``z`` of ``model`` on ``mesh``.

    obstacles: the obstacles of the model's NLP (``model.problem.Obstacle``: ``h_many``, name);
    radius: the string's radius r [m].
    """
    count = mesh.element_count
    depth, where = np.full(count, -np.inf), np.zeros(count)
    intervals: list[tuple[float, float]] = []
    if not obstacles:
        return ContactSurvey(np.zeros(count), where, "", ())
    dense = np.concatenate(
        [
            np.linspace(a, b, OVERSAMPLING * (el.count - 1) + 1)
            for a, b, el in zip(mesh.breakpoints[:-1], mesh.breakpoints[1:], mesh.elements)
        ]
    )
    which = mesh.element_of(dense)
    x = np.asarray(model.positions(z, dense)).reshape(-1, 3)
    x_rows = np.asarray(model.positions(z, mesh.nodes)).reshape(-1, 3)
    name, worst = "", -np.inf
    for ob in obstacles:
        cut = ob.h_many(x) + radius
        for e in range(count):
            on = which == e
            j = int(np.argmax(np.where(on, cut, -np.inf)))
            if cut[j] > depth[e]:
                depth[e], where[e] = cut[j], dense[j]
        if float(cut.max()) > worst:
            worst, name = float(cut.max()), ob.name
        gap = ob.h_many(x_rows) + radius
        intervals += _runs(gap > -ACTIVE * mesh.length, mesh.nodes)
    return ContactSurvey(depth, where, name if worst > 0 else "", tuple(intervals))
