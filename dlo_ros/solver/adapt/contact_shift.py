"""The centreline error of a point contact held at a mesh node rather than where it touches.

With the obstacle rows on the mesh nodes (``solver.obstacle_points: nodes``) a point contact
(a post under a strip) pushes at a row s_j, while the exact contact is where the centreline is
tangent to the obstacle's surface.  The strong-form residual (``results/element_error.py``)
takes the force where the answer applies it, so this error is invisible to it (the strip on a
post of test_contact_auto.py at 1e-4 L: the row 1.9e-6 m from the contact, estimate 8.4e-8 m
against a true 2.5e-7 m).

What is used here, to first order:

* **the shift.**  Along the answer, the clearance g(s) = h(x(s)) + r to the obstacle is 0 at the
  row; the point it touches is where g' = 0, Δs = −g'(s_j)/g''(s_j) away (one Newton step;
  g', g'' by central differences at ``STEP`` · L).  Measured on the post: Δs = 2.07e-3 and
  2.31e-6 m against the reference's 1.75e-3 and 1.89e-6 m.  The touching point lies between
  the rows next to s_j (they hold g ≤ 0 while g(s_j) = 0, so g's largest value there is in
  that bracket): a step that leaves the bracket (g'' near 0, where a heavy string touches down
  on a floor: steps of centimetres, estimates of 9 mm against a true error of 0.3 mm on
  #37's table path) is replaced by the largest of g on ``BRACKET_GRID`` points of the bracket.
* **the load it stands for.**  A force P misplaced by Δs is the right force plus a couple of
  about P·Δs: in virtual work, the work of P moved from x(s_j) to x(s_j + Δs),
  φ(z) = P·(x(s_j + Δs; z) − x(s_j; z)).
* **the answer's response.**  Not a beam formula (a couple's centreline error ranges from
  P·Δs·L²/(2 Rf) on a cantilever to far less between two clamps): the answer's own linear
  response, with its grips and the active rows held (the contact row included: the strip still
  touches the post), K [δz; δλ] = [σ ∇φ; 0] with K the KKT matrix of the NLP at the answer
  (σ: the objective's scale, ``StringNLP.sigma``), and δx(s) = ∂x(s)/∂z · δz on the residual's
  grid.  ∇φ and ∂x/∂z · δz by central differences of ``model.positions``.

:func:`contact_shift_error` sums max_s |δx(s)| over the point contacts, and lists the points
s_j + Δs where they touch.  ``auto/mesh_check.py`` adds the error times ``SAFETY`` (the Newton
step's Δs came out 1.2 times the true one, and the response is first order).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..results.contacts import contact_loads
from ..update.kkt import active_rows

#: the difference step of g', g'' [fraction of L] (Δs agrees to 1e-4 relative from 1e-5 to 1e-3)
STEP = 1e-5
#: the difference step in z (unknowns of order one: unit quaternions, tangents, positions / L)
Z_STEP = 1e-6
#: points of the bracket between the neighbouring rows searched when the Newton step leaves it
BRACKET_GRID = 65


@dataclass(frozen=True)
class ContactShift:
    """error_m [m]: Σ max_s |δx(s)| over the point contacts; touches: s_j + Δs of each [m]."""

    error_m: float
    touches: tuple[float, ...]


def contact_shift(
    positions,
    ob,
    radius: float,
    s_j: float,
    length: float,
    bracket: tuple[float, float] | None = None,
) -> float:
    """Return Δs [m] from the row at ``s_j`` to where the answer is tangent to obstacle ``ob``.

    ``positions(s)``: the answer's centreline at the arc lengths s, (len(s), 3).  0 when the
    clearance is not curved towards the obstacle there (g'' ≥ 0: no touching point nearby).
    ``bracket``: the arc lengths [m] of the rows before and after the contact; a Newton step
    that leaves it gives way to the largest clearance on ``BRACKET_GRID`` points in it.
    """
    e = STEP * length
    s = np.clip(np.array([s_j - e, s_j, s_j + e]), 0.0, length)
    g = ob.h_many(positions(s)) + radius
    h1, h2 = s[1] - s[0], s[2] - s[1]
    if h1 <= 0 or h2 <= 0:  # a contact at an end: the end's grip decides where it touches
        return 0.0
    d1 = (g[2] - g[0]) / (h1 + h2)
    d2 = 2 * ((g[2] - g[1]) / h2 - (g[1] - g[0]) / h1) / (h1 + h2)
    if d2 >= 0:
        return 0.0
    shift = float(-d1 / d2)
    if bracket is None or bracket[0] <= s_j + shift <= bracket[1]:
        return shift
    grid = np.linspace(bracket[0], bracket[1], BRACKET_GRID)
    return float(grid[np.argmax(ob.h_many(positions(grid)))] - s_j)


def row_bracket(rows: np.ndarray, first: float, last: float, length: float) -> tuple[float, float]:
    """Return the arc lengths [m] of the rows just before ``first`` and after ``last``.

    0 and L where no row is on that side.
    """
    before, after = rows[rows < first - 1e-12], rows[rows > last + 1e-12]
    return (
        float(before.max()) if before.size else 0.0,
        float(after.min()) if after.size else length,
    )


def contact_shift_error(nlp, problem, state, grid: np.ndarray) -> ContactShift:
    """Return the centreline error [m] of the point contacts' positions (module docstring).

    ``nlp``: the solver's ``StringNLP``; ``problem``: the scene as the NLP sees it; ``state``:
    the answer (``SolverState``: z, p, lam_g); ``grid``: arc lengths [m] to measure δx on.
    Zero without point contacts; the KKT matrix singular: that contact's error is left out.
    """
    lam_si = state.lam_g / (nlp.row_scale * nlp.sigma) if state.lam_g.size else state.lam_g
    loads = [
        c
        for c in contact_loads(nlp, problem, state.z, state.p, lam_si)
        if c.kind == "point" and np.linalg.norm(c.force) > 0
    ]
    if not loads:
        return ContactShift(0.0, ())
    model, z, length = nlp.model, np.asarray(state.z, dtype=float), nlp.length

    def positions(zz, s):
        return np.asarray(model.positions(zz, np.asarray(s, dtype=float))).reshape(-1, 3)

    kkt = None
    total, touches = 0.0, []
    for load in loads:
        s_j = float(load.s[0])
        ob = problem.obstacles[load.obstacle]
        bracket = row_bracket(np.asarray(nlp.obstacle_s), s_j, float(load.s[-1]), length)
        shift = contact_shift(
            lambda s: positions(z, s), ob, problem.string.radius, s_j, length, bracket
        )
        if shift == 0.0:
            continue
        ends = np.clip([s_j, s_j + shift], 0.0, length)
        touches.append(float(ends[1]))
        if kkt is None:
            kkt = kkt_matrix(nlp, state)
        rhs = np.zeros(kkt.shape[0])
        rhs[: z.size] = nlp.sigma * work_gradient(positions, z, ends, load.force)
        try:
            dz = np.linalg.solve(kkt, rhs)[: z.size]
        except np.linalg.LinAlgError:
            continue
        size = float(np.linalg.norm(dz))
        if size == 0.0:
            continue
        u = dz / size
        dx = (positions(z + Z_STEP * u, grid) - positions(z - Z_STEP * u, grid)) / (2 * Z_STEP)
        total += size * float(np.max(np.linalg.norm(dx, axis=1)))
    return ContactShift(total, tuple(touches))


def work_gradient(positions, z: np.ndarray, ends: np.ndarray, force: np.ndarray) -> np.ndarray:
    """Return ∇_z of φ(z) = force · (x(ends[1]; z) − x(ends[0]; z)), by central differences."""

    def work(zz: np.ndarray) -> float:
        x = positions(zz, ends)
        return float(force @ (x[1] - x[0]))

    out = np.zeros(z.size)
    for k in range(z.size):
        step = np.zeros(z.size)
        step[k] = Z_STEP
        out[k] = (work(z + step) - work(z - step)) / (2 * Z_STEP)
    return out


def kkt_matrix(nlp, state) -> np.ndarray:
    """Return [∇²L J_Aᵀ; J_A 0] of the NLP at ``state`` over its active rows (``kkt.py``)."""
    z, lam, p = state.z, state.lam_g, state.p
    _, g, jac, hess, _ = (np.asarray(a) for a in nlp.kkt_fn(z, p, lam))
    idx = np.flatnonzero(active_rows(nlp, lam, g.ravel()))
    n, m = z.size, idx.size
    out = np.zeros((n + m, n + m))
    out[:n, :n] = hess
    out[:n, n:] = jac[idx].T
    out[n:, :n] = jac[idx]
    return out
