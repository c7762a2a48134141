"""The NLP's parameter vector p for a scene.

The NLP's parameter vector p for a scene: everything a solve may change without rebuilding the
NLP.

p holds, at the quadrature nodes, the bending, twisting and stretching stiffnesses Rf, Rt, Re
[N·m², N·m², N] and the weight per length D [N/m]; the unit gravity direction; the string's radius
[m]; each load's force [N] and moment [N·m]; each relative position's offset [m]; each obstacle's
parameters; and each grip's target; each self-contact slot's pair (empty here:
``self_contact.fill`` sets the pairs); and, with each obstacle's contact slots, placed at the
reference shape's closest approaches (``obstacle_slots.py``):

* director models: the position [m] and the orientation matrix R_g (column-major), and for each
  point
  load the unit rotation its moment's pseudo-potential is centred on (``model/director.py``);
* Euler-angle models: the position and the Euler angles (φ, θ, ψ) [rad] of R_g in the NLP's
  reference
  frame R0, on the branch (the two Euler triples of one rotation, plus 2πk) nearest the current
  shape's angles at the grip, so that an end turned by several revolutions in small steps is
  tracked.

The Euler models apply only a moment's component along the working-plane normal n = R0 e_z (its
work −m·φ is exact); ``check_moments`` rejects others.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import numpy as np

from ...model.problem import GripPose, Problem
from ...model.rotations import TANGENT_X, euler_from_frame, quat_to_matrix
from ..contact import obstacle_slots as OSL
from .nlp import StringNLP

T = TypeVar("T")


def _placed_key(problem: Problem, z: np.ndarray, keep: np.ndarray | None) -> tuple:
    """Return what a slot placement depends on besides the NLP.

    The shape, the slots kept, the obstacles (the objects: a stream replaces grip poses only) and
    the string's radius.
    """
    return (
        np.asarray(z, dtype=float).tobytes(),
        None if keep is None else np.asarray(keep, dtype=float).tobytes(),
        problem.obstacles,
        problem.string.radius,
    )


def _same_key(a: tuple, b: tuple) -> bool:
    """Whether two ``_placed_key`` are of one placement (the obstacles compared as objects)."""
    return (
        a[0] == b[0]
        and a[1] == b[1]
        and len(a[2]) == len(b[2])
        and all(x is y for x, y in zip(a[2], b[2]))
        and a[3] == b[3]
    )


def _by_pose(cache: dict[int, tuple], pose: GripPose, compute: Callable[[], T]) -> T:
    """Return ``compute()`` for ``pose``, remembered in ``cache`` by the pose object.

    A stream moves one grip; the others keep their GripPose objects, so what depends on a pose
    alone is worked out once.  The cache holds (pose, value) by id, checked by identity (an id
    may be reused after a pose is freed), and is emptied past 16 entries.
    """
    hit = cache.get(id(pose))
    if hit is not None and hit[0] is pose:
        return hit[1]
    if len(cache) > 16:
        cache.clear()
    value = compute()
    cache[id(pose)] = (pose, value)
    return value


def check_moments(nlp: StringNLP, problem: Problem) -> None:
    """Raise ValueError (naming the load) for a point moment the NLP cannot apply exactly."""
    if nlp.director:  # moments about any axis (model/director.py)
        return
    n = nlp.r0[:, 2]
    for i, ld in enumerate(problem.loads):
        m = np.asarray(ld.moment, dtype=float)
        if np.linalg.norm(m - np.dot(m, n) * n) > 1e-9 * max(1.0, float(np.linalg.norm(m))):
            raise ValueError(
                f"loads[{i}].moment: only moments about the working-plane normal "
                f"n = {np.round(n, 6).tolist()} "
                "are supported (their work −m·φ is exact); this moment has other components"
            )


class ProblemParameters:
    """Packs p for one NLP, caching what a stream of new grip poses leaves unchanged.

    Packs p for one NLP (see the module docstring), caching what a stream of new grip poses
    leaves unchanged: the scene's part of p, and the Euler angles of the grip poses of the last few
    calls.
    """

    def __init__(self, nlp: StringNLP):
        self.nlp = nlp
        self._scene_p: tuple | None = None  # (scene objects, gravity, p without grip targets)
        self._euler_cache: dict[int, tuple] = {}
        self._frame_cache: dict[int, tuple] = {}  # (pose, its frame entries) by id (_pose_frame)
        self._grip_layout: dict[str, tuple] = {}  # grip name: its rows of p (_grip_rows)
        #: the contact slots the last ``pack`` found, per obstacle (read by the solver right after
        #: it)
        self.placements: list[OSL.SlotPlacement] = []
        #: (what the last ``place_slots`` depended on, its placements): an update places the slots
        #: on its answer, and the next update on that same shape again (``_placed_key``)
        self._placed: tuple[tuple, list[OSL.SlotPlacement]] | None = None
        self._slot_entries: np.ndarray | None = None  # (slot_entries)
        self._slices: dict[int, tuple[slice, ...]] = {}  # obstacle: its slots' slices of p
        #: obstacle: (σ and on as bytes, the slot rows written last) (``_slot_matrices``)
        self._matrices: dict[int, tuple[bytes, np.ndarray]] = {}

    def pack(
        self,
        problem: Problem,
        z_reference: np.ndarray,
        keep: np.ndarray | None = None,
        slots: bool = True,
    ) -> np.ndarray:
        """Return the NLP parameter vector for ``problem``.

        The NLP parameter vector for ``problem``; angles unwrapped to, and obstacle contact
        slots placed on, the shape ``z_reference``.  ``keep``: a parameter vector whose slots stay
        while they are still placed well for ``z_reference``; ``slots`` False: leave them empty (a
        caller that reads grip angles only).
        """
        nlp, lay = self.nlp, self.nlp.params
        p = self.scene(problem).copy()
        if nlp.obstacle_slots and slots:
            self.placements = self.place_slots(problem, z_reference, p, keep)
        if nlp.director:
            for g in problem.grips:
                position, frame = self._grip_rows(g.name)
                p[position] = g.pose.position
                p[frame] = self._pose_frame(g.pose)
            if problem.loads:
                self.centre_moments(problem, z_reference, p)
            return p
        references = self._grip_reference_angles(problem, z_reference)
        for g, reference in zip(problem.grips, references):
            p[lay[f"grip:{g.name}:position"]] = g.pose.position
            p[lay[f"grip:{g.name}:angles"]] = self.grip_angles(g.pose, reference)
        return p

    def slot_entries(self) -> np.ndarray:
        """Return the rows of p that hold the obstacles' contact slots, worked out once.

        Every obstacle's ``StringNLP.slot_parameters`` in their order, as one read-only index
        array (empty without slots).
        """
        if self._slot_entries is None:
            nlp, lay = self.nlp, self.nlp.params
            rows = [
                np.arange(lay.size)[lay[name]]
                for i in range(len(nlp.slot_rows))
                for name in nlp.slot_parameters(i)
            ]
            entries = np.concatenate(rows) if rows else np.zeros(0, dtype=int)
            entries.flags.writeable = False
            self._slot_entries = entries
        return self._slot_entries

    def _slot_slices(self, i: int) -> tuple[slice, ...]:
        """Return the slices of p of obstacle i's ``slot_parameters``, looked up once."""
        found = self._slices.get(i)
        if found is None:
            lay = self.nlp.params
            found = tuple(lay[name] for name in self.nlp.slot_parameters(i))
            self._slices[i] = found
        return found

    def slots(self, p: np.ndarray, i: int) -> OSL.SlotPlacement:
        """Obstacle i's contact slots as p holds them (clearance unknown: inf)."""
        s, on, _, _, _, samples_on = self._slot_slices(i)
        return OSL.SlotPlacement(
            p[s].copy(),
            p[on].copy(),
            p[samples_on].copy(),
            np.full(self.nlp.obstacle_slots, np.inf),
        )

    def slot_lists(self, p: np.ndarray, i: int) -> tuple[list[float], list[float], list[float]]:
        """Return obstacle i's slots as p holds them: σ [m], on, the samples' switches (floats)."""
        s, on, _, _, _, samples_on = self._slot_slices(i)
        return p[s].tolist(), p[on].tolist(), p[samples_on].tolist()

    def write_slots(
        self, p: np.ndarray, i: int, placement: OSL.SlotPlacement, keep: np.ndarray | None = None
    ) -> None:
        """Write obstacle i's slots of p (in place) from ``placement``.

        Obstacle i's slots of p (in place) from ``placement`` (``keep``: a vector holding its
        rows already).  The rows W, P, P' of the last slots written are remembered per obstacle
        (a stream writes the slots it placed on an answer again as the next solve's).
        """
        slices = self._slot_slices(i)
        if keep is not None:
            for rows_of_p in slices:
                p[rows_of_p] = keep[rows_of_p]
            return
        s, on, w, t, k, samples_on = slices
        rows = self._slot_matrices(i, placement)
        p[s], p[on] = placement.s, placement.on
        p[w], p[t], p[k] = rows[0].ravel(), rows[1].ravel(), rows[2].ravel()
        p[samples_on] = placement.samples_on

    def _slot_matrices(self, i: int, placement: OSL.SlotPlacement) -> np.ndarray:
        """Return obstacle i's slot rows [W; P; P'] (3, K, M) at ``placement``'s filled slots.

        Zero rows where a slot is empty.  Remembered for the last (σ, on) of each obstacle
        (read-only).
        """
        key = placement.s.tobytes() + placement.on.tobytes()
        last = self._matrices.get(i)
        if last is not None and last[0] == key:
            return last[1]
        nlp = self.nlp
        rows = np.zeros((3, nlp.obstacle_slots, nlp.model.quad.count))
        filled = placement.on > 0
        if np.any(filled):
            rows[0, filled] = nlp.model.position_rows(placement.s[filled])
            rows[1, filled], rows[2, filled] = nlp.model.tangent_rows(placement.s[filled])
        rows.flags.writeable = False
        self._matrices[i] = (key, rows)
        return rows

    def place_slots(
        self, problem: Problem, z: np.ndarray, p: np.ndarray, keep: np.ndarray | None = None
    ) -> list[OSL.SlotPlacement]:
        """Place every obstacle's contact slots of p (in place) at shape z's closest approaches.

        Fill every obstacle's contact slots of p (in place) at the closest approaches of shape z
        (``obstacle_slots``); ``keep``: a vector whose slots stay where they still fit.  Returns
        the placements (with the shape's clearance at each slot).
        """
        key = _placed_key(problem, z, keep)
        last = self._placed
        if last is not None and _same_key(last[0], key):
            for i, new in enumerate(last[1]):
                self.write_slots(p, i, new, keep if new.kept else None)
            return last[1]
        placements = self._place_slots(problem, z, p, keep)
        self._placed = (key, placements)
        return placements

    def place_on(
        self, problem: Problem, z: np.ndarray, keep: np.ndarray
    ) -> list[OSL.SlotPlacement]:
        """Place the slots on shape z as ``pack(problem, z, keep)`` does, the rest of p unpacked.

        Sets and returns ``placements`` (the slots written into a copy of ``keep``, dropped).
        """
        self.placements = self.place_slots(problem, z, keep.copy(), keep)
        return self.placements

    def _place_slots(
        self, problem: Problem, z: np.ndarray, p: np.ndarray, keep: np.ndarray | None
    ) -> list[OSL.SlotPlacement]:
        """``place_slots`` worked out (not from the last call's)."""
        nlp, m = self.nlp, self.nlp.model
        L, S, radius = nlp.length, len(nlp.obstacle_s), problem.string.radius
        s_fine = OSL.fine_grid(L, S)
        x = m.positions(z, s_fine)
        within = OSL.slot_tolerance(L, nlp.options.error_tolerance)
        placements = []
        for i, ob in enumerate(problem.obstacles):

            def clearance_at(s: np.ndarray, ob=ob) -> np.ndarray:
                return -ob.h_many(m.positions_at_rows(z, m.position_rows(s))) - radius

            flat = ob.type in OSL.FLAT
            if not OSL.slotted(ob.type, nlp.options.slotted_obstacles):
                found = (np.zeros(0), np.zeros(0))
            else:
                found = OSL.minima(
                    s_fine,
                    -ob.h_many(x) - radius,
                    nlp.obstacle_spacing,
                    OSL.band(L, radius),
                    L,
                    clearance_at,
                    flat,
                )
            previous = self.slots(keep, i) if keep is not None else None
            new = OSL.assign(found, nlp.obstacle_s, nlp.obstacle_slots, previous, L, within)
            self.write_slots(p, i, new, keep if new.kept else None)
            placements.append(new)
        return placements

    def scene(self, problem: Problem) -> np.ndarray:
        """Return the parameter vector without grip targets (zeros there), cached.

        The parameter vector without grip targets (zeros there), cached while the string,
        gravity, loads, relative positions and obstacles are the same objects (a stream only
        changes grip poses).
        """
        key = (problem.string, problem.loads, problem.relative_positions, problem.obstacles)
        cached = self._scene_p
        if (
            cached is not None
            and all(a is b for a, b in zip(cached[0], key))
            and np.array_equal(cached[1], problem.gravity)
        ):
            return cached[2]
        nlp, lay = self.nlp, self.nlp.params
        nodes = nlp.model.quad.nodes
        st = problem.string
        p = np.zeros(lay.size)
        p[lay["Rf"]] = st.bend_stiffness(nodes)
        p[lay["Rt"]] = st.twist_stiffness(nodes)
        p[lay["Re"]] = st.stretch_stiffness(nodes) if st.stretch_stiffness is not None else 0.0
        p[lay["D"]] = st.weight_per_length(nodes)
        if "Rl" in lay.slices:  # a strip's stiffness about d2
            p[lay["Rl"]] = st.lateral_stiffness(nodes)
        nlp.material_parameters(p)
        p[lay["gravity"]] = problem.gravity_unit
        p[lay["radius"]] = st.radius
        n = nlp.r0[:, 2]
        for i, ld in enumerate(problem.loads):
            p[lay[f"load:{i}:force"]] = ld.force
            p[lay[f"load:{i}:moment"]] = ld.moment if nlp.director else float(np.dot(ld.moment, n))
        for i, rel in enumerate(problem.relative_positions):
            p[lay[f"relative:{i}"]] = rel.offset
        for i, ob in enumerate(problem.obstacles):
            p[lay[f"obstacle:{i}"]] = ob.params
        for i, _ in enumerate(
            problem.obstacles if nlp.obstacle_slots else ()
        ):  # no slots: every sample on
            p[lay[f"samples:{i}:on"]] = 1.0
        for k in range(
            nlp.self_contact_slots
        ):  # empty slots: b = −L, the row reads −1 ≤ 0 for any shape
            p[lay[f"self:{k}"].stop - 1] = -st.length
        p.flags.writeable = False
        self._scene_p = (key, np.array(problem.gravity, dtype=float), p)
        return p

    def grip_angles(self, pose: GripPose, reference: Sequence[float]) -> np.ndarray:
        """Euler angles (φ, θ, ψ) of a grip orientation, on the branch nearest ``reference``."""
        phi, theta, psi = self._pose_euler(pose)
        best, best_d = None, math.inf
        two_pi = 2.0 * math.pi
        for ph, th, ps in ((phi, theta, psi), (phi + math.pi, -theta, psi + math.pi)):
            th = th + two_pi * round((reference[1] - th) / two_pi)
            ph = ph + two_pi * round((reference[0] - ph) / two_pi)
            ps = ps + two_pi * round((reference[2] - ps) / two_pi)
            d = (ph - reference[0]) ** 2 + (th - reference[1]) ** 2 + (ps - reference[2]) ** 2
            if d < best_d:
                best, best_d = (ph, th, ps), d
        return np.array(best)

    def _grip_rows(self, name: str) -> tuple[Any, Any]:
        """Return the layout entries of grip ``name``'s position and frame, looked up once."""
        rows = self._grip_layout.get(name)
        if rows is None:
            lay = self.nlp.params
            rows = (lay[f"grip:{name}:position"], lay[f"grip:{name}:frame"])
            self._grip_layout[name] = rows
        return rows

    def _pose_frame(self, pose: GripPose) -> np.ndarray:
        """Return a director model's grip frame entries of p (R column by column), remembered.

        Remembered for the pose objects of the last few calls (``_by_pose``).  Read-only.
        """

        def frame() -> np.ndarray:
            entries = quat_to_matrix(pose.orientation).ravel(order="F")
            entries.flags.writeable = False
            return entries

        return _by_pose(self._frame_cache, pose, frame)

    def _pose_euler(self, pose: GripPose) -> tuple[float, float, float]:
        """Return ``euler_from_frame`` of a grip pose in this NLP's frame, remembered.

        Remembered for the pose objects of the last few calls (``_by_pose``).
        """
        return _by_pose(
            self._euler_cache,
            pose,
            lambda: euler_from_frame(self.nlp.r0, quat_to_matrix(pose.orientation) @ TANGENT_X.T),
        )

    def _grip_reference_angles(self, problem: Problem, z: np.ndarray) -> list[list[float]]:
        """Return (φ, θ, ψ) of shape z at every grip's s.

        (φ, θ, ψ) of shape z at every grip's s, in one product B(s_grips) [c_φ c_θ c_ψ] (θ ≡ π/2
        and ψ ≡ 0 where they are not unknowns, as ``RitzModel.fields``).
        """
        m = self.nlp.model
        s_grips = np.array([g.s for g in problem.grips])
        b = m.matrices(s_grips)[0]
        out = np.empty((len(s_grips), 3))
        for k, (name, constant) in enumerate((("phi", 0.0), ("theta", np.pi / 2), ("psi", 0.0))):
            c = m.coefficients(z, name)
            out[:, k] = b @ c if c is not None else constant
        return out.tolist()

    def centre_moments(self, problem: Problem, z: np.ndarray, p: np.ndarray) -> None:
        """Centre each point moment's pseudo-potential on shape z's rotation at its load.

        Centre each point moment's pseudo-potential (in p, in place) on the rotation of shape z
        at its load.
        """
        m, lay = self.nlp.model, self.nlp.params
        values = m.node_values(z)
        for i, ld in enumerate(problem.loads):
            ref = np.zeros(4)
            v = values[m.mesh.node_index(ld.s)]
            ref[: v.size] = v / np.linalg.norm(v)
            p[lay[f"load:{i}:reference"]] = ref
