"""The NLP's constraint rows g(z, p), written row by row, each with its scale, kind and bounds.

Rows come in this order (``StringNLP``'s module docstring): grips, relative positions, the director
model's unit-norm rows (every equality so far), then the inequalities: the director model's fold
rows, the obstacle rows, the obstacles' contact slots and the self-contact slots.  Each writer
below appends its rows to a ``ConstraintRows`` and returns their indices.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ...model.director import DirectorModel
from ...model.obstacles import OBSTACLE_TYPES, Obstacle
from ...model.problem import Grip, RelativePosition
from ...model.ritz import RitzModel
from .parameter_layout import ParameterLayout, slot_matrix
from .slot_envelope import envelope_value
from .structure import breakpoint_node


@dataclass
class ConstraintRows:
    """The rows written so far: expression / scale, scale, kind and bounds of each."""

    exprs: list[ca.SX] = field(default_factory=list)
    scale: list[float] = field(default_factory=list)
    kind: list[tuple] = field(default_factory=list)
    lower: list[float] = field(default_factory=list)
    upper: list[float] = field(default_factory=list)

    @property
    def count(self) -> int:
        """The number of rows written so far (the index the next row gets)."""
        return len(self.exprs)

    def add(
        self, expr: ca.SX, scale: float, kind: tuple, lower: float = 0.0, upper: float = 0.0
    ) -> None:
        """Append the row lower ≤ expr / scale ≤ upper of kind ``kind``."""
        self.exprs.append(expr / scale)
        self.scale.append(scale)
        self.kind.append(kind)
        self.lower.append(lower)
        self.upper.append(upper)


@dataclass(frozen=True)
class RowSymbols:
    """What rows are written in: the unknowns z, the parameters p and the model's structure."""

    z: ca.SX
    p: ca.SX
    #: the tangents at the quadrature nodes (3 × M), x(s) = x0 + T W(s)ᵀ
    t: ca.SX
    model: DirectorModel | RitzModel
    params: ParameterLayout
    length: float
    director: bool
    planar: bool
    twist: bool


def grip_rows(
    rows: ConstraintRows, sym: RowSymbols, grips: tuple[Grip, ...], grip_x: ca.SX, r0: np.ndarray
) -> tuple[dict[str, dict[str, list[int]]], dict[str, np.ndarray]]:
    """Write every grip's position rows and orientation rows.

    Returns, per grip name, the indices of its "position" and "angles" rows, and the axes of its
    position rows.
    """
    m, lay, L = sym.model, sym.params, sym.length
    by_grip: dict[str, dict[str, list[int]]] = {}
    grip_axes: dict[str, np.ndarray] = {}
    in_plane = r0[:, :2].T  # e1, e2
    for gi, g in enumerate(grips):
        indices: dict[str, list[int]] = {"position": [], "angles": []}
        target = sym.p[lay[f"grip:{g.name}:position"]]
        # A planar model moves out of its plane only through x0·n: one grip fixes that, and the
        # other grips' out-of-plane rows would repeat it (dependent rows break IPOPT's LICQ).
        axes = np.eye(3) if (not sym.planar or gi == 0) else in_plane
        for k, axis in enumerate(axes):
            indices["position"].append(rows.count)
            rows.add(
                ca.dot(ca.DM(axis), grip_x[:, gi] - target),
                L,
                ("grip", g.name, "position", tuple(np.round(axis, 12))),
            )
        grip_axes[g.name] = axes
        if sym.director:
            indices["angles"] = director_grip_rows(rows, sym, g)
            by_grip[g.name] = indices
            continue
        assert isinstance(m, RitzModel)
        angles = sym.p[lay[f"grip:{g.name}:angles"]]
        held = ["phi"] if sym.planar else ["phi", "theta"]
        names = {"clamp": held + ["psi"] if sym.twist else held, "tangent": held, "pin": []}[
            g.mode
        ]
        for k, name in enumerate(names):
            indices["angles"].append(rows.count)
            rows.add(m.angle_sym(sym.z, name, g.s) - angles[k], 1.0, ("grip", g.name, name, k))
        by_grip[g.name] = indices
    return by_grip, grip_axes


def director_grip_rows(rows: ConstraintRows, sym: RowSymbols, grip: Grip) -> list[int]:
    """Write a grip's orientation rows on a director model; return their indices.

    The rows are t·R_g e_y = t·R_g e_z = 0 (clamp, tangent) and d1·R_g e_z = 0 (clamp, twist
    modelled), at the grip's node.
    """
    m = sym.model
    assert isinstance(m, DirectorModel)
    first = rows.count
    node = breakpoint_node(m.mesh, grip.s)
    t, d1 = m.node_columns_sym(sym.z, node)
    frame = ca.reshape(sym.p[sym.params[f"grip:{grip.name}:frame"]], 3, 3)
    indices = []
    if grip.mode in ("clamp", "tangent"):
        rows.add(ca.dot(t, frame[:, 1]), 1.0, ("grip", grip.name, "t.d1", 0))
        rows.add(ca.dot(t, frame[:, 2]), 1.0, ("grip", grip.name, "t.d2", 1))
        indices += [first, first + 1]
    if grip.mode == "clamp" and sym.twist:
        assert d1 is not None  # the frame model carries d1 whenever twist is modelled
        rows.add(ca.dot(d1, frame[:, 2]), 1.0, ("grip", grip.name, "d1.d2", 2))
        indices.append(first + len(indices))
    return indices


def relative_rows(
    rows: ConstraintRows,
    sym: RowSymbols,
    relative: tuple[RelativePosition, ...],
    rel_x: ca.SX,
    axes: np.ndarray,
) -> list[list[int]]:
    """Write c_r · (x(s_b) − x(s_a) − offset) = 0 per relative position and axis c_r in ``axes``.

    Returns each relative position's row indices.  ``rel_x``: x(s_a), x(s_b) of each, in turn.
    """
    out: list[list[int]] = []
    for i, _ in enumerate(relative):
        off = sym.p[sym.params[f"relative:{i}"]]
        out.append([])
        for k, axis in enumerate(axes):
            out[-1].append(rows.count)
            rows.add(
                ca.dot(ca.DM(axis), rel_x[:, 2 * i + 1] - rel_x[:, 2 * i] - off),
                sym.length,
                ("relative", i, k),
            )
    return out


def director_rows(rows: ConstraintRows, sym: RowSymbols) -> None:
    """Write the director model's unit-norm rows (equalities), then its fold rows (≤ 0)."""
    m = sym.model
    assert isinstance(m, DirectorModel)
    for i, expr in enumerate(m.norm_rows_sym(sym.z)):
        rows.add(expr, 1.0, ("norm", i))
    # inequality rows (folds, then obstacles) come after every equality row
    for i, expr in enumerate(m.fold_rows_sym(sym.z)):
        rows.add(expr, 1.0, ("fold", i), -ca.inf, 0.0)


def obstacle_rows(
    rows: ConstraintRows,
    sym: RowSymbols,
    obstacles: tuple[Obstacle, ...],
    obs_x: ca.SX,
    samples: int,
    slots: int,
) -> list[list[int]]:
    """Write (h_i(x(σ_j)) + r)/L ≤ 0 per obstacle i and sample j; return each obstacle's rows.

    With contact slots (``slots`` > 0) a sample a slot replaces reads −1 ≤ 0
    (``contact/obstacle_slots.py``).
    """
    p, lay, L = sym.p, sym.params, sym.length
    out: list[list[int]] = []
    radius = p[lay["radius"]][0]
    for i, ob in enumerate(obstacles):
        indices = []
        h = OBSTACLE_TYPES[ob.type].h
        for j in range(samples):
            indices.append(rows.count)
            expr = h(obs_x[:, j], p[lay[f"obstacle:{i}"]]) + radius
            if slots:  # a sample replaced by a slot reads −1 ≤ 0 (obstacle_slots.py)
                on = p[lay[f"samples:{i}:on"]][j]
                expr = on * expr - (1 - on) * L
            rows.add(expr, L, ("obstacle", i, j), -ca.inf, 0.0)
        out.append(indices)
    return out


def slot_rows(
    rows: ConstraintRows,
    sym: RowSymbols,
    obstacles: tuple[Obstacle, ...],
    slots: int,
    reach: float,
) -> list[list[int]]:
    """Write each obstacle's contact slots' rows, on·v*(σ_k) − (1 − on) L ≤ 0, by 1/L.

    v* is h + r at the closest approach near σ_k (``slot_envelope.py``, Δ = ``reach`` [m]).
    Returns each obstacle's slot rows (an empty list without slots).
    """
    p, lay, L, t = sym.p, sym.params, sym.length, sym.t
    out: list[list[int]] = []
    radius = p[lay["radius"]][0]
    M = sym.model.quad.count
    for i, ob in enumerate(obstacles):
        if not slots:
            break
        on = p[lay[f"slots:{i}:on"]]
        w, d1, d2 = (slot_matrix(p, lay, i, slots, M, part) for part in "wtk")
        slot_x = ca.repmat(sym.z[0:3] * L, 1, slots) + ca.mtimes(t, w.T)
        slot_d1, slot_d2 = ca.mtimes(t, d1.T), ca.mtimes(t, d2.T)
        out.append([])
        for k in range(slots):
            out[-1].append(rows.count)
            reach_k = envelope_value(
                ob.type, slot_x[:, k], slot_d1[:, k], slot_d2[:, k], p[lay[f"obstacle:{i}"]],
                radius, reach,
            )  # fmt: skip
            rows.add(on[k] * reach_k - (1 - on[k]) * L, L, ("slot", i, k), -ca.inf, 0.0)
    return out


def self_contact_rows(rows: ConstraintRows, sym: RowSymbols, slots: int) -> list[int]:
    """Write the self-contact slots' rows (b_k − |T q_k|²)/L ≤ 0; return their indices.

    x(s_a) − x(s_b) = T q_k is linear in the tangents, whatever the pair.
    """
    M = sym.model.quad.count
    out: list[int] = []
    for k in range(slots):
        prm = sym.p[sym.params[f"self:{k}"]]
        gap = ca.mtimes(sym.t, prm[:M])
        out.append(rows.count)
        rows.add(prm[M] - ca.dot(gap, gap), sym.length, ("self", k), -ca.inf, 0.0)
    return out
