"""The dynamic peers robotics users reach for (method 5): PyElastica, MuJoCo 3's cable and MuJoCo 4's rod
(``MuJoCoRodRunner``, whose docstring and worker module say how it differs), relaxed to rest.

All three start from the same feasible buckled polyline (N segments of exact length L/N, the end segments
along the clamps, the far end on its target — the peers clamp by fixing the first/last *segment*, their
standard usage, which is first order in L/N), hold both ends, add weight/loads/table, and integrate
damped dynamics until the largest node speed falls below ``settle`` · L · ω₁ (ω₁ = 22.4 √(Rf/m')/L², the
clamped beam's first bending frequency; near rest the distance to equilibrium is about speed/ω₁) or
``max_time`` runs out.

Settings (chosen by bench/suite/peer_tuning.py, results in bench/results/peers_tuning.md): PyElastica
cfl 0.5 (0.9 blows up), ζ = 2, radius 5 mm (stretch error ≈ P r²/(4 Rf) ≈ 1e-4 L, below the first-order
discretisation error; a thinner rod only shrinks dt); MuJoCo cfl 0.5 (≥ 1.5 never settles), ζ = 1;
settle 1e-4 for both (1e-5 costs 50 % more time and changes nothing at N ≤ 80).

Mass scaling (dynamic relaxation): the equilibrium does not depend on the mass, so both use a line
density m' = 1 kg/m and set gravity g = D/m' (weight per length D unchanged).

PyElastica (Cosserat rod, shearable and extensible): radius r sets EA/EI = 4/r², i.e. the stretch error
(≈ P r²/(4 Rf)) and the axial wave speed that bounds the explicit time step (PositionVerlet,
dt = cfl · (L/N) / √(EA/m')).  Damping: AnalyticalLinearDamper (velocities × exp(−ν dt)), ν = ζ·2ω₁.
MuJoCo (composite cable + elasticity.cable plugin: inextensible capsules on ball joints): the far clamp
is a weld equality (soft: solref time constant 2·dt), joint damping integrated implicitly
(implicitfast), dt from the bending stability bound of one segment.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import weakref
from pathlib import Path
from typing import NamedTuple

import numpy as np

from dlo_ros.model.rotations import quat_to_matrix

from bench.common import S_OUT, Case, Outcome, interp_points, quat_twisted
from bench.methods.planar import guess_angles, tangent_angle

OMEGA1 = 22.37  # (4.730)² : first clamped–clamped bending mode, ω₁ = 22.37 √(EI/m') / L²


def initial_polyline(problem, N: int, tau: float = 0.0, sag_sign: float | None = None, beta=None):
    """Nodes (N+1, 3) and segment frames (N, 3, 3) (columns: tangent, normal, binormal) in the x–z plane.

    Interior angles from the buckled guess (or ``beta``), corrected by Gauss–Newton (minimum-norm steps)
    so that the far end lands on its target; first/last segments along held tangents; the turn τ spread
    along s."""
    L = problem.string.length
    gl, gr = problem.grip("left"), problem.grip("right")
    modes = {g.name: g.mode for g in problem.grips}
    pr = {"left_pos": gl.pose.position[[0, 2]], "right_pos": gr.pose.position[[0, 2]],
          "left_angle": tangent_angle(gl.pose.orientation), "right_angle": tangent_angle(gr.pose.orientation)}
    u = (np.arange(N) + 0.5) / N
    beta = guess_angles(u, problem, pr, sag_sign) if beta is None else np.array(beta, float)
    free = np.ones(N, dtype=bool)
    if modes["left"] != "pin":
        beta[0], free[0] = pr["left_angle"], False
    if modes["right"] != "pin":
        beta[-1], free[-1] = pr["right_angle"], False
    h = L / N
    target = pr["right_pos"] - pr["left_pos"]
    for _ in range(50):
        r = h * np.array([np.cos(beta).sum(), np.sin(beta).sum()]) - target
        if np.max(np.abs(r)) < 1e-13:
            break
        J = h * np.stack([-np.sin(beta), np.cos(beta)])[:, free]
        beta[free] -= J.T @ np.linalg.solve(J @ J.T, r)
    nodes = np.zeros((N + 1, 3))
    nodes[0] = gl.pose.position
    nodes[1:, 0] = nodes[0, 0] + h * np.cumsum(np.cos(beta))
    nodes[1:, 2] = nodes[0, 2] + h * np.cumsum(np.sin(beta))
    frames = np.stack([quat_to_matrix(quat_twisted(b, tau * uu)) for b, uu in zip(beta, u)])
    if modes["right"] == "clamp":
        frames[-1] = quat_to_matrix(quat_twisted(pr["right_angle"], tau))
    return nodes, frames


class RodConstants(NamedTuple):
    """What every peer derives from the string (SI units; E and G in Pa for the peer's radius r)."""

    L: float
    N: int
    r: float
    Rf: float
    Rt: float
    D: float
    E: float
    G: float


class PeerRunner:
    """Common bookkeeping: cold = relax from the buckled polyline; warm = relax from the previous
    equilibrium with the far end moved (the old shape stretched affinely along the chord)."""

    def __init__(self, case: Case, segments: int, settle: float = 1e-4, max_time: float = 60.0):
        self.case, self.N, self.settle, self.max_time = case, int(segments), settle, max_time
        self.previous = None
        self.build_time_s = 0.0

    def cold(self, problem) -> Outcome:
        nodes, frames = initial_polyline(problem, self.N, self.case.tau)
        return self._relax(problem, nodes, frames)

    def _constants(self, problem) -> "RodConstants":
        """The string's length, largest stiffnesses and weight, this peer's segments and radius, and the
        circular section's moduli that give Rf = E π r⁴/4 and Rt = G π r⁴/2 (G = E/3 where Rt = 0)."""
        st, r = problem.string, self.radius
        Rf, Rt = float(st.bend_stiffness.maximum), float(st.twist_stiffness.maximum)
        E = 4 * Rf / (np.pi * r**4)
        G = 2 * Rt / (np.pi * r**4) if Rt > 0 else E / 3
        return RodConstants(st.length, self.N, r, Rf, Rt, float(st.weight_per_length.maximum), E, G)

    def warm(self, problem) -> Outcome:
        """Planar cases: the previous equilibrium's segment angles, re-projected (Gauss–Newton, exact segment
        lengths) so that the far end sits on its new target.  3D cases: a cold relax."""
        if self.previous is None or not self.case.planar:
            return self.cold(problem)
        nodes = self.previous[0]
        d = np.diff(nodes, axis=0)
        beta = np.arctan2(d[:, 2], d[:, 0])
        nodes, frames = initial_polyline(problem, self.N, 0.0, beta=np.unwrap(beta))
        return self._relax(problem, nodes, frames)


# ---------------------------------------------------------------------------------------------------
class PyElasticaRunner(PeerRunner):
    def __init__(self, case: Case, segments: int, radius: float = 0.005, cfl: float = 0.5, zeta: float = 2.0, **kw):
        super().__init__(case, segments, **kw)
        import elastica  # noqa: F401  (fails here if not installed)

        self.radius, self.cfl, self.zeta = radius, cfl, zeta
        t0 = time.perf_counter()
        self._relax(case.problem, *initial_polyline(case.problem, self.N, case.tau), max_time=1e-3)  # numba JIT
        self.build_time_s = time.perf_counter() - t0
        self.previous = None

    def _relax(self, problem, nodes, frames, max_time=None) -> Outcome:
        import elastica as ea

        L, N, r, Rf, Rt, D, E, G = self._constants(problem)
        area = np.pi * r**2
        density = 1.0 / area  # m' = 1 kg/m
        dl = L / N
        dt = self.cfl * dl / np.sqrt(E * area / 1.0)
        w1 = OMEGA1 * np.sqrt(Rf / 1.0) / L**2
        nu = self.zeta * 2 * w1

        class Sim(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
            pass

        sim = Sim()
        directors = np.zeros((3, 3, N))
        for j in range(N):  # elastica: rows d1, d2, d3 with d3 the tangent
            directors[0, :, j] = frames[j][:, 1]
            directors[1, :, j] = frames[j][:, 2]
            directors[2, :, j] = frames[j][:, 0]
        rod = ea.CosseratRod.straight_rod(N, nodes[0], frames[0][:, 0], frames[0][:, 1], L, r, density,
                                          youngs_modulus=E, shear_modulus=G, position=nodes.T.copy(),
                                          directors=directors)
        sim.append(rod)
        modes = {g.name: g.mode for g in problem.grips}
        pos_idx = (0, -1)
        dir_idx = tuple(i for i, name in ((0, "left"), (-1, "right")) if modes[name] == "clamp")
        sim.constrain(rod).using(ea.FixedConstraint, constrained_position_idx=pos_idx, constrained_director_idx=dir_idx)
        if D > 0:
            sim.add_forcing_to(rod).using(ea.GravityForces, acc_gravity=problem.gravity_unit * D)
        loads = problem.loads
        obstacles = problem.obstacles

        class Extra(ea.NoForces):
            def apply_forces(self_, system, time=0.0):  # noqa: N805
                for ld in loads:
                    k = int(round(ld.s / dl))
                    system.external_forces[:, k] += ld.force
                    if np.linalg.norm(ld.moment) > 0:
                        for j in (k - 1, k):  # split between the two elements meeting at the node
                            if 0 <= j < N:
                                system.external_torques[:, j] += 0.5 * system.director_collection[:, :, j] @ ld.moment
                for ob in obstacles:
                    pt, n = ob.point, ob.normal
                    depth = -((system.position_collection.T - pt) @ n)  # > 0 inside
                    inside = depth > 0
                    if inside.any():
                        k_c = 1e4 * max(D, 1.0) * dl
                        vn = system.velocity_collection.T[inside] @ n
                        f = (k_c * depth[inside] - 2 * np.sqrt(k_c) * np.minimum(vn, 0) * 0)[:, None] * n[None, :]
                        system.external_forces[:, inside] += f.T

        if loads or obstacles:
            sim.add_forcing_to(rod).using(Extra)
        sim.dampen(rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=nu, time_step=dt)
        sim.finalize()
        # rotational-inertia scaling (statics unchanged): a thin element's own inertia ρI·dl would make the
        # shear–rotation mode ω ≈ √(G/ρ)/r bound dt by r instead of L/N; raise it to the segment's m·dl²/12
        factor = max(1.0, dl**2 / (3 * r**2))
        rod.mass_second_moment_of_inertia[:] *= factor
        rod.inv_mass_second_moment_of_inertia[:] /= factor
        stepper = ea.PositionVerlet()
        v_tol = self.settle * L * w1
        t0 = time.perf_counter()
        tsim, steps, ok, msg = 0.0, 0, False, ""
        limit = self.max_time if max_time is None else max_time
        check = max(1, int(0.02 / (w1 * dt)))
        while time.perf_counter() - t0 < limit:
            for _ in range(check):
                tsim = stepper.step(sim, tsim, dt)
            steps += check
            v = np.abs(rod.velocity_collection).max()
            if not np.isfinite(v) or v > 1e3 * L * w1:
                msg = f"blew up at t = {tsim:.3g} s (dt = {dt:.2e} s)"
                break
            if v < v_tol and tsim > 3.0 / w1:
                ok, msg = True, f"settled at t = {tsim:.3g} s"
                break
        else:
            msg = f"not settled after {steps} steps (speed {v:.2e})"
        dt_wall = time.perf_counter() - t0
        pos = rod.position_collection.T.copy()
        s_nodes = np.concatenate([[0.0], np.cumsum(np.full(N, dl))])
        pts = interp_points(s_nodes, pos, S_OUT * L) if np.all(np.isfinite(pos)) else None
        frames_out = np.stack([np.stack([rod.director_collection[2, :, j], rod.director_collection[0, :, j],
                                         rod.director_collection[1, :, j]], axis=1) for j in range(N)])
        if ok:
            self.previous = (pos, frames_out, problem)
        strain = float(np.max(np.abs(rod.lengths / rod.rest_lengths - 1))) if np.all(np.isfinite(pos)) else np.nan
        return Outcome(ok, pts, dt_wall, steps, None, np.nan, msg, extra={"dt": dt, "steps": steps, "strain": strain,
                                                                           "nu": nu, "sim_time": tsim})


# ---------------------------------------------------------------------------------------------------
class MuJoCoRunner(PeerRunner):
    def __init__(self, case: Case, segments: int, radius: float = 0.002, zeta: float = 1.0, cfl: float = 0.5, **kw):
        super().__init__(case, segments, **kw)
        import mujoco  # noqa: F401

        self.radius, self.zeta, self.cfl = radius, zeta, cfl
        t0 = time.perf_counter()
        self._model(case.problem, *initial_polyline(case.problem, self.N, case.tau))
        self.build_time_s = time.perf_counter() - t0

    def _model(self, problem, nodes, frames):
        import mujoco

        L, N, r, Rf, Rt, D, E, G = self._constants(problem)
        dl = L / N
        # capsules overlap by their caps: density such that m' = 1 kg/m including the caps
        density = 1.0 / (np.pi * r**2 + (4.0 / 3.0) * np.pi * r**3 / dl)
        w1 = OMEGA1 * np.sqrt(Rf) / L**2
        w_max = np.sqrt(12 * Rf / dl**4)  # one segment's bending mode (m' = 1)
        dt = self.cfl * 2 / w_max
        g = problem.gravity_unit * D
        vert = " ".join(f"{v:.12g}" for v in nodes.ravel())
        # joint damping c: segment rotational inertia ~ dl³/12, critical for the first mode ~ ζ 2 ω₁ dl³/12 …
        # measured instead: c = ζ · 2 ω₁ · (L³/(12 N)) spreads the first mode's critical damping over the joints
        damping = self.zeta * 2 * w1 * L**3 / (12 * N) * 12 / np.pi**2
        # armature = a segment's bending inertia: raises the thin capsules' tiny twist inertia (statics unchanged),
        # so the explicit plugin forces are stable at the bending time step
        plane = ""
        for ob in problem.obstacles:
            pt, n = ob.point, ob.normal
            plane += (f'<geom type="plane" size="5 5 0.1" pos="{pt[0]} {pt[1]} {pt[2] - r}" zaxis="{n[0]} {n[1]} {n[2]}" '
                      'contype="0" conaffinity="2" condim="1" solref="0.002 1"/>')
        modes = {gg.name: gg.mode for gg in problem.grips}
        # near-hard equality (impedance 0.9999): a default soft weld lets the clamp turn by ~1 rad, because
        # its stiffness scales with the thin segment's tiny rotational inertia
        imp = 'solimp="0.9999 0.9999 0.001 0.5 2"'
        end = nodes[-1]
        weld = (f'<weld body1="cB_last" anchor="{end[0]} {end[1]} {end[2]}" solref="{2 * dt:.6g} 1" {imp}/>'
                if modes["right"] == "clamp" else
                f'<connect body1="cB_last" anchor="{dl} 0 0" solref="{2 * dt:.6g} 1" {imp}/>')
        first = "none" if modes["left"] == "clamp" else "ball"
        xml = f"""<mujoco><extension><plugin plugin="mujoco.elasticity.cable"/></extension>
<option timestep="{dt:.6g}" gravity="{g[0]} {g[1]} {g[2]}" integrator="implicitfast"/>
<worldbody>{plane}
<composite type="cable" prefix="c" initial="{first}" vertex="{vert}">
 <plugin plugin="mujoco.elasticity.cable"><config key="twist" value="{G:.9g}"/><config key="bend" value="{E:.9g}"/>
  <config key="vmax" value="0"/><config key="flat" value="true"/></plugin>
 <joint kind="main" damping="{damping:.6g}" armature="{dl**3 / 12:.6g}"/>
 <geom type="capsule" size="{r}" density="{density:.9g}" contype="2" conaffinity="0" condim="1"/>
</composite></worldbody>
<equality>{weld}</equality></mujoco>"""
        self.xml = xml
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        self.dt, self.w1, self.dl = dt, w1, dl
        self.body_ids = [mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, "cB_first")]
        self.body_ids = list(range(1, self.model.nbody))
        self.loads = problem.loads

    def _relax(self, problem, nodes, frames) -> Outcome:
        import mujoco

        t_build = time.perf_counter()
        self._model(problem, nodes, frames)  # the vertex list is the initial state; rebuilding is part of the cost
        m, d = self.model, self.data
        L, N = problem.string.length, self.N
        v_tol = self.settle * L * self.w1
        t0 = t_build
        steps, ok, msg = 0, False, ""
        check = max(1, int(0.02 / (self.w1 * self.dt)))
        load_bodies = []
        for ld in self.loads:
            k = min(int(round(ld.s / self.dl)), N - 1)
            load_bodies.append((self.body_ids[k], ld))
        v = np.inf
        while time.perf_counter() - t0 < self.max_time:
            for _ in range(check):
                d.xfrc_applied[:] = 0
                for b, ld in load_bodies:  # xfrc acts at the CoM: move the force to the segment's start node
                    d.xfrc_applied[b, 0:3] = ld.force
                    d.xfrc_applied[b, 3:6] = ld.moment + np.cross(d.xpos[b] - d.xipos[b], ld.force)
                mujoco.mj_step(m, d)
            steps += check
            # the largest node speed, from the bodies' linear velocities (cvel: rotation then translation)
            v = np.abs(d.cvel[1:, 3:]).max() if m.nbody > 1 else 0.0
            if not np.isfinite(v) or v > 1e3 * L * self.w1:
                msg = f"blew up after {steps} steps (dt = {self.dt:.2e} s)"
                break
            if v < v_tol and d.time > 3.0 / self.w1:
                ok, msg = True, f"settled at t = {d.time:.3g} s"
                break
        else:
            msg = f"not settled after {steps} steps (speed {v:.2e})"
        dt_wall = time.perf_counter() - t0
        pos = np.vstack([d.xpos[1:], d.xpos[-1] + d.xmat[-1].reshape(3, 3)[:, 0] * self.dl])
        s_nodes = np.arange(N + 1) * self.dl
        pts = interp_points(s_nodes, pos, S_OUT * L) if np.all(np.isfinite(pos)) else None
        if ok:
            fr = np.stack([d.xmat[i].reshape(3, 3) for i in range(1, m.nbody)])
            self.previous = (pos, fr, problem)
        return Outcome(ok, pts, dt_wall, steps, None, np.nan, msg, extra={"dt": self.dt, "steps": steps,
                                                                           "sim_time": d.time})


# ---------------------------------------------------------------------------------------------------
#: where mujoco-core 4 is installed for MuJoCoRodRunner's worker (the bench's own environment keeps mujoco
#: 3.17 for the cable peer): ``bash scripts/dlo-env run pip install --no-deps --target .bench-mujoco4 -r requirements-bench-mujoco4.txt``
MUJOCO4_DIR = Path(__file__).resolve().parents[2] / ".bench-mujoco4"


class MuJoCoRodRunner(PeerRunner):
    """MuJoCo 4's rod: a 1D flexcomp with discrete-elastic-rod bending and torsion, inextensible edges,
    relaxed to rest in a worker process (``mujoco_rod_worker.py``, which says how the rod is built).
    Line density 1 kg/m (mass scaling, as for the other peers); every vertex damped at ζ of the first
    mode (c = ζ · 2 ω₁ per unit mass); dt = cfl / (N ω₁).  The integrator is implicit in the rod's forces,
    so no segment mode bounds the step; what does is inextensibility.  MuJoCo's equality constraints are
    soft (impedance at most 0.9999, time constant 2 dt), and the rod shortens by about N² dt² in all,
    which moves the buckled shape several times as much: on the chord-0.6 elastica at N = 320, cfl 6 /
    3 / 1.5 shortened it by 0.18 / 0.05 / 0.01 % with errors 3.5e-2 / 8.7e-3 / 1.9e-3 L; cfl 1.5 leaves the
    first-order discretisation error in charge up to N = 160."""

    def __init__(self, case: Case, segments: int, radius: float = 0.005, zeta: float = 1.0, cfl: float = 1.5, **kw):
        super().__init__(case, segments, **kw)
        if not (MUJOCO4_DIR / "mujoco").is_dir():
            raise ImportError(f"mujoco-core 4 is not installed in {MUJOCO4_DIR} (see requirements-bench-mujoco4.txt)")
        if not case.planar and case.tau:
            raise NotImplementedError("the twisted case: the far end's turn is not held by the position equalities")
        self.radius, self.zeta, self.cfl = radius, zeta, cfl
        path = [str(MUJOCO4_DIR)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(path))
        self._worker = subprocess.Popen([sys.executable, "-u", str(Path(__file__).with_name("mujoco_rod_worker.py"))],
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
        weakref.finalize(self, _stop_worker, self._worker)
        t0 = time.perf_counter()
        first = self._call(self._job(case.problem, *initial_polyline(case.problem, self.N, case.tau), max_time=0.0))
        if "error" in first:
            raise RuntimeError(first["error"])
        self.version = first.get("mujoco", "?")
        self.build_time_s = time.perf_counter() - t0

    def _call(self, job: dict) -> dict:
        self._worker.stdin.write(json.dumps(job) + "\n")
        self._worker.stdin.flush()
        line = self._worker.stdout.readline()
        if not line:
            raise RuntimeError(f"the MuJoCo 4 worker exited ({self._worker.poll()})")
        return json.loads(line)

    def _job(self, problem, nodes, frames, max_time=None) -> dict:
        L, N, r, Rf, Rt, D, E, _ = self._constants(problem)
        w1 = OMEGA1 * np.sqrt(Rf) / L**2
        dt = self.cfl / (N * w1)
        modes = {g.name: g.mode for g in problem.grips}
        dl = L / N
        loads = [(min(int(round(ld.s / dl)), N), list(ld.force), list(ld.moment)) for ld in problem.loads]
        return {"nodes": nodes.tolist(), "segment": dl, "left": modes["left"], "right": modes["right"], "radius": r,
                "young": E, "poisson": min(max(Rf / Rt - 1.0, 0.0), 0.49) if Rt > 0 else 0.49, "mass": L * (N + 1) / N,
                "gravity": list(problem.gravity_unit * D), "planes": [(list(ob.point), list(ob.normal)) for ob in problem.obstacles],
                "loads": loads, "dt": dt, "damping_per_mass": self.zeta * 2 * w1, "contact_time": 2 * dt, "impedance": 0.9999, "constraint_time": 2 * dt,
                "check_every": max(1, int(0.02 / (w1 * dt))), "v_tol": self.settle * L * w1, "v_max": 1e3 * L * w1,
                "t_min": 3.0 / w1, "max_time": self.max_time if max_time is None else max_time}

    def _relax(self, problem, nodes, frames) -> Outcome:
        job = self._job(problem, nodes, frames)
        answer = self._call(job)
        if "error" in answer:
            return Outcome(False, None, np.nan, 0, None, np.nan, answer["error"])
        pos = np.asarray(answer["nodes"])
        L = problem.string.length
        pts = interp_points(np.arange(self.N + 1) * L / self.N, pos, S_OUT * L) if np.all(np.isfinite(pos)) else None
        if answer["ok"]:
            self.previous = (pos, None, problem)
        return Outcome(answer["ok"], pts, answer["wall_s"], answer["steps"], None, np.nan, answer["message"],
                       extra={"dt": job["dt"], "steps": answer["steps"],
                              "sim_time": answer["sim_time"]})


def _stop_worker(worker: subprocess.Popen) -> None:
    if worker.poll() is None:
        worker.stdin.close()
        try:
            worker.wait(timeout=5)
        except subprocess.TimeoutExpired:
            worker.kill()


def make_peer(method: str, setting, case: Case, **kw):
    if method == "pyelastica":
        return PyElasticaRunner(case, int(setting), **kw)
    if method == "mujoco":
        return MuJoCoRunner(case, int(setting), **kw)
    if method == "mujoco-rod":
        return MuJoCoRodRunner(case, int(setting), **kw)
    raise ValueError(method)
