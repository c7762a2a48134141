"""The NLP's parameter vector p for a scene: everything a solve may change without rebuilding the NLP.

p holds, at the quadrature nodes, the bending, twisting and stretching stiffnesses Rf, Rt, Re [N·m², N·m²,
N] and the weight per length D [N/m]; the unit gravity direction; the string's radius [m]; each load's
force [N] and moment [N·m]; each relative position's offset [m]; each obstacle's parameters; and each
grip's target; and each self-contact slot's pair (empty here: ``self_contact.fill`` sets the pairs):

* director models: the position [m] and the orientation matrix R_g (column-major), and for each point
  load the unit rotation its moment's pseudo-potential is centred on (``model/director.py``);
* Euler-angle models: the position and the Euler angles (φ, θ, ψ) [rad] of R_g in the NLP's reference
  frame R0, on the branch (the two Euler triples of one rotation, plus 2πk) nearest the current shape's
  angles at the grip, so that an end turned by several revolutions in small steps is tracked.

The Euler models apply only a moment's component along the working-plane normal n = R0 e_z (its work
−m·φ is exact); ``check_moments`` rejects others.
"""
from __future__ import annotations

import math

import numpy as np

from ..model.problem import GripPose, Problem
from ..model.rotations import TANGENT_X, euler_from_frame, quat_to_matrix
from .nlp import StringNLP


def check_moments(nlp: StringNLP, problem: Problem) -> None:
    """Raise ValueError (naming the load) for a point moment the NLP cannot apply exactly."""
    if nlp.director:  # moments about any axis (model/director.py)
        return
    n = nlp.r0[:, 2]
    for i, ld in enumerate(problem.loads):
        m = np.asarray(ld.moment, dtype=float)
        if np.linalg.norm(m - np.dot(m, n) * n) > 1e-9 * max(1.0, np.linalg.norm(m)):
            raise ValueError(
                f"loads[{i}].moment: only moments about the working-plane normal n = {np.round(n, 6).tolist()} "
                "are supported (their work −m·φ is exact); this moment has other components"
            )


class ProblemParameters:
    """Packs p for one NLP (see the module docstring), caching what a stream of new grip poses leaves
    unchanged: the scene's part of p, and the Euler angles of the grip poses of the last few calls."""

    def __init__(self, nlp: StringNLP):
        self.nlp = nlp
        self._scene_p: tuple | None = None  # (scene objects, gravity, p without grip targets)
        self._euler_cache: dict[int, tuple] = {}

    def pack(self, problem: Problem, z_reference: np.ndarray) -> np.ndarray:
        """The NLP parameter vector for ``problem``; angles unwrapped to the shape ``z_reference``."""
        nlp, lay = self.nlp, self.nlp.params
        p = self.scene(problem).copy()
        if nlp.director:
            for g in problem.grips:
                p[lay[f"grip:{g.name}:position"]] = g.pose.position
                p[lay[f"grip:{g.name}:frame"]] = quat_to_matrix(g.pose.orientation).ravel(order="F")
            self.centre_moments(problem, z_reference, p)
            return p
        references = self._grip_reference_angles(problem, z_reference)
        for g, reference in zip(problem.grips, references):
            p[lay[f"grip:{g.name}:position"]] = g.pose.position
            p[lay[f"grip:{g.name}:angles"]] = self.grip_angles(g.pose, reference)
        return p

    def scene(self, problem: Problem) -> np.ndarray:
        """The parameter vector without grip targets (zeros there), cached while the string, gravity, loads,
        relative positions and obstacles are the same objects (a stream only changes grip poses)."""
        key = (problem.string, problem.loads, problem.relative_positions, problem.obstacles)
        cached = self._scene_p
        if cached is not None and all(a is b for a, b in zip(cached[0], key)) and np.array_equal(cached[1], problem.gravity):
            return cached[2]
        nlp, lay = self.nlp, self.nlp.params
        nodes = nlp.model.quad.nodes
        st = problem.string
        p = np.zeros(lay.size)
        p[lay["Rf"]] = st.bend_stiffness(nodes)
        p[lay["Rt"]] = st.twist_stiffness(nodes)
        p[lay["Re"]] = st.stretch_stiffness(nodes) if st.stretch_stiffness is not None else 0.0
        p[lay["D"]] = st.weight_per_length(nodes)
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
        for k in range(nlp.self_contact_slots):  # empty slots: b = −L, the row reads −1 ≤ 0 for any shape
            p[lay[f"self:{k}"].stop - 1] = -st.length
        p.flags.writeable = False
        self._scene_p = (key, np.array(problem.gravity, dtype=float), p)
        return p

    def grip_angles(self, pose: GripPose, reference: tuple[float, float, float]) -> np.ndarray:
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

    def _pose_euler(self, pose: GripPose) -> tuple[float, float, float]:
        """``euler_from_frame`` of a grip pose in this NLP's frame, remembered for the pose objects of the
        last few calls (a stream moves one grip; the others keep their GripPose objects)."""
        cache = self._euler_cache
        hit = cache.get(id(pose))
        if hit is not None and hit[0] is pose:
            return hit[1]
        if len(cache) > 16:
            cache.clear()
        angles = euler_from_frame(self.nlp.r0, quat_to_matrix(pose.orientation) @ TANGENT_X.T)
        cache[id(pose)] = (pose, angles)
        return angles

    def _grip_reference_angles(self, problem: Problem, z: np.ndarray) -> list[list[float]]:
        """(φ, θ, ψ) of shape z at every grip's s, in one product B(s_grips) [c_φ c_θ c_ψ] (θ ≡ π/2 and
        ψ ≡ 0 where they are not unknowns, as ``RitzModel.fields``)."""
        m = self.nlp.model
        s_grips = np.array([g.s for g in problem.grips])
        b = m.matrices(s_grips)[0]
        out = np.empty((len(s_grips), 3))
        for k, (name, constant) in enumerate((("phi", 0.0), ("theta", np.pi / 2), ("psi", 0.0))):
            c = m.coefficients(z, name)
            out[:, k] = b @ c if c is not None else constant
        return out.tolist()

    def centre_moments(self, problem: Problem, z: np.ndarray, p: np.ndarray) -> None:
        """Centre each point moment's pseudo-potential (in p, in place) on the rotation of shape z at its load."""
        m, lay = self.nlp.model, self.nlp.params
        values = m.node_values(z)
        for i, ld in enumerate(problem.loads):
            ref = np.zeros(4)
            v = values[m.mesh.node_index(ld.s)]
            ref[: v.size] = v / np.linalg.norm(v)
            p[lay[f"load:{i}:reference"]] = ref
