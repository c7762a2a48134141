"""The linking number of a clamped ribbon along a stream: Lk = Tw + Wr, in numpy.

Lk = Tw + Wr is the Călugăreanu–White theorem; everything here is pure numpy.

A string clamped at both ends with its twist modelled is a ribbon: the centreline x(s) and the
director d1(s) of its frame (t, d1, d2).  Closed in a fixed way through the clamps (each clamp's
tangent ray to infinity, d1 carried along it unturned), its linking number

    Lk = Tw + Wr,   Tw = (1/2π) ∫ (d1' · d2) ds = (1/2π) ∫ Ω_1 ds,
                    Wr = (1/4π) ∬ (t₁ × t₂)·(x₁ − x₂)/|x₁ − x₂|³

is an integer that cannot change while the string deforms continuously without passing through
itself and the clamps hold still.  A clamp turned by α about its own tangent adds α/2π (the
string's twist follows; the closure at infinity absorbs it).  A discretised model has no such
guarantee: a solver that lands far from its start may have released whole turns of twist without
the centreline ever coming near itself (issue #15: three turns released in one warm IPOPT update).

Between two shapes of a stream (``link_change``):

    ΔLk = ΔTw + ΔWr − (α_end − α_start)/2π

must stay near 0; a change near a whole number means a jump to another topological branch.

* ΔTw: each shape's twist, the discrete parallel-transport twist of its frames at fine samples
  (``twist``: the signed angle about t_{i+1} from d1_i transported by the minimal rotation t_i →
  t_{i+1} to d1_{i+1}; exact for a uniformly twisted circle or straight line, O(h²) in general).
* ΔWr: Fuller's formula relative to the previous shape (``fuller_writhe_change``),

      Wr₁ − Wr₀ = (1/2π) ∫ (t₀ × t₁)·(t₀' + t₁') / (1 + t₀·t₁) ds,

  the solid angle swept by the geodesic homotopy of the tangent indicatrix, computed exactly per
  sample interval as the signed area of the spherical quadrilateral (t₀,i, t₀,i+1, t₁,i+1, t₁,i).
  It holds while t₀(s) ≠ −t₁(s) everywhere, and only mod 2 (Fuller 1978): it misses ±2 whenever the
  curves of the tangent homotopy pass through themselves — as they do in a large jump (measured: a
  twisted loop whose tangents turned 166° somewhere lost two turns of Lk, Fuller read 0).  So it is
  used only for small changes, every tangent turned less than 90° (``FULLER_ALIGNMENT``), where the
  homotopy stays near both shapes; it does not see the centreline passing through itself (the
  crossing checks of ``self_contact.py`` do), so ΔTw + ΔWr_Fuller is conserved through anything but
  a jump of the discrete frame field.  On the rays the tangents do not turn, so the closure adds
  nothing when the clamps' tangents stay put; when they turn, the closure's part is of the order of
  the solid angle their tangents swept / 2π (the stream's small moves keep it far below ½).
* For a larger change (a tangent turned 90° or more) the absolute Gauss writhe of each centreline
  extended by its clamps' tangent rays (length ``RAY_LENGTHS``
  × the span, ``ray_writhe``; exact for polylines, Klenin & Langowski 2000) is used instead, no mod
  2. That closure can be crossed by the string wrapping behind a clamp (a false alarm of ±1: only a
  big jump is judged this way, and a big jump is suspect anyway).
* The clamps' turns α: the signed angle about the new tangent from the old d1, transported by the
  minimal rotation old tangent → new tangent, to the new d1, in (−π, π] (a stream turns a clamp in
  steps smaller than half a turn).  A solver sums them over every target it was asked for since the
  committed shape (``ClampTurns``), failed updates included: after a run of failures the committed
  shape lags the clamps by more than half a turn, and one comparison would alias.
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field

import numpy as np

#: |ΔLk| above this (turns) is a jump to another branch (a change from continuous deformation is
#: near 0)
JUMP = 0.5

#: 1 + t₀·t₁ at or below this somewhere (a tangent turned 90° or more): Fuller's formula (mod 2) is
#: not used
FULLER_ALIGNMENT = 1.0

#: samples along the clamped span at which a solver compares two shapes (Tw and Fuller's writhe are
#: O(h²): a jump is a whole turn, the error at 401 samples a few 1e-4 turns on the twisted test
#: streams)
SAMPLES = 401

#: the clamps' tangent rays of ``ray_writhe``, in units of the span's length (the writhe they leave
#: out decays like 1/length)
RAY_LENGTHS = 200.0


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return a × b over the last axis.

    a × b over the last axis (numpy's cross costs more than the sums here on a few hundred
    rows).
    """
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def transport(v: np.ndarray, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """Turn v (…, 3) by the minimal rotation taking unit t0 to unit t1.

    v (…, 3) turned by the minimal rotation taking unit t0 to unit t1 (rows; Rodrigues with axis
    t0 × t1; antipodal t0 = −t1 has no minimal rotation and is turned about any axis ⊥ t0).
    """
    c = _dot(t0, t1)[..., None]
    k = _cross(t0, t1)
    # R v = c v + k × v + (k·v) k / (1 + c)  (the Rodrigues formula with sin θ k̂ = k, cos θ = c)
    return c * v + _cross(k, v) + _dot(k, v)[..., None] * k / np.maximum(1.0 + c, 1e-300)


def signed_angle(a: np.ndarray, b: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Angle (…) from a to b about ``axis`` (right hand), in (−π, π]; a, b ⊥ axis."""
    return np.arctan2(_dot(_cross(a, b), axis), _dot(a, b))


def twist(tangents: np.ndarray, d1: np.ndarray) -> float:
    """Return Tw [turns] of a ribbon sampled at unit tangents and directors along s.

    Tw [turns] of a ribbon sampled at (n, 3) unit tangents and directors along s (module
    docstring): Σ_i angle_{t_{i+1}}(P_i d1_i, d1_{i+1}) / 2π, P_i the minimal rotation t_i →
    t_{i+1}.
    """
    moved = transport(d1[:-1], tangents[:-1], tangents[1:])
    return float(np.sum(signed_angle(moved, d1[1:], tangents[1:])) / (2 * np.pi))


def _spherical_triangle(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Return the signed solid angle of the geodesic triangle a → b → c on the unit sphere.

    Signed solid angle (…) of the geodesic triangle a → b → c on the unit sphere (Van Oosterom &
    Strackee): 2 atan2(a·(b × c), 1 + a·b + b·c + c·a); positive when counter-clockwise seen from
    outside.
    """
    num = _dot(a, _cross(b, c))
    den = 1.0 + _dot(a, b) + _dot(b, c) + _dot(c, a)
    return 2.0 * np.arctan2(num, den)


def fuller_writhe_change(t0: np.ndarray, t1: np.ndarray) -> float:
    """Return Wr₁ − Wr₀ [turns] of two curves' unit tangents by Fuller's formula.

    Wr₁ − Wr₀ [turns] by Fuller's formula (module docstring) for unit tangents (n, 3) of two
    curves at the same samples along s: Σ_i of the signed area of the spherical quadrilateral t₀,i
    → t₀,i+1 → t₁,i+1 → t₁,i, over 2π; exact mod 2 while no t₁ = −t₀ (``link_change`` uses it only
    for small changes, ``min_alignment(t0, t1) > FULLER_ALIGNMENT``).
    """
    a, b, c, d = t0[:-1], t0[1:], t1[1:], t1[:-1]
    area = _spherical_triangle(a, b, c) + _spherical_triangle(a, c, d)
    return float(-np.sum(area) / (2 * np.pi))


def min_alignment(t0: np.ndarray, t1: np.ndarray) -> float:
    """Return min_s (1 + t₀·t₁): 0 where two tangents are antipodal.

    min_s (1 + t₀·t₁): 0 where two tangents are antipodal (Fuller's formula then breaks
    down).
    """
    return float(np.min(1.0 + _dot(t0, t1)))


def _segment_pair_solid_angles(p1, p2, p3, p4) -> np.ndarray:
    """Return Ω_ij of segment pairs: the signed solid angle one segment sees the other under.

    Ω_ij of segment pairs (p1 → p2, p3 → p4): the signed solid angle of the spherical
    quadrilateral swept by the unit vector from a point of the first segment to a point of the
    second, whose corners are the directions of p3 − p1, p4 − p1, p4 − p2, p3 − p2 (Klenin &
    Langowski 2000); Σ Ω / 4π over pairs is the Gauss integral, exactly for polylines.  Two
    geodesic triangles by Van Oosterom & Strackee's atan2 (``_spherical_triangle``), which stays
    exact where the four points are (nearly) coplanar.
    """
    a, b, c, d = (_unit(v) for v in (p3 - p1, p4 - p1, p4 - p2, p3 - p2))
    return -(_spherical_triangle(a, b, c) + _spherical_triangle(a, c, d))


def gauss_writhe(points: np.ndarray, closed: bool = False) -> float:
    """Return the writhe Wr of the closed polyline through ``points`` (Gauss double integral).

    Wr of the polyline through ``points`` (n, 3) (closed: the last point joins the first): the
    Gauss double integral, exact for a polyline, (1/4π) Σ_{i≠j} Ω_ij over non-adjacent segment
    pairs.
    """
    pts = np.vstack([points, points[:1]]) if closed else np.asarray(points)
    m = len(pts) - 1
    i, j = np.triu_indices(m, 2)
    if closed:
        keep = ~((i == 0) & (j == m - 1))  # the first and last segments share the closing vertex
        i, j = i[keep], j[keep]
    omega = _segment_pair_solid_angles(pts[i], pts[i + 1], pts[j], pts[j + 1])
    return float(2.0 * np.sum(omega) / (4 * np.pi))


def gauss_linking(a: np.ndarray, b: np.ndarray) -> float:
    """Return the linking number Lk of two closed polylines.

    Lk of two closed polylines (n, 3) and (m, 3): (1/4π) Σ_ij Ω_ij over all segment pairs; an
    integer up to rounding when the polylines do not meet.
    """
    pa, pb = np.vstack([a, a[:1]]), np.vstack([b, b[:1]])
    i, j = np.meshgrid(np.arange(len(a)), np.arange(len(b)), indexing="ij")
    i, j = i.ravel(), j.ravel()
    omega = _segment_pair_solid_angles(pa[i], pa[i + 1], pb[j], pb[j + 1])
    return float(np.sum(omega) / (4 * np.pi))


def ray_writhe(
    points: np.ndarray, tangents: np.ndarray, rays: float = RAY_LENGTHS, ray_segments: int = 64
) -> float:
    """Return the writhe of the centreline ``points`` extended by straight rays at both ends.

    Wr of the centreline ``points`` (n, 3) extended at both ends along its end ``tangents``
    (first and last rows) by straight rays of ``rays`` × its arc length, each cut into
    ``ray_segments`` geometrically growing pieces (only their directions matter to a straight ray;
    the pieces keep the Ω formula well conditioned next to the string).
    """
    span = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
    reach = np.geomspace(span / len(points), rays * span, ray_segments)
    before = points[0] - reach[::-1, None] * tangents[0]
    after = points[-1] + reach[:, None] * tangents[-1]
    return gauss_writhe(np.vstack([before, points, after]))


@dataclass(frozen=True)
class LinkChange:
    """ΔLk between two shapes of a clamped ribbon [turns], by its parts.

    ΔLk between two shapes of a clamped ribbon [turns] (module docstring): the twist and writhe
    changes, the turns the clamps added, and how the writhe was measured ('fuller' or 'rays').
    """

    twist: float
    writhe: float
    clamps: float
    method: str

    @property
    def unexplained(self) -> float:
        """Return ΔTw + ΔWr − clamps' turns: near an integer after a jump, near 0 otherwise.

        ΔTw + ΔWr − clamps' turns: near 0 for a continuous deformation, near an integer after a
        jump.
        """
        return self.twist + self.writhe - self.clamps

    @property
    def jumped(self) -> bool:
        return abs(self.unexplained) > JUMP


def clamp_turn(frame0: np.ndarray, frame1: np.ndarray) -> float:
    """Return the angle [rad] a clamp turned about its tangent between two frames.

    The angle [rad] a clamp turned about its tangent between frames (3, 3) (columns t, d1, d2):
    from the old d1 transported to the new tangent to the new d1, in (−π, π] (``transport`` and
    ``signed_angle`` on one vector, in floats: numpy's per-call cost is most of it at this
    size).
    """
    return _turn_of_rows(frame0.tolist(), frame1.tolist())


def _turn_of_rows(rows0: list, rows1: list) -> float:
    """Return ``clamp_turn`` of two frames given as nested lists of their rows."""
    (a0, a1, _), (b0, b1, _), (c0, c1, _) = rows0
    (p0, p1, _), (q0, q1, _), (r0, r1, _) = rows1
    t0, v, t1, d1 = (a0, b0, c0), (a1, b1, c1), (p0, q0, r0), (p1, q1, r1)
    c = _fdot(t0, t1)
    k = _fcross(t0, t1)
    kv, kxv = _fdot(k, v), _fcross(k, v)
    scale = kv / max(1.0 + c, 1e-300)
    moved = tuple(c * v[i] + kxv[i] + scale * k[i] for i in range(3))
    return math.atan2(_fdot(_fcross(moved, d1), t1), _fdot(moved, d1))


def _fdot(a: tuple, b: tuple) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _fcross(a: tuple, b: tuple) -> tuple:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _turn(frame0: np.ndarray | None, frame1: np.ndarray) -> float:
    """Return ``clamp_turn``, or 0 without a previous frame or for an unchanged one.

    ``clamp_turn``, 0 without a previous frame, and exactly 0 for an unchanged frame without
    computing it (a stream that moves grips without turning them: the usual case).
    """
    if frame0 is None or frame0 is frame1:
        return 0.0
    rows0, rows1 = frame0.tolist(), frame1.tolist()
    # (equal lists of floats: np.array_equal's answer, nan unequal to itself alike)
    if rows0 == rows1:
        return 0.0
    return _turn_of_rows(rows0, rows1)


@dataclass(frozen=True)
class ClampTurns:
    """How far [rad] each clamp has turned since the committed shape, and its last frame.

    How far [rad] each clamp (by grip name) has turned about its tangent over the targets
    requested since the committed shape, and the last requested frame (3, 3) of each.
    """

    frames: dict[str, np.ndarray]
    turns: dict[str, float] = field(default_factory=dict)

    def advanced(self, requested: dict[str, np.ndarray]) -> ClampTurns:
        """Return the turns after one more target.

        Turns after one more target: each clamp's step from its last requested frame
        (``clamp_turn``).
        """
        turns = {
            name: self.turns.get(name, 0.0) + _turn(self.frames.get(name), frame)
            for name, frame in requested.items()
        }
        return ClampTurns(dict(requested), turns)

    def committed(self) -> ClampTurns:
        """Return the turns of the new committed shape: none since it."""
        return ClampTurns(self.frames)


def link_change(
    points0: np.ndarray,
    frames0: np.ndarray,
    points1: np.ndarray,
    frames1: np.ndarray,
    clamp_turns: tuple[float, float] | None = None,
) -> LinkChange:
    """Return ΔLk from shape 0 to shape 1 of the span between two clamps.

    ΔLk from shape 0 to shape 1 of the span between two clamps, sampled at the same arc lengths
    from the first clamp (row 0) to the last (row −1): points (n, 3) [m] and frames (n, 3, 3)
    (columns t, d1, d2).  Writhe by Fuller's formula when every tangent turned less than 90°
    (``FULLER_ALIGNMENT``), else by the two shapes' ray-closed Gauss writhes.  ``clamp_turns``: the
    first and the last clamp's turns [rad] (``ClampTurns``); default: each end's ``clamp_turn``
    between the two shapes.
    """
    t0, t1 = frames0[:, :, 0], frames1[:, :, 0]
    d_twist = twist(t1, frames1[:, :, 1]) - twist(t0, frames0[:, :, 1])
    if clamp_turns is None:
        clamp_turns = (clamp_turn(frames0[0], frames1[0]), clamp_turn(frames0[-1], frames1[-1]))
    clamps = (clamp_turns[1] - clamp_turns[0]) / (2 * np.pi)
    if min_alignment(t0, t1) > FULLER_ALIGNMENT:
        return LinkChange(d_twist, fuller_writhe_change(t0, t1), clamps, "fuller")
    return LinkChange(d_twist, ray_writhe(points1, t1) - ray_writhe(points0, t0), clamps, "rays")
