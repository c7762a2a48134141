"""A solved state carried from one element mesh to another (h/p refinement's warm start).

Both meshes belong to one scene and one director model (``DirectorModel``, model 'full'); only
the breakpoints and the LGL nodes per element differ (``build/mesh.py`` ``MeshSpec``).

Primal z: x(0) is kept; the rotation field (nodal quaternions or unit tangents) and ε are the old
mesh's element polynomials evaluated at the new nodes (exact for a field that is a polynomial of
degree < n_e on every old element), the rotation values renormalised to unit length (the
unit-norm rows) and, for quaternions, signed so that neighbours have a positive dot product.

Multipliers, row by row of the new NLP (in SI, λ_SI = λ / (row_scale · σ)):

* rows with a twin of the same kind on the old mesh (grip positions and orientations, relative
  positions) copy it;
* obstacle rows: each old row's force goes to the new row nearest along s (rows on the nodes
  move between meshes; rows on uniform samples sit at the same arc lengths and copy theirs); a
  sample that a contact slot switched off on the new mesh gets 0;
* contact slots copy the multiplier of the old slot nearest along s (within
  ``obstacle_slots.CARRIED`` · L, as ``update/warm_start.py`` does across models);
* the unit-norm row of node i takes λ_i = −½ v_i · (∇_{v_i} f + Σ_other J_{k,v_i} λ_k), the
  stationarity equation projected on that node's normal direction.  A nodal multiplier is a
  weighted integral of the continuous one over the node's basis function (it scales with the
  node's quadrature weight and carries the internal moment at an element end), so it is not
  interpolated as a point value; the projection gives it exactly for the interpolated shape;
* fold guards (inactive on a resolved shape) get 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model.director import DirectorModel, continuous_signs
from ...model.elements import ElementMesh
from ..contact import obstacle_slots as OSL
from ..contact.obstacle_points import carried_forces
from ..shape_solver import ShapeSolver
from ..state import SolverState
from ..update.newton import fill_start


@dataclass(frozen=True)
class TransferredState:
    """The new mesh's warm start and what the transfer could not match."""

    state: SolverState
    #: new rows without a twin on the old mesh that got 0 (other than folds and norm rows)
    unmatched_rows: int


def nodal_matrix(old: ElementMesh, new: ElementMesh) -> np.ndarray:
    """Return T (new.count × old.count): new nodal values = T · old nodal values.

    Each new node takes the value of the old element polynomial it lies on (at an old breakpoint
    either side: the field is continuous there).  Raise ValueError for strings of other lengths.
    """
    if abs(old.length - new.length) > 1e-12 * max(old.length, 1.0):
        raise ValueError(f"transfer: meshes of {old.length} m and {new.length} m")
    return old.interpolation(new.nodes)[0]


def transfer_z(old: DirectorModel, new: DirectorModel, z: np.ndarray) -> np.ndarray:
    """Return the unknowns of ``new`` for the shape ``z`` of ``old`` (module docstring).

    Raise ValueError when the two models do not share the rotation field and strain.
    """
    lo, ln = old.layout, new.layout
    if (lo.frame, lo.stretch) != (ln.frame, ln.stretch):
        raise ValueError(
            "transfer: the meshes' models differ (rotation field or strain); "
            "use ShapeSolver.adopt_warm_start across models"
        )
    T = nodal_matrix(old.mesh, new.mesh)
    values = T @ old.node_values(z)
    values /= np.linalg.norm(values, axis=1)[:, None]
    if ln.frame:
        # T reproduces the old first node, so its sign anchors the new field's
        values = continuous_signs(values)
    out = np.zeros(ln.size)
    out[0:3] = z[0:3]
    out[ln.rotation] = values.ravel()
    eps = old.strain_nodes(z)
    if eps is not None:
        out[ln.eps] = T @ eps
    return out


def _slot_multipliers(
    old: ShapeSolver, old_p: np.ndarray, lam_si: np.ndarray, new: ShapeSolver, p: np.ndarray
) -> dict[int, float]:
    """Return {new row: SI multiplier} of the new mesh's filled slots matched by arc length."""
    out: dict[int, float] = {}
    L = new.nlp.length
    for i, rows in enumerate(new.nlp.slot_rows):
        if i >= len(old.nlp.slot_rows):
            break
        was, now = old.parameters.slots(old_p, i), new.parameters.slots(p, i)
        filled = was.on > 0
        src_s, src_lam = was.s[filled], lam_si[np.asarray(old.nlp.slot_rows[i])[filled]]
        for k, row in enumerate(rows):
            if now.on[k] <= 0 or not src_s.size:
                continue
            j = OSL.carried_slot(src_s, float(now.s[k]), L)
            if j is not None:
                out[row] = float(src_lam[j])
    return out


def _switched_off(new: ShapeSolver, p: np.ndarray, kind: tuple) -> bool:
    """Whether ``kind`` is an obstacle sample row that a contact slot switched off in ``p``."""
    if kind[0] != "obstacle" or not new.nlp.obstacle_slots:
        return False
    return bool(new.parameters.slots(p, kind[1]).samples_on[kind[2]] <= 0)


def transfer_multipliers(
    old: ShapeSolver, src: SolverState, new: ShapeSolver, z: np.ndarray, p: np.ndarray
) -> tuple[np.ndarray, int]:
    """Return the new NLP's multipliers (IPOPT's scaling) at (z, p) and the unmatched row count.

    ``src``: the old solver's state; z, p: the new NLP's unknowns and parameters (module
    docstring for the rules).
    """
    onlp, nnlp = old.nlp, new.nlp
    lam_si = src.lam_g / (np.asarray(onlp.row_scale) * onlp.sigma)
    by_kind = {kind: float(lam_si[i]) for i, kind in enumerate(onlp.row_kind)}
    slots = _slot_multipliers(old, src.p, lam_si, new, p)
    lam = np.zeros(len(nnlp.row_kind))
    carried = {
        k: carried_forces(
            onlp.obstacle_s,
            lam_si[np.asarray(onlp.obstacle_rows[k])],
            nnlp.obstacle_s,
            onlp.obstacle_weights,
            nnlp.obstacle_weights,
        )
        for k in range(min(len(nnlp.obstacle_rows), len(onlp.obstacle_rows)))
    }
    norm_rows, unmatched = [], 0
    for i, kind in enumerate(nnlp.row_kind):
        if kind[0] == "norm":
            norm_rows.append(i)
        elif kind[0] == "slot":
            lam[i] = slots.get(i, 0.0)
        elif kind[0] == "obstacle" and kind[1] in carried:
            lam[i] = 0.0 if _switched_off(new, p, kind) else carried[kind[1]][kind[2]]
        elif kind[0] != "fold" and kind in by_kind:
            lam[i] = 0.0 if _switched_off(new, p, kind) else by_kind[kind]
        elif kind[0] != "fold":
            unmatched += 1
    lam *= np.asarray(nnlp.row_scale) * nnlp.sigma
    if norm_rows:
        lam[norm_rows] = _norm_multipliers(new, z, p, lam, np.array(norm_rows))
    return lam, unmatched


def _norm_multipliers(
    new: ShapeSolver, z: np.ndarray, p: np.ndarray, lam: np.ndarray, rows: np.ndarray
) -> np.ndarray:
    """Return λ of the unit-norm rows: the stationarity equation on each node's normal direction.

    Row i reads (|v_i|² − 1)/1, whose gradient is 2 v_i in v_i's block: with r = ∇f + Σ_other Jᵀλ
    the multiplier that cancels r along v_i is −(r · 2 v_i)/|2 v_i|², a closed form per node.
    """
    grad, _, jac, _, _ = new.functions.kkt(z, p, np.zeros_like(lam))
    jac = np.asarray(jac)
    rest = np.asarray(grad).ravel() + jac.T @ lam  # lam holds 0 at the norm rows
    out = np.empty(rows.size)
    for k, row in enumerate(rows):
        normal = jac[row]  # 2 v_i on v_i's entries (scaled row), 0 elsewhere
        out[k] = -float(rest @ normal) / float(normal @ normal)
    return out


def transferred_state(old: ShapeSolver, new: ShapeSolver) -> TransferredState | None:
    """Return ``old``'s committed equilibrium mapped onto ``new``'s mesh (None: nothing committed).

    Both solvers model the same scene structure with the director model; the parameters are
    packed for ``new``'s scene on the mapped shape (grip targets, and contact slots placed on it
    afresh: the parameter layout differs between meshes).
    """
    src = old.committed_state
    if src is None:
        return None
    if not (old.nlp.director and new.nlp.director):
        raise ValueError("transfer: both meshes need an element model (solver.model 'full')")
    z = transfer_z(old.nlp.model, new.nlp.model, src.z)
    p = new.pack_parameters(new.problem, z)
    lam, unmatched = transfer_multipliers(old, src, new, z, p)
    return TransferredState(SolverState(z, lam, np.zeros(z.size), p), unmatched)


def warm_start_from(old: ShapeSolver, new: ShapeSolver) -> bool:
    """Hand ``new`` (another mesh of ``old``'s scene) ``old``'s equilibrium as its warm start.

    The next ``new.solve()`` then starts warm from it (``ShapeSolver.install_warm_start``), with
    the derivatives its first Newton step reuses (``fill_start``).  ``new`` must not be solving in
    another thread meanwhile (it is evaluated outside its lock: a freshly built solver).  False
    when ``old`` has nothing committed.
    """
    moved = transferred_state(old, new)
    if moved is None:
        return False
    fill_start(new.nlp, new.functions, moved.state)
    new.install_warm_start(moved.state)
    return True
