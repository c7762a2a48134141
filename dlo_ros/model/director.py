"""The 3D string without a pole: nodal unit quaternions (or unit tangents) on spectral elements.

Unknowns z = [x0/L (3), nodal values of the rotation field (4 N or 3 N), ε at the nodes (N, if
extensible)] on the ``ElementMesh`` (N global nodes, breakpoints at every interior grip, point load
and material kink).  Two kinds of rotation field:

* frame (twist modelled): q(s) = Σ_i ℓ_i(s) q_i, a polynomial through unit quaternions q_i
  (x, y, z, w) with |q_i|² = 1 imposed at every node.  Between nodes the rotation is that of q/|q|
  (any non-zero q is a rotation, so no direction is singular).  Body curvature and twist
  (R' = R [Ω]×, R = [t d1 d2]):

      Ω = 2 vec(q* ⊗ q') / |q|²  =  2 (w q'_v − w' q_v − q_v × q'_v) / |q|²,
      U_bend = ∫ ½ Rf (Ω_2² + Ω_3²) ds,   U_twist = ∫ ½ Rt Ω_1² ds;
  a strip (``lateral``: string.lateral_bend_stiffness R_l, frame only): ∫ ½ (Rf Ω_2² + R_l Ω_3²).

* tangent (twist not held: at most one clamp or Rt = 0, so the string untwists to Ω_1 ≡ 0):
  t(s) = Σ_i ℓ_i(s) t_i with |t_i|² = 1 at the nodes, unit tangent t/|t| and
      κ² = |(t/|t|)'|² = (|t'|² − (t·t')²/|t|²) / |t|²,   U_bend = ∫ ½ Rf κ² ds.

Both bend energies carry the gauge term ½ c Rf ((ln|v|)')² (v = q with a factor 2, or t;
c = GAUGE_WEIGHT): it vanishes where the interpolant keeps unit norm between nodes and is of the
order of the interpolation error squared when resolved, but it forbids a field that dips toward
zero between quadrature nodes, where the normalised rotation would jump unseen by the quadrature
(a fold that costs no energy).

Both: x(s) = x0 + ∫_0^s (1 + ε) t̂ ds,  U_stretch = ∫ ½ Re ε²,  U_grav = −∫ D ĝ·x ds, every
integral by the mesh's quadrature.  Grip orientations are held by rows that are linear in the
node's rotation (t_g · R_g e_y = t_g · R_g e_z = 0, and for a clamp with twist d1_g · R_g e_z = 0),
whose parameters are R_g itself: no angle is unwrapped and no pole exists.

Point moments M at s_k are dead loads; their work M·δθ is not the variation of any function of the
rotation, so it enters as the pseudo-potential W_M = M · θ_k with θ_k = 2 vec(q_k ⊗ q_ref*) (frame)
or t_ref × t_k (tangent: the part of M normal to the tangent), whose gradient equals M·δθ exactly
at
q_k = q_ref.  The solver substitutes q_ref = q_k/|q_k| after differentiating
(``solver/build/moments.py``), which gives the exact equilibrium equations, and solves those.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import casadi as ca
import numpy as np

from .centreline import positions_sym, weight_energy_sym
from .elements import ElementMesh
from .memo import ArrayMemo
from .mesh_geometry import geometry_vectors
from .quaternion_frames import (
    continuous_signs,
    frame_columns,
    frame_to_quat,
    quat_to_frame,
    tangent_column,
)
from .rotations import cross3
from .transport import transported_frames


#: weight of the gauge term ½ c Rf ((ln|v|)')² relative to the bend energy: large enough to forbid
#: a fold
#: hidden between quadrature nodes, small enough to leave the spectral accuracy
GAUGE_WEIGHT = 1e-2


@dataclass(frozen=True)
class DirectorLayout:
    """Where the unknowns sit in z."""

    nodes: int
    frame: bool
    stretch: bool
    order: int
    elements: int

    planar = False

    @property
    def twist(self) -> bool:
        return self.frame

    @property
    def width(self) -> int:
        """Components of the rotation field per node: 4 (quaternion) or 3 (tangent)."""
        return 4 if self.frame else 3

    @property
    def size(self) -> int:
        return 3 + self.nodes * (self.width + int(self.stretch))

    @property
    def rotation(self) -> slice:
        return slice(3, 3 + self.width * self.nodes)

    @property
    def eps(self) -> slice:
        start = 3 + self.width * self.nodes
        return slice(start, start + self.nodes)


def integrands(rows, drows, frame: bool):
    """Return the bend and twist integrands and the unit tangent of a rotation field.

    (b, τ, t̂) of the rotation field's values ``rows`` and s-derivatives ``drows`` (4 quaternion
    or 3 tangent components; CasADi scalars or row vectors, element-wise): U_bend = ∫ ½ Rf b ds,
    U_twist = ∫ ½ Rt τ ds (τ = 0 for the tangent model), t̂ the unit tangent (3 components).

    frame:   b = Ω_2² + Ω_3² + c Ω_0²,  τ = Ω_1²,  Ω = 2 (w q'_v − w' q_v − q_v × q'_v) / |q|²,
             Ω_0 = 2 q·q' / |q|² (the gauge term, c = GAUGE_WEIGHT: zero where |q| is constant,
             it keeps the interpolant from dipping toward q = 0 between quadrature nodes, a
             rotation jump the quadrature would not see);
    tangent: b = (|t'|² − (1 − c)(t·t')²/|t|²) / |t|²  = κ² + c ((ln|t|)')²  (the same gauge term).
    """
    if frame:
        o0, o1, o2, o3 = quaternion_rates(rows, drows)
        return o2 * o2 + o3 * o3 + GAUGE_WEIGHT * o0 * o0, o1 * o1, frame_columns(rows, ca)[0]
    n2 = rows[0] ** 2 + rows[1] ** 2 + rows[2] ** 2
    tdt = rows[0] * drows[0] + rows[1] * drows[1] + rows[2] * drows[2]
    dd = drows[0] ** 2 + drows[1] ** 2 + drows[2] ** 2
    inv = 1 / ca.sqrt(n2)
    return (
        (dd - (1 - GAUGE_WEIGHT) * tdt * tdt / n2) / n2,
        0,
        [rows[0] * inv, rows[1] * inv, rows[2] * inv],
    )


def quaternion_rates(rows, drows):
    """(Ω_0, Ω_1, Ω_2, Ω_3) of a quaternion field: ``integrands``' gauge rate and Ω (body)."""
    x, y, zq, wq = rows
    dx, dy, dz, dw = drows
    n2 = x * x + y * y + zq * zq + wq * wq
    o1 = 2 * (wq * dx - dw * x - (y * dz - zq * dy)) / n2
    o2 = 2 * (wq * dy - dw * y - (zq * dx - x * dz)) / n2
    o3 = 2 * (wq * dz - dw * zq - (x * dy - y * dx)) / n2
    return 2 * (x * dx + y * dy + zq * dz + wq * dw) / n2, o1, o2, o3


def strip_integrands(rows, drows):
    """Return (b_1, b_2, τ, t̂) of a strip's quaternion field (``integrands``' frame case split).

    U_bend = ∫ ½ (Rf b_1 + R_l b_2) ds with b_1 = Ω_2² + c Ω_0² (about d1, the soft axis, with
    ``integrands``' gauge term) and b_2 = Ω_3² (about d2, the lateral axis); τ = Ω_1².
    """
    o0, o1, o2, o3 = quaternion_rates(rows, drows)
    return o2 * o2 + GAUGE_WEIGHT * o0 * o0, o3 * o3, o1 * o1, frame_columns(rows, ca)[0]


class DirectorModel:
    """Maps z to fields, positions and energy terms (see module docstring)."""

    kind = "director"

    def __init__(
        self, length: float, mesh: ElementMesh, frame: bool, stretch: bool, lateral: bool = False
    ):
        if lateral and not frame:
            raise ValueError("a strip (lateral bend stiffness) needs the frame model")
        #: a strip: p carries "Rl", the stiffness about d2 (``strip_integrands``)
        self.lateral = lateral
        self.length = float(length)
        self.mesh = mesh
        self.layout = DirectorLayout(mesh.count, frame, stretch, mesh.order, mesh.element_count)
        self.B, self.dB = mesh.B, mesh.dB
        # the composite quadrature, under the names RitzModel's single-interval one has
        self.quad = SimpleNamespace(
            nodes=mesh.quad_nodes, weights=mesh.weights, count=mesh.quad_count
        )
        #: matrices per arc-length array, remembered: a solver asks for the same s again
        self._matrices: ArrayMemo = ArrayMemo()
        #: (z as bytes, ``quad_tangents(z)``, read-only) of the last z asked for: one update asks
        #: for the positions of its answer up to three times (slots, self-pass, the next start)
        self._tangents: tuple[bytes, np.ndarray] | None = None

    # ---- numpy ----------------------------------------------------------------------------------
    def node_values(self, z: np.ndarray) -> np.ndarray:
        """(N, 4) nodal quaternions or (N, 3) nodal tangents."""
        return np.asarray(z[self.layout.rotation]).reshape(self.layout.nodes, self.layout.width)

    def strain_nodes(self, z: np.ndarray) -> np.ndarray | None:
        return np.asarray(z[self.layout.eps]) if self.layout.stretch else None

    def position_matrix(self, s: np.ndarray) -> np.ndarray:
        """W(s) with x(s) = x0 + W(s) · (1+ε)t̂ at the quadrature nodes."""
        return self._matrices.get("W", s, self.mesh.integration_matrix)

    def position_rows(self, s: np.ndarray) -> np.ndarray:
        """Return W(s) as ``position_matrix`` does, not remembered (s changes every solve)."""
        return self.mesh.integration_matrix(s)

    def tangent_rows(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return (P, P') with x'(s) = T Pᵀ and x''(s) = T P'ᵀ (T: ``quad_tangents``)."""
        return self.mesh.quad_interpolation(s)

    def positions_at_rows(self, z: np.ndarray, w: np.ndarray) -> np.ndarray:
        """(len(w), 3) centreline positions [m] at the arc lengths whose rows of W are ``w``."""
        return (np.asarray(z[0:3]) * self.length)[None, :] + w @ self.quad_tangents(z).T

    def interpolation(self, s: np.ndarray, side: str = "left") -> tuple[np.ndarray, np.ndarray]:
        """``ElementMesh.interpolation``, remembered."""
        return self._matrices.get("B" + side, s, lambda x: self.mesh.interpolation(x, side))

    def quad_tangents(self, z: np.ndarray) -> np.ndarray:
        """(1 + ε) t̂ at the quadrature nodes, (3, M), read-only (the last z's is remembered)."""
        key = np.asarray(z, dtype=float).tobytes()
        last = self._tangents  # one read: another thread may replace it
        if last is not None and last[0] == key:
            return last[1]
        t = self._unit_tangents(self.B @ self.node_values(z))
        eps = self.strain_nodes(z)
        t = t if eps is None else t * (1 + self.B @ eps)[None, :]
        t.flags.writeable = False
        self._tangents = (key, t)
        return t

    def shifted_tangents(self, z: np.ndarray, step: float) -> np.ndarray:
        """``quad_tangents`` at z ± step·e_k for every unknown k: (2, n, 3, M), + first.

        The same numbers, bit for bit, as ``quad_tangents(z ± step e_k)`` one k at a time (each
        rotation unknown's is the same matrix product, batched, and the rest the same elementwise
        operations on stacked arrays), for the differences of the centreline over z
        (``adapt/contact_shift.PositionJacobian``).
        """
        z = np.asarray(z, dtype=float)
        lay = self.layout
        base = self.quad_tangents(z)
        out = np.broadcast_to(base, (2, z.size, *base.shape)).copy()  # x0's: T unchanged
        eps = self.strain_nodes(z)
        if eps is not None:  # the rotation unknowns' scale, and the strain unknowns' directions
            scale = (1 + self.B @ eps)[None, None, :]
            unit = self._unit_tangents(self.B @ self.node_values(z))
        rot = np.arange(z.size)[lay.rotation]
        for side, sign in enumerate((1.0, -1.0)):
            nodes = np.repeat(z[None, lay.rotation], rot.size, axis=0)
            nodes[np.arange(rot.size), np.arange(rot.size)] = z[rot] + sign * step
            v = np.matmul(self.B[None], nodes.reshape(rot.size, lay.nodes, lay.width))
            t = self._unit_tangents(v)
            out[side, rot] = t if eps is None else t * scale
            if eps is not None:
                shifted = np.repeat(eps[:, None], eps.size, axis=1)  # column j: eps ± step e_j
                shifted[np.arange(eps.size), np.arange(eps.size)] = eps + sign * step
                scales = [1 + self.B @ shifted[:, j] for j in range(eps.size)]
                out[side, lay.eps] = unit[None] * np.stack(scales)[:, None, :]
        return out

    def _unit_tangents(self, v: np.ndarray) -> np.ndarray:
        """t̂ (…, 3, M) of the rotation field's values v (…, M, width) at the quadrature nodes."""
        if self.layout.frame:
            return np.moveaxis(tangent_column(np.moveaxis(v, -1, 0)), 0, -2)
        return np.swapaxes(v / np.linalg.norm(v, axis=-1)[..., None], -1, -2)

    def positions(self, z: np.ndarray, s: np.ndarray) -> np.ndarray:
        """(len(s), 3) centreline positions [m]."""
        return self.positions_with(z, s, self.quad_tangents(z))

    def positions_with(self, z: np.ndarray, s: np.ndarray, tangents: np.ndarray) -> np.ndarray:
        """``positions`` from the tangents (1 + ε) t̂ at the quadrature nodes (3, M) given.

        E.g. as the compiled outputs' function evaluated them at z (``output_function.py``): the
        same expressions, equal to rounding.
        """
        return (np.asarray(z[0:3]) * self.length)[None, :] + self.position_matrix(s) @ tangents.T

    def tangents_at(self, z: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return the unit tangents (len(s), 3)."""
        v = self.interpolation(s)[0] @ self.node_values(z)
        if self.layout.frame:
            return tangent_column(v.T).T
        return v / np.linalg.norm(v, axis=1)[:, None]

    def pose_frames(
        self, z: np.ndarray, s: np.ndarray, anchor: tuple[float, np.ndarray] | None = None
    ) -> np.ndarray:
        """Return the pose frames (len(s), 3, 3) at s, columns (t, d1, d2): x along the tangent.

        The tangent model has no roll: its frames are transported without twist (d1' = −(t'·d1) t)
        from ``anchor`` = (s_a, R_a) (default: d1 ⊥ t closest to the world z-axis at s = 0), on a
        grid four times finer than s.
        """
        s = np.asarray(s, dtype=float)
        if self.layout.frame:
            return quat_to_frame(self.interpolation(s)[0] @ self.node_values(z))
        s_anchor, r_anchor = anchor if anchor is not None else (0.0, None)
        fine = np.unique(
            np.concatenate([np.linspace(0.0, self.length, 4 * max(len(s), 16) + 1), s, [s_anchor]])
        )
        t = self.tangents_at(z, fine)
        k0 = int(np.argmin(np.abs(fine - s_anchor)))
        if r_anchor is None:
            hint = np.array([0.0, 0.0, 1.0]) if abs(t[k0, 2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        else:
            hint = r_anchor[:, 1]
        return transported_frames(t, k0, hint)[np.searchsorted(fine, s)]

    def curvature(self, z: np.ndarray, s: np.ndarray, side: str = "left") -> np.ndarray:
        """Return the body Darboux vector Ω = (twist, κ_d1, κ_d2) [1/m] at s, (len(s), 3).

        Frame model only (the tangent model has no body frame: ``world_curvature``).
        """
        if not self.layout.frame:
            raise ValueError("the tangent model has no body frame; use world_curvature")
        b, db = self.interpolation(s, side)
        v, dv = b @ self.node_values(z), db @ self.node_values(z)
        qv, w, dqv, dw = v[:, :3], v[:, 3:], dv[:, :3], dv[:, 3:]
        n2 = np.sum(v * v, axis=1)[:, None]
        return 2 * (w * dqv - dw * qv - cross3(qv, dqv)) / n2

    def world_curvature(self, z: np.ndarray, s: np.ndarray, side: str = "left") -> np.ndarray:
        """Return the world-frame Darboux vector at s.

        World-frame Darboux vector: R Ω (frame model) or t̂ × t̂' (tangent model, no twist),
        (len(s), 3).
        """
        if self.layout.frame:
            b = self.interpolation(s, side)[0]
            return np.einsum(
                "kij,kj->ki", quat_to_frame(b @ self.node_values(z)), self.curvature(z, s, side)
            )
        b, db = self.interpolation(s, side)
        v, dv = b @ self.node_values(z), db @ self.node_values(z)
        n = np.linalg.norm(v, axis=1)[:, None]
        t = v / n
        dt = (dv - np.sum(t * dv, axis=1)[:, None] * t) / n
        return cross3(t, dt)

    # ---- CasADi ---------------------------------------------------------------------------------
    def material_sizes(self) -> dict[str, int]:
        """Return the sizes of p's slices ``material_terms`` fills."""
        M = self.mesh.quad_count
        return {"weight_moments": M, "weight_total": 1, "mesh:j": M, "mesh:w": M}

    def material_terms(self, profiles: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Return the gravity terms that depend on the material alone, and the mesh's geometry.

        Σ_j w_j D_j x(σ_j) = x0 ΣwD + Σ_k m_k (1+ε_k) t_k with m = W(σ)ᵀ (w ∘ D), assembled
        once; and the geometry vectors j = 2/h and w at the quadrature nodes, which the assembled
        KKT functions read (``model/mesh_geometry.py``, ``solver/build/mesh_parameters.py``).
        """
        wd = self.mesh.weights * profiles["D"]
        j, w = geometry_vectors(self.mesh)
        return {
            "weight_moments": self.position_matrix(self.mesh.quad_nodes).T @ wd,
            "weight_total": np.array([wd.sum()]),
            "mesh:j": j,
            "mesh:w": w,
        }

    def quad_nodes(self) -> np.ndarray:
        return self.mesh.quad_nodes

    def _fields_sym(self, z: ca.SX):
        lay = self.layout
        V = ca.reshape(z[lay.rotation], lay.width, lay.nodes)  # column i = node i
        # sparse: B selects nodes, B' is block-diagonal by element
        return (
            V,
            ca.mtimes(V, ca.sparsify(ca.DM(self.B.T))),
            ca.mtimes(V, ca.sparsify(ca.DM(self.dB.T))),
        )

    def energy_terms(self, z: ca.SX, profiles: dict[str, ca.SX], gravity: ca.SX):
        """Return the energies [J] and the quadrature-node tangents.

        (bend, twist, stretch, gravity) energies [J] and the quadrature-node tangents (1+ε)t̂
        (3×M).
        """
        lay, w = self.layout, ca.DM(self.mesh.weights)
        _, v, dv = self._fields_sym(z)
        rows = [v[k, :].T for k in range(lay.width)]
        drows = [dv[k, :].T for k in range(lay.width)]
        if self.lateral:
            b, b2, tw, tangent = strip_integrands(rows, drows)
            bend = 0.5 * ca.dot(w, profiles["Rf"] * b + profiles["Rl"] * b2)
        else:
            b, tw, tangent = integrands(rows, drows, lay.frame)
            bend = 0.5 * ca.dot(w, profiles["Rf"] * b)
        twist = 0.5 * ca.dot(w, profiles["Rt"] * tw) if lay.frame else ca.SX(0)
        t = ca.horzcat(*tangent).T
        if lay.stretch:
            eps = ca.mtimes(ca.sparsify(ca.DM(self.B)), z[lay.eps])
            stretch = 0.5 * ca.dot(w, profiles["Re"] * eps * eps)
            t = t * ca.repmat(ca.reshape(1 + eps, 1, -1), 3, 1)
        else:
            stretch = ca.SX(0)
        grav = weight_energy_sym(
            z[0:3] * self.length, t, profiles["weight_total"], profiles["weight_moments"], gravity
        )
        return bend, twist, stretch, grav, t

    def positions_sym(self, z: ca.SX, t: ca.SX, s: np.ndarray) -> ca.SX:
        return positions_sym(z[0:3] * self.length, t, self.position_matrix(s))

    def node_sym(self, z: ca.SX, i: int) -> ca.SX:
        lay = self.layout
        return z[lay.rotation][lay.width * i : lay.width * (i + 1)]

    def node_columns_sym(self, z: ca.SX, i: int) -> tuple[ca.SX, ca.SX | None]:
        """(t, d1) at node i (d1 None for the tangent model)."""
        v = self.node_sym(z, i)
        if self.layout.frame:
            t, d1, _ = frame_columns([v[0], v[1], v[2], v[3]], ca)
            return ca.vertcat(*t), ca.vertcat(*d1)
        return v / ca.norm_2(v), None

    def norm_rows_sym(self, z: ca.SX) -> list[ca.SX]:
        """|v_i|² − 1 at every node."""
        V = ca.reshape(z[self.layout.rotation], self.layout.width, self.layout.nodes)
        return [ca.sumsqr(V[:, i]) - 1.0 for i in range(self.layout.nodes)]

    def fold_rows_sym(self, z: ca.SX) -> list[ca.SX]:
        """Return the constraints that forbid a fold between neighbouring nodes.

        c − v_i · v_{i+1} ≤ 0 for neighbouring nodes: neighbouring tangents within 90° (c = 0),
        neighbouring quaternions within a 120° rotation and of one sign (c = cos 60°).  Inactive on
        any resolved shape; they forbid a fold between two nodes, which the normalised field would
        hide from the quadrature (its energy is not seen between quadrature nodes).
        """
        lay = self.layout
        V = ca.reshape(z[lay.rotation], lay.width, lay.nodes)
        c = 0.5 if lay.frame else 0.0
        return [c - ca.dot(V[:, i], V[:, i + 1]) for i in range(lay.nodes - 1)]

    def moment_work_sym(self, z: ca.SX, i: int, moment: ca.SX, reference: ca.SX) -> ca.SX:
        """Return the pseudo-potential of a point moment at node i.

        Pseudo-potential of a point moment at node i (module docstring); ``reference`` is q_ref
        (4) for the frame model, t_ref (3, in the first 3 of 4 entries) for the tangent model.
        """
        return self.moment_work_node_sym(self.node_sym(z, i), moment, reference)

    def moment_work_node_sym(self, v: ca.SX, moment: ca.SX, reference: ca.SX) -> ca.SX:
        """``moment_work_sym`` of the node value v (4 or 3)."""
        if self.layout.frame:
            # vec(q ⊗ q_ref*) = −q_w r_v ... for p = q, r* = (−r_v, r_w): vec = p_w(−r_v) + r_w p_v
            # + p_v × (−r_v)
            pv, pw, rv, rw = v[0:3], v[3], reference[0:3], reference[3]
            theta = 2 * (rw * pv - pw * rv - ca.cross(pv, rv))
            return ca.dot(moment, theta)
        t = v / ca.norm_2(v)
        return ca.dot(moment, ca.cross(reference[0:3], t))

    # ---- guesses and transfers ------------------------------------------------------------------
    def z_from_frames(
        self, x0: np.ndarray, frames: np.ndarray, eps: np.ndarray | None = None
    ) -> np.ndarray:
        """Return z from the position of s = 0 and the pose frames at the nodes.

        z from the position of s = 0 and pose frames (N, 3, 3) (columns t, d1, d2) at the
        nodes.
        """
        z = np.zeros(self.layout.size)
        z[0:3] = np.asarray(x0, dtype=float) / self.length
        if self.layout.frame:
            vals = continuous_signs(frame_to_quat(frames))
        else:
            vals = frames[:, :, 0]
        z[self.layout.rotation] = vals.ravel()
        if self.layout.stretch:
            z[self.layout.eps] = 0.0 if eps is None else eps
        return z
