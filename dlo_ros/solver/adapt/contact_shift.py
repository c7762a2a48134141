"""The centreline error of a contact point held at mesh nodes rather than where it touches.

With the obstacle rows on the mesh nodes (``solver.obstacle_points: nodes``) a point contact
(a cable on a post) pushes at one row s_j, or at two neighbouring rows, while the exact contact
is where the centreline is tangent to the obstacle's surface.  The strong-form residual
(``results/element_error.py``) takes the force where the answer applies it, so this error is
invisible to it.

The shape does not stay put while the contact slides: a cable hanging past a post swings about
it (on the main job's last pose 1.3 m of centreline per m of contact shift, while the shape with
the contact row held responds with 0.24 m/m, and the answer's own tangency −g'/g'' points the
wrong way).  So the error is measured along the family of equilibria whose contact is *pinned*
at arc length c (the point x(c) on the surface, the force there free, every other row as at the
answer):

* the family: σ∇f(z) + μ ∇_z v(z; c) + J_Aᵀ λ_A = 0, v(z; c) = h(x(c; z)) + r = 0, the other
  active rows held; μ = σ λ with λ [N] the contact's push (its force over −∇h), σ the
  objective's scale (``StringNLP.sigma``).  The answer is its member at c₀, the force-weighted
  arc length of the contact's rows (two rows' forces about c₀ make no couple to first order).
* its tangent: K [dz/dc; dλ/dc] = [−μ ∂_c∇_z v; −∂_c v; 0] with K the KKT matrix of the NLP
  at the answer over its active rows, the contact's rows replaced by v's (the Hessian keeps the
  rows' curvature, which stands for v's to first order).
* the exact contact is where the family is tangent to the surface: τ(c) = ∂_c v = 0.  One Newton
  step from c₀: Δc = −τ / (dτ/dc), dτ/dc = ∂²_c v + ∂_c∇_z v · dz/dc.
* the answer is not quite the family's member at c₀ when its force sits on two rows about c₀
  (they hold the shape down at both): the step onto it, K [Δz; Δλ] = [Σ_rows J_kᵀ λ_k; −v(c₀)],
  moves the rows' forces to the one row at c₀ (zero for a contact on one row at c₀).
* the error: max_s |∂x(s)/∂z · (Δz + Δc dz/dc)| on the grid.  Without the step onto the family
  the paper's Fig. 3 streamed at ρ = 1000 (a touch between two rows 3 mm apart) had an estimate
  10.9x its true error (the bound allows 10x); with it, 3.7x.

test_post_last_pose.py checks the step and the error against an exact contact reference.  ∂_c by
central differences at ``STEP`` · L, ∂/∂z by central differences of the centreline's tangents
at ``Z_STEP`` (:class:`PositionJacobian`).

A line contact (a strip lying on a floor) has the same error at its ends: the concentrated force
where it lifts off sits at the run's first or last row.  Its family pins that row's point at c
(the run's other rows held), and the exact lift-off is where the bending moment is continuous:
zero curvature relative to the surface on the free side, τ(c) = v''(c±) = 0 (one-sided
differences at ``END_STEP`` · L).  Rows hovering less than ``HOVER`` · L above the surface
between pressed rows belong to the run.  Where the strip lies flat the family barely moves with
c, so a run end's error is also measured by the step from the answer to the end row moved to
c₀ + Δc (its force there, the run's other rows held), and the larger of the two is taken: Fig. 3
streamed at 1e-6 L, ρ = 1000, pressed 0.8 mm past its lift-off with an estimate of 5.2e-6 m for
a true error of 2.7e-5 m; the moved end gives 2.5e-5 m.

:func:`contact_shift_error` sums the errors over the point contacts and lists where each
touches, c₀ + Δc, where the step is no longer than the bracket of rows about the contact (a kink
for the refinement to split at; a longer step is a first-order guess on a coarse mesh).  Contact
slots (``contact/obstacle_slots.py``) are point contacts too, each on its own row, taken here as
pinned at σ with the plain row h(x(σ)) + r (their row bounds the closest approach near σ,
``build/slot_envelope.py``: the same where the string is tangent at σ, as the slot rounds leave
it to within the slot tolerance).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..results.contacts import row_forces
from ..update.kkt import active_rows, kkt_step

#: the difference step in c [fraction of L]
STEP = 1e-5
#: the longest run of active rows [fraction of L] taken for one point contact when it has more
#: than two rows (rows crowded about a contact point by the refinement all touch)
POINT_EXTENT = 1e-3
#: rows between two pressed rows closer than this to the surface [fraction of L] join them in
#: one contact (the paper's Fig. 3 strip at ρ = 1000: three rows 0.15–0.35 µm above its floor
#: split its run in two, and its lift-off passed for a point touch); results/contacts.py reports
#: loads with a tighter ROW_TOUCH
HOVER = 1e-6
#: the difference step of a run end's one-sided v'' and its derivative in c [fraction of L]
END_STEP = 1e-4
#: the difference step in z (unknowns of order one: unit quaternions, tangents, positions / L)
Z_STEP = 1e-6
#: a line contact's end rows pressing less than this part of the largest push in that end's half
#: of the run are not its end: the end is the row of the concentrated force at the lift-off
END_SHARE = 0.05


@dataclass(frozen=True)
class ContactShift:
    """error_m [m]: Σ max_s |δx(s)| over the point contacts; touches: c₀ + Δc of each [m].

    parts: (c₀ [m], that contact's error [m]) of each point contact counted.
    """

    error_m: float
    touches: tuple[float, ...]
    parts: tuple[tuple[float, float], ...] = ()


@dataclass(frozen=True)
class PointContact:
    """One pinned contact of an answer: obstacle index, its NLP rows, c₀ [m], total force [N].

    side: 0 for a point contact (where it touches, τ = v'(c) = 0); +1 or −1 for the last or
    first row of a line contact, whose free side is after or before it (where it lifts off,
    τ = v''(c±) = 0: the bending moment is continuous there, and zero curvature relative to the
    surface along the run).  bracket: the arc lengths of the rows on either side [m].
    """

    obstacle: int
    rows: np.ndarray
    s: float
    force: np.ndarray
    bracket: tuple[float, float]
    side: int = 0


@dataclass(frozen=True)
class ContactFamily:
    """The pinned family's step at one contact: Δc [m], dz/dc [1/m], and the error [m]."""

    shift: float
    dz: np.ndarray
    error_m: float


def point_contacts(nlp, problem, state, g: np.ndarray) -> list[PointContact]:
    """Return the answer's point contacts: short runs of active rows, and filled slots.

    ``g``: the NLP's rows at the answer (which rows are active: ``update/kkt.active_rows``).  A
    run of one or two rows, or of more within ``POINT_EXTENT`` · L, is one point contact; a longer
    run is a line load (``results/contacts.py``).
    """
    lam = np.asarray(state.lam_g, dtype=float)
    if not nlp.obstacle_rows or not lam.size:
        return []
    active = active_rows(nlp, lam, np.asarray(g, dtype=float).ravel())
    lam_si = lam / (nlp.row_scale * nlp.sigma)
    s_rows, length = np.asarray(nlp.obstacle_s, dtype=float), nlp.length
    x = np.asarray(nlp.model.positions(state.z, s_rows)).reshape(-1, 3)
    out = []
    for i, rows in enumerate(nlp.obstacle_rows):
        ob, rows = problem.obstacles[i], np.asarray(rows)
        push = lam_si[rows]
        if nlp.obstacle_slots:  # a row a contact slot replaces holds no force
            push = push * state.p[nlp.params[f"samples:{i}:on"]]
        pressed = (push > 0) & active[rows]
        # a row within HOVER of the surface joins the stretch it is in even when it holds no
        # force: a run whose rows lift by a fraction of a micrometre ends at its last row
        gap = -ob.h_many(x) - problem.string.radius
        on = np.flatnonzero(pressed | (gap <= HOVER * length))
        # consecutive rows, or rows closer than POINT_EXTENT · L (crowded about one contact)
        apart = (np.diff(on) != 1) & (np.diff(s_rows[on]) > POINT_EXTENT * length)
        for run in np.split(on, np.flatnonzero(apart) + 1) if on.size else []:
            run = run[pressed[run]]  # its rows that press, from the first to the last
            if not run.size:
                continue
            if len(run) > 2 and s_rows[run[-1]] - s_rows[run[0]] > POINT_EXTENT * length:
                out += _run_ends(nlp, ob, i, rows, run, x, push, s_rows)
                continue
            force = row_forces(nlp, ob, x[run], push[run])
            w = np.linalg.norm(force, axis=1)
            out.append(
                PointContact(
                    i,
                    rows[run],
                    float(w @ s_rows[run] / w.sum()),
                    force.sum(axis=0),
                    row_bracket(s_rows, s_rows[run[0]], s_rows[run[-1]], length),
                )
            )
        out += _slot_contacts(nlp, problem, i, state, lam_si, active)
    return out


def _run_ends(nlp, ob, i, rows, run, x, push, s_rows) -> list[PointContact]:
    """Return the first and last rows of a line contact as pinned run ends (not at a grip).

    A lift-off carries a concentrated force, the largest push in its half of the run (the
    paper's Fig. 3 at ρ = 2000: 500–900 N beside 0.1–10 N per row of the distributed weight).
    Rows beyond it pressing less than END_SHARE of it are not the end: past a lift-off the strip
    leaves the surface by (s − s*)³, and rows crowded there by the refinement hover within the
    solver's tolerance, pressing 1e-5 to 1.6e-3 of the lift-off's force in a decaying sequence;
    pinned at such a row, the family's step estimated 0.003–0.05 m (at 1.4e-3: 9.6e-4 m) for a
    true error of 5e-7–2.8e-6 m.  Two rows sharing the force (the lift-off between them) both
    press above END_SHARE: the outer one is the end.
    """
    half = len(run) // 2  # (a run of three rows or more, point_contacts)
    first, last = push[run[:half]], push[run[half:]]
    start = int(np.flatnonzero(first >= END_SHARE * np.max(first))[0])
    stop = half + int(np.flatnonzero(last >= END_SHARE * np.max(last))[-1])
    run = run[start : stop + 1]
    length, out = nlp.length, []
    for j, side in ((run[0], -1), (run[-1], 1)):
        s = float(s_rows[j])
        if min(s, length - s) <= END_STEP * length * 4:
            continue
        out.append(
            PointContact(
                i,
                rows[[j]],
                s,
                row_forces(nlp, ob, x[[j]], push[[j]])[0],
                row_bracket(s_rows, s, s, length),
                side,
            )
        )
    return out


def _slot_contacts(
    nlp, problem, i: int, state, lam_si: np.ndarray, active: np.ndarray
) -> list[PointContact]:
    """Return obstacle i's filled contact slots as point contacts."""
    if not nlp.slot_rows:
        return []
    rows, lay = np.asarray(nlp.slot_rows[i]), nlp.params
    touch = np.flatnonzero((lam_si[rows] > 0) & (state.p[lay[f"slots:{i}:on"]] > 0))
    touch = touch[active[rows[touch]]]
    if not touch.size:
        return []
    ob, s = problem.obstacles[i], state.p[lay[f"slots:{i}:s"]]
    x = np.asarray(nlp.model.positions(state.z, s[touch])).reshape(-1, 3)
    forces = row_forces(nlp, ob, x, lam_si[rows[touch]])
    return [
        PointContact(i, rows[[k]], float(s[k]), f, (0.0, nlp.length))
        for k, f in zip(touch, forces)
    ]


def row_bracket(rows: np.ndarray, first: float, last: float, length: float) -> tuple[float, float]:
    """Return the arc lengths [m] of the rows just before ``first`` and after ``last``.

    0 and L where no row is on that side.
    """
    before, after = rows[rows < first - 1e-12], rows[rows > last + 1e-12]
    return (
        float(before.max()) if before.size else 0.0,
        float(after.min()) if after.size else length,
    )


class PositionJacobian:
    """x(s) and ∂x(s)/∂z at one answer z, for any s, from one sweep of differences over z.

    The models' centreline is linear in their tangents at the quadrature nodes:
    x(s) = x₀(z) + W(s) T(z)ᵀ (``positions_at_rows``).  So central differences of (x₀, T) over
    z, taken once (2n evaluations at ``Z_STEP``, on the first call), give every
    ∂x(s)/∂z = ∂x₀/∂z + W(s) ∂Tᵀ/∂z by a product.  One answer's contacts ask at several sets of
    arc lengths; each used to take its own 2n evaluations.
    """

    def __init__(self, model, z: np.ndarray):
        self.model, self.z = model, np.asarray(z, dtype=float)
        self._sweep: np.ndarray | None = None  # (1 + M, 3, n): ∂x₀/∂z, then ∂Tᵀ/∂z

    def at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return x(s) (len(s), 3) and ∂x(s)/∂z (len(s), 3, len(z))."""
        w = self.model.position_rows(np.asarray(s, dtype=float))
        x = np.asarray(self.model.positions_at_rows(self.z, w)).reshape(-1, 3)
        sweep = self._differences(w.shape[1])
        return x, sweep[0][None] + np.einsum("pm,mik->pik", w, sweep[1:])

    def positions(self, s: np.ndarray) -> np.ndarray:
        """Return x(s) (len(s), 3) [m]."""
        w = self.model.positions_at_rows(self.z, self.model.position_rows(np.asarray(s, float)))
        return np.asarray(w).reshape(-1, 3)

    def _differences(self, m: int) -> np.ndarray:
        if self._sweep is None:
            shifted = getattr(self.model, "shifted_tangents", None)  # director models: batched
            self._sweep = (
                self._batched(shifted(self.z, Z_STEP)) if shifted is not None else self._swept(m)
            )
        return self._sweep

    def _swept(self, m: int) -> np.ndarray:
        """Return the sweep by ``positions_at_rows`` at z ± Z_STEP e_k, one k at a time."""
        z, n = self.z, self.z.size
        rows = np.vstack([np.zeros((1, m)), np.eye(m)])  # x₀, then x₀ + each tangent
        sweep = np.empty((1 + m, 3, n))
        step = np.zeros(n)
        for k in range(n):
            step[k] = Z_STEP
            plus = np.asarray(self.model.positions_at_rows(z + step, rows))
            minus = np.asarray(self.model.positions_at_rows(z - step, rows))
            diff = (plus - minus) / (2 * Z_STEP)
            diff[1:] -= diff[0]  # the tangents' rows without x₀'s part
            sweep[:, :, k] = diff
            step[k] = 0.0
        return sweep

    def _batched(self, tangents: np.ndarray) -> np.ndarray:
        """``_swept``'s numbers, bit for bit, from the tangents at every z ± Z_STEP e_k.

        ``tangents``: (2, n, 3, M), ``shifted_tangents``; ``positions_at_rows`` of the rows
        [0; I] is x₀ L, then x₀ L + each tangent; the rest is elementwise, over every k at once.
        """
        z, n, length = self.z, self.z.size, self.model.length
        own = np.arange(3)  # the unknowns x₀ itself: z[0:3]
        sides = []
        for sign, t in ((1.0, tangents[0]), (-1.0, tangents[1])):
            x0 = np.repeat(z[None, 0:3], n, axis=0)  # x₀ of each shifted z, (n, 3)
            x0[own, own] = z[own] + sign * Z_STEP
            x0 = x0 * length
            sides.append(
                np.concatenate([x0[:, None, :] + 0.0, x0[:, None, :] + np.swapaxes(t, 1, 2)], 1)
            )
        diff = (sides[0] - sides[1]) / (2 * Z_STEP)  # (n, 1 + M, 3)
        diff[:, 1:] -= diff[:, :1]  # the tangents' rows without x₀'s part
        return np.ascontiguousarray(np.moveaxis(diff, 0, -1))


def pinned_family(
    nlp,
    problem,
    state,
    contact: PointContact,
    grid: np.ndarray,
    kkt=None,
    jacobian: PositionJacobian | None = None,
):
    """Return the pinned family's Newton step at ``contact`` (module docstring), or None.

    None at an end of the string (the grip decides where it touches) or where the KKT matrix is
    singular.  ``kkt``: ``nlp.kkt_fn``'s outputs at the answer, and ``jacobian``: the
    centreline's at the answer, when the caller has them.
    """
    length, z = nlp.length, np.asarray(state.z, dtype=float)
    c = contact.s + STEP * length * np.array([-1.0, 0.0, 1.0])
    # a run end's one-sided stencil: τ at c₀ ∓ δ and c₀, each on 4 points toward the free side
    big = END_STEP * length
    ends = contact.s + np.add.outer(np.array([-big, 0.0, big]), contact.side * big * np.arange(4))
    if min(c[0], ends.min()) < 0.0 or max(c[2], ends.max()) > length:
        return None
    if kkt is None:
        kkt = tuple(np.asarray(a) for a in nlp.kkt_fn(z, state.p, state.lam_g))
    _, g, jac, hess, _ = kkt
    ob, n = problem.obstacles[contact.obstacle], z.size
    points = np.concatenate([c, ends[1]]) if contact.side else c
    jacobian = jacobian or PositionJacobian(nlp.model, z)
    x, jx = jacobian.at(points)
    grads = np.asarray(nlp.obstacle_gradient[ob.type](x.T, ob.params)).reshape(3, -1).T
    v = ob.h_many(x) + problem.string.radius
    gz = np.einsum("pi,pik->pk", grads, jx)  # ∇_z v at c₀ − h, c₀, c₀ + h (and the stencil)
    step = c[1] - c[0]
    v_c = float(v[2] - v[0]) / (2 * step)  # ∂_c v
    v_cz = (gz[2] - gz[0]) / (2 * step)  # ∂_c∇_z v
    if contact.side == 0:  # τ = ∂_c v
        tau, tau_c, tau_z = v_c, (v[2] - 2 * v[1] + v[0]) / step**2, v_cz
    else:  # τ = v''(c±), one-sided, second order: (2, −5, 4, −1) / H²
        weights = np.array([2.0, -5.0, 4.0, -1.0]) / big**2

        def at(s: np.ndarray) -> np.ndarray:
            return ob.h_many(jacobian.positions(s))

        tau = float(weights @ v[3:])
        tau_c = float(weights @ at(ends[2]) - weights @ at(ends[0])) / (2 * big)
        tau_z = weights @ gz[3:]
    push = -float(contact.force @ grads[1]) / float(grads[1] @ grads[1])
    held = active_rows(nlp, state.lam_g, np.asarray(g).ravel())
    held[contact.rows] = False
    rows = np.vstack([np.asarray(jac)[held], gz[1][None, :]])
    prim = np.zeros(rows.shape[0])
    prim[-1] = v_c
    # K [dz; dλ] = [−μ ∂_c∇_z v; −∂_c v], solved as Newton's steps are (update/kkt.py)
    step = kkt_step(np.asarray(hess), rows, nlp.sigma * push * v_cz, prim)
    if step is None:
        return None
    dz = step[:n]
    slope = tau_c + float(tau_z @ dz)
    if not np.isfinite(slope) or slope == 0.0:
        return None
    shift = float(-tau / slope)
    # the answer onto the family's member at c₀: its rows' forces moved to the one row at c₀ (two
    # rows bracketing the touch hold the shape there); a contact on one row is that member already
    swap = None if len(contact.rows) == 1 else _moved_onto(state, kkt, held, contact, gz[1], v[1])
    steps = [shift * dz + (swap if swap is not None else 0.0)]
    if contact.side and abs(shift) <= contact.bracket[1] - contact.bracket[0]:
        # a run end: also the step to its row moved to the predicted lift-off
        x, jx = jacobian.at(np.array([contact.s + shift]))
        grad = np.asarray(nlp.obstacle_gradient[ob.type](x.T, ob.params)).reshape(3, -1).T
        value = float(ob.h_many(x)[0] + problem.string.radius)
        moved = _moved_onto(state, kkt, held, contact, grad[0] @ jx[0], value)
        if moved is not None:
            steps.append(moved)
    return ContactFamily(shift, dz, max(_centreline_change(nlp, z, d, grid) for d in steps))


def _moved_onto(state, kkt, held, contact: PointContact, row: np.ndarray, value: float):
    """Return Δz from the answer to the equilibrium with the contact's force at one row instead.

    ``row``: ∇_z v there, ``value``: v there; the other active rows (``held``) held.  One KKT
    step, K [Δz; Δλ] = [Σ_rows J_kᵀ λ_k; −value] (None where K is singular).
    """
    _, _, jac, hess, _ = kkt
    lam = np.asarray(state.lam_g, dtype=float)
    rows = np.vstack([np.asarray(jac)[held], row[None, :]])
    onto = np.zeros(rows.shape[0])
    onto[-1] = value
    dual = -np.asarray(jac)[contact.rows].T @ lam[contact.rows]
    step = kkt_step(np.asarray(hess), rows, dual, onto)
    return None if step is None else step[: row.size]


def _centreline_change(nlp, z: np.ndarray, dz: np.ndarray, grid: np.ndarray) -> float:
    """Return max_s |∂x(s)/∂z · dz| on the grid [m] (central differences along dz)."""
    size = float(np.linalg.norm(dz))
    if size == 0.0:
        return 0.0
    u, pos = dz / size, nlp.model.positions
    dx = (np.asarray(pos(z + Z_STEP * u, grid)) - np.asarray(pos(z - Z_STEP * u, grid))) / (
        2 * Z_STEP
    )
    return size * float(np.max(np.linalg.norm(dx, axis=1)))


def contact_shift_error(nlp, problem, state, grid: np.ndarray) -> ContactShift:
    """Return the centreline error [m] of the point contacts' positions (module docstring).

    ``nlp``: the solver's ``StringNLP``; ``problem``: the scene as the NLP sees it; ``state``:
    the answer (``SolverState``: z, p, lam_g); ``grid``: arc lengths [m] to measure δx on.
    Zero without point contacts; a contact whose family has no step (an end, a singular KKT
    matrix) is left out.
    """
    if not nlp.obstacle_rows:
        return ContactShift(0.0, ())
    kkt = tuple(np.asarray(a) for a in nlp.kkt_fn(state.z, state.p, state.lam_g))
    contacts = point_contacts(nlp, problem, state, kkt[1])
    if not contacts:
        return ContactShift(0.0, ())
    parts, touches, length = [], [], nlp.length
    jacobian = PositionJacobian(nlp.model, state.z)
    for contact in contacts:
        family = pinned_family(nlp, problem, state, contact, grid, kkt, jacobian)
        if family is None or family.shift == 0.0:
            continue
        parts.append((contact.s, family.error_m))
        lo, hi = contact.bracket
        if abs(family.shift) <= hi - lo:  # a step longer than the rows' bracket: first order only
            touches.append(float(np.clip(contact.s + family.shift, 0.0, length)))
    return ContactShift(sum(e for _, e in parts), tuple(touches), tuple(parts))
