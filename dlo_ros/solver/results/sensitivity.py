"""Sensitivities of an equilibrium to the material, by the implicit-function theorem.

The sensitivities are dx(s)/dθ and d(grip force)/dθ.

θ_k = log c_k, where the material profile k ∈ {Rf, Rt, Re, D, a strip's Rl} is scaled uniformly,
P_k(s) → c_k P_k(s); or, for a ``MaterialDirection`` with a ``change`` profile, any parameter θ
with dP/dθ (s) = change(s) (e.g. θ = log of one knot's value of a piecewise-linear table: change =
the table with every other value zero). At a converged state (z, λ) of the NLP the KKT residual
over the active rows a,

    F(z, λ_a; p) = [∇f(z; p) + J_a(z; p)ᵀ λ_a ;  g_a(z; p) − g_bound] = 0,

holds for every θ near the solution, so

    K [dz/dθ_k; dλ_a/dθ_k] = −∂F/∂p · dp/dθ_k,        K = [∇²L  J_aᵀ; J_a  0],

(the Newton matrix of ``newton.py``).  p is linear in the profiles' values at the quadrature nodes
(the assembled material terms are linear in them too), so dp/dθ_k is p's material part packed from
dP/dθ_k alone (for a uniform scale: profile k at its current values).  ∂F/∂p · v is one forward
derivative of a CasADi function (``jtimes``).

The centreline is x(s) = L z[0:3] + W(s) T(z) (T: the tangents at the quadrature nodes, W the
model's integration matrix), so dx(s)/dθ = L dz[0:3]/dθ + W(s) (∂T/∂z) dz/dθ, exact.  A grip's
force is F = −Aᵀ λ_SI on its position rows (``wrenches.wrench``), λ_SI = λ/(row_scale σ), so dF/dθ
follows from dλ/dθ.  A grip's torque (about the grip point) on a director model is T = −(λ0 t×a1 +
λ1 t×a2 [+ λ2 d1×a2]) from its orientation rows' multipliers, the grip node's frame (t, d1) and the
target frame [a0 a1 a2] (``wrenches.director_torque``); it is bilinear in ((t, d1), λ), so

    dT/dθ = T((∂t/∂z) dz/dθ, (∂d1/∂z) dz/dθ; λ) + T(t, d1; dλ/dθ),

with ∂(t, d1)/∂z exact (a CasADi function of the node's values, the expressions of the NLP's rows).
The planar model holds φ only: T = μ_φ n, dT/dθ = (dμ_φ/dθ) n.  The 3D Euler models' torques are
not differentiated (they are absent from ``grip_torques``).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ...model.profile import Profile
from ...model.rotations import quat_to_matrix
from ..update.kkt import active_rows
from ..build.mesh_clone import symbolic_nlp
from ..build.nlp import StringNLP
from ..shape_solver import ShapeSolver
from .wrenches import director_torque

#: material profiles a sensitivity can be taken with respect to, in the order of the NLP's
#: parameters (Rl: a strip's lateral bend stiffness, string.lateral_bend_stiffness; strips only)
MATERIALS = ("Rf", "Rt", "Re", "D", "Rl")


@dataclass(frozen=True)
class MaterialDirection:
    """One material direction θ: a material and dP/dθ.

    θ of one column: ``material`` ∈ MATERIALS, and dP/dθ (s) as a Profile in SI units
    (``change``), or None for θ = log of a uniform scale (dP/dθ = the current profile).
    """

    name: str
    material: str
    change: Profile | None = None


@dataclass
class ShapeSensitivity:
    """A solver's committed equilibrium and its derivatives with respect to θ.

    The committed equilibrium of a solver and its derivatives with respect to θ = log(material
    scale).

    s (S,) [m]; points (S, 3) [m]; d_points (S, 3, k) [m] = dx(s)/dθ_k; grip_forces[name] (3,) [N],
    the force each grip exerts on the string, and d_grip_forces[name] (3, k) [N];
    grip_torques[name] (3,) [N·m], the torque each grip exerts on the string about the grip point,
    and d_grip_torques[name] (3, k) [N·m] (director and planar models only: empty for the 3D Euler
    models; a pin's are zero); names: the θ_k.  A column of zeros means the parameter does not
    enter the solved model (e.g. Rt of a planar model).
    """

    names: tuple[str, ...]
    s: np.ndarray
    points: np.ndarray
    d_points: np.ndarray
    grip_forces: dict[str, np.ndarray]
    d_grip_forces: dict[str, np.ndarray]
    grip_torques: dict[str, np.ndarray] = field(default_factory=dict)
    d_grip_torques: dict[str, np.ndarray] = field(default_factory=dict)


class _Functions:
    """CasADi functions of one NLP that the sensitivity needs (built once per NLP)."""

    def __init__(self, nlp: StringNLP):
        # a clone's graph is its template mesh's (``build/mesh_clone.py``): differentiate its own
        nlp = symbolic_nlp(nlp)
        z, p, g = nlp.z_sym, nlp.p_sym, nlp.g_sym
        lam = ca.SX.sym("lam", g.shape[0])
        residual = ca.vertcat(ca.gradient(nlp.nlp["f"] + ca.dot(lam, g), z), g)
        v = ca.SX.sym("v", p.shape[0])
        self.forward = ca.Function(
            "dlo_kkt_dp", [z, p, lam, v], [ca.densify(ca.jtimes(residual, p, v))]
        )
        lay, m = nlp.params, nlp.model
        names = (*(k for k in MATERIALS if k in lay.slices), *m.material_sizes())
        profiles = {k: p[lay[k]] for k in names}
        tangents = m.energy_terms(z, profiles, p[lay["gravity"]])[-1]
        flat = ca.vec(tangents)  # column-major: (3, M) → 3M
        self.tangents = ca.Function(
            "dlo_tangents", [z, p], [ca.densify(tangents), ca.densify(ca.jacobian(flat, z))]
        )
        self._z, self._model = z, m
        self._frames: dict[int, ca.Function] = {}

    def node_frame(self, node: int) -> ca.Function:
        """Return the function z → (t, d1, ∂t/∂z, ∂d1/∂z) at a director model's node.

        z → (t, d1, ∂t/∂z, ∂d1/∂z) at a director model's node (d1 outputs zero for the tangent
        model): the expressions of the grip rows (``model.node_columns_sym``).
        """
        fn = self._frames.get(node)
        if fn is None:
            z = self._z
            t, d1 = self._model.node_columns_sym(z, node)
            d1 = ca.SX.zeros(3) if d1 is None else d1
            fn = self._frames[node] = ca.Function(
                f"dlo_node_frame_{node}",
                [z],
                [ca.densify(e) for e in (t, d1, ca.jacobian(t, z), ca.jacobian(d1, z))],
            )
        return fn


_FUNCTIONS: "weakref.WeakKeyDictionary[StringNLP, _Functions]" = weakref.WeakKeyDictionary()


def _functions(nlp: StringNLP) -> _Functions:
    fns = _FUNCTIONS.get(nlp)
    if fns is None:
        fns = _FUNCTIONS[nlp] = _Functions(nlp)
    return fns


def material_direction(
    nlp: StringNLP, p: np.ndarray, direction: MaterialDirection | str
) -> np.ndarray:
    """Return dp/dθ: the parameters' material part packed from dP/dθ, zero elsewhere.

    dp/dθ: p's material part packed from dP/dθ alone (the current profile for a uniform log
    scale, or ``direction.change`` at the quadrature nodes), zero elsewhere (p is linear in the
    profile values).
    """
    if isinstance(direction, str):
        direction = MaterialDirection(direction, direction)
    name = direction.material
    if name not in MATERIALS:
        raise ValueError(f"material {name!r}: must be one of {MATERIALS}")
    lay = nlp.params
    if name not in lay.slices:
        raise ValueError(f"material {name!r}: the string is not a strip (no lateral stiffness)")
    v = np.zeros_like(p)
    v[lay[name]] = (
        p[lay[name]] if direction.change is None else direction.change(nlp.model.quad.nodes)
    )
    nlp.material_parameters(v)
    return v


def shape_sensitivity(
    solver: ShapeSolver, names: tuple[MaterialDirection | str, ...], s: np.ndarray
) -> ShapeSensitivity:
    """Return the centreline at ``s`` [m] and its θ-derivatives at the committed equilibrium.

    Centreline at ``s`` [m] and its θ-derivatives at ``solver``'s committed equilibrium (module
    docstring); ``names``: one θ per entry, a material name (uniform log scale) or a
    MaterialDirection. Raises ValueError when nothing is committed or the Newton matrix is
    singular.
    """
    state = solver.snapshot()
    if state is None:
        raise ValueError("sensitivity: the solver has no committed equilibrium (solve first)")
    nlp = solver.nlp
    fns = _functions(nlp)
    z, lam, p = state.z, state.lam_g, state.p
    grad, g, jac, hess, _ = (np.asarray(a) for a in nlp.kkt_fn(z, p, lam))
    g = g.ravel()
    active = active_rows(nlp, lam, g)
    idx = np.flatnonzero(active)
    n, m = z.size, idx.size
    kkt = np.zeros((n + m, n + m))
    kkt[:n, :n] = hess
    kkt[:n, n:] = jac[idx].T
    kkt[n:, :n] = jac[idx]
    lam_active = np.zeros_like(lam)
    lam_active[idx] = lam[
        idx
    ]  # inactive rows carry no multiplier in the residual being differentiated
    rhs = np.empty((n + m, len(names)))
    for k, name in enumerate(names):
        dfdp = np.asarray(fns.forward(z, p, lam_active, material_direction(nlp, p, name))).ravel()
        rhs[:n, k] = -dfdp[:n]
        rhs[n:, k] = -dfdp[n + idx]
    try:
        sol = np.linalg.solve(kkt, rhs)
    except np.linalg.LinAlgError:
        raise ValueError("sensitivity: the KKT matrix is singular at this equilibrium") from None
    dz, dlam = sol[:n], np.zeros((lam.size, len(names)))
    dlam[idx] = sol[n:]

    s = np.asarray(s, dtype=float)
    tangents, dtangents = (np.asarray(a) for a in fns.tangents(z, p))
    w = nlp.model.position_matrix(s)  # (S, M)
    L = nlp.length
    points = L * z[0:3][None, :] + w @ tangents.T
    dt = (dtangents @ dz).reshape(3, tangents.shape[1], len(names), order="F")  # (3, M, k)
    d_points = L * dz[0:3][None, :, :] + np.einsum("sm,imk->sik", w, dt)

    scale = nlp.row_scale * nlp.sigma
    forces, d_forces = {}, {}
    for grip in solver.problem.grips:
        rows = nlp.grip_rows[grip.name]["position"]
        axes = nlp.grip_axes[grip.name]
        forces[grip.name] = -axes.T @ (lam[rows] / scale[rows])
        d_forces[grip.name] = -axes.T @ (dlam[rows] / scale[rows][:, None])
    torques, d_torques = _grip_torques(solver, fns, z, lam / scale, dz, dlam / scale[:, None])
    labels = tuple(n if isinstance(n, str) else n.name for n in names)
    return ShapeSensitivity(labels, s, points, d_points, forces, d_forces, torques, d_torques)


def _grip_torques(
    solver: ShapeSolver,
    fns: _Functions,
    z: np.ndarray,
    lam_si: np.ndarray,
    dz: np.ndarray,
    dlam_si: np.ndarray,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Return each grip's torque T and dT/dθ from the multipliers and their derivatives.

    Each grip's torque T and dT/dθ (module docstring) from the SI multipliers and their
    derivatives; empty for a 3D Euler model.
    """
    nlp = solver.nlp
    torques: dict[str, np.ndarray] = {}
    d_torques: dict[str, np.ndarray] = {}
    if not (nlp.director or nlp.planar):
        return torques, d_torques
    k = dz.shape[1]
    for grip in solver.problem.grips:
        rows = nlp.grip_rows[grip.name]["angles"]
        torque, d_torque = np.zeros(3), np.zeros((3, k))
        if rows and nlp.planar:
            normal = nlp.r0[:, 2]
            torque, d_torque = lam_si[rows[0]] * normal, np.outer(normal, dlam_si[rows[0]])
        elif rows:
            t, d1, dt, dd1 = (
                np.asarray(a) for a in fns.node_frame(nlp.model.mesh.node_index(grip.s))(z)
            )
            # d1 only where the twist is held (a third orientation row)
            t, d1_held = t.ravel(), (d1.ravel() if len(rows) == 3 else None)
            target = quat_to_matrix(grip.pose.orientation)
            torque = director_torque(t, d1_held, target, lam_si[rows])
            dt, dd1 = dt @ dz, dd1 @ dz  # (3, k)
            for j in range(k):
                d_torque[:, j] = director_torque(
                    dt[:, j], None if d1_held is None else dd1[:, j], target, lam_si[rows]
                ) + director_torque(t, d1_held, target, dlam_si[rows, j])
        torques[grip.name], d_torques[grip.name] = torque, d_torque
    return torques, d_torques
