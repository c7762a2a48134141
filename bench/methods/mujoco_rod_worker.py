"""MuJoCo 4's rod (a 1D flexcomp with discrete-elastic-rod elasticity), relaxed to rest: the worker process.

MuJoCo 4 removed the cable plugin that ``peers.MuJoCoRunner`` is built from, so the bench keeps
mujoco 3.17 for that peer and runs this one in its own process, with mujoco-core 4 first on its path
(``peers.MuJoCoRodRunner`` starts it; ``MUJOCO4_DIR`` in peers.py says where it is installed).  This module
imports only numpy and mujoco.  Protocol: one JSON job per stdin line, one JSON answer per stdout line.

The rod: N + 1 vertices, ``<edge equality="true"/>`` (inextensible: near-hard, impedance 0.9999, as the
far end's equalities; MuJoCo's default is far too soft for a line density of 1 kg/m),
``<elasticity young poisson>`` with a circular section of the flex radius (bending E I, torsion G J).  Its reference configuration
qpos0 is straight (MuJoCo keeps the bending of qpos0 as the rest curvature), laid from the left grip
along its tangent; ``<pin id="0 1"/>`` clamps the first edge there (``id="0"`` for a pin).  The far end's
vertices are held at their targets by connect equalities between sites (the last two for a clamp).  The
run starts from the job's polyline (qpos), with the weight per length as gravity on a line density of
1 kg/m (the flexcomp's mass is spread evenly over its N + 1 points, so the job asks for L (N + 1)/N),
point loads as forces on the nearest vertex (a moment as two couples, one on each edge at that vertex),
planes as plane geoms, no self-collision (at N = 160 the capsules of elements two apart overlap), and
damps every vertex's motion (dof damping c = 2 ζ ω₁ m_vertex) until the largest vertex speed is below
``v_tol`` after ``t_min``.  Integrator: ``discrete`` with the Newton
solver (MuJoCo's advice for rods: bending and torsion implicit).
"""
from __future__ import annotations

import json
import os
import sys
import time

import numpy as np


def build(job: dict):
    """The compiled model and data for ``job`` (see ``relax``), with qpos at the job's polyline."""
    import mujoco

    nodes = np.asarray(job["nodes"], float)
    n = len(nodes) - 1
    dl = float(job["segment"])
    start, tangent = nodes[0], nodes[1] - nodes[0]
    tangent = tangent / np.linalg.norm(tangent)
    straight = start + np.outer(np.arange(n + 1) * dl, tangent)
    pts = " ".join(f"{v:.15g}" for v in straight.ravel())
    elements = " ".join(f"{i} {i + 1}" for i in range(n))
    pins = "0" if job["left"] == "pin" else "0 1"  # a clamp or a tangent grip holds the first edge's direction
    held = [n] if job["right"] == "pin" else [n - 1, n]
    r = float(job["radius"])
    planes = "".join(
        f'<geom type="plane" size="5 5 0.1" pos="{p[0] - r * q[0]:.15g} {p[1] - r * q[1]:.15g} {p[2] - r * q[2]:.15g}" '
        f'zaxis="{q[0]:.15g} {q[1]:.15g} {q[2]:.15g}" condim="1" solref="{job["contact_time"]:.6g} 1"/>'
        for p, q in job["planes"])
    targets = "".join(f'<site name="target{k}" pos="{nodes[k][0]:.15g} {nodes[k][1]:.15g} {nodes[k][2]:.15g}"/>'
                      for k in held)
    g = job["gravity"]
    xml = f"""<mujoco><option timestep="{job['dt']:.8g}" gravity="{g[0]:.15g} {g[1]:.15g} {g[2]:.15g}"
 integrator="discrete" solver="Newton"/>
<worldbody>{planes}{targets}
<flexcomp name="rod" type="direct" dim="1" point="{pts}" element="{elements}" radius="{r:.8g}" mass="{job['mass']:.15g}">
 <edge equality="true" solref="{job['constraint_time']:.8g} 1" solimp="{job['impedance']} {job['impedance']} 0.001 0.5 2"/><elasticity young="{job['young']:.10g}" poisson="{job['poisson']:.10g}"/>
 <contact condim="1" selfcollide="none" solref="{job['contact_time']:.6g} 1"/><pin id="{pins}"/>
</flexcomp></worldbody></mujoco>"""
    spec = mujoco.MjSpec.from_string(xml)
    imp = [job["impedance"], job["impedance"], 0.001, 0.5, 2.0]  # near-hard
    for k in held:
        spec.body(f"rod_{k}").add_site(name=f"end{k}")
        spec.add_equality(type=mujoco.mjtEq.mjEQ_CONNECT, objtype=mujoco.mjtObj.mjOBJ_SITE, name1=f"end{k}",
                          name2=f"target{k}", solref=[job["constraint_time"], 1.0], solimp=imp)
    model = spec.compile()
    data = mujoco.MjData(model)
    vertex_bodies = {}
    for k in range(n + 1):
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"rod_{k}")
        if b >= 0:
            vertex_bodies[k] = b
            adr = model.jnt_qposadr[model.body_jntadr[b]]
            data.qpos[adr:adr + 3] = nodes[k] - straight[k]  # three slide joints along x, y, z
            model.dof_damping[model.body_dofadr[b]:model.body_dofadr[b] + 3] = job["damping_per_mass"] * model.body_mass[b]
    mujoco.mj_forward(model, data)
    return model, data, vertex_bodies, straight


def vertex_positions(data, vertex_bodies: dict, straight: np.ndarray) -> np.ndarray:
    pos = straight.copy()
    for k, b in vertex_bodies.items():
        pos[k] = data.xpos[b]
    return pos


def relax(job: dict) -> dict:
    """Relax the rod of ``job`` (nodes, segment, left/right grip modes, radius, young, poisson, mass,
    gravity, planes [(point, normal)], loads [(vertex, force, moment)], dt, damping_per_mass,
    contact_time, impedance, constraint_time, check_every, v_tol, v_max, t_min, max_time) and return its
    vertices, whether it settled, a message, the wall time (model build included, as for the cable peer),
    the steps and the simulated time."""
    import mujoco

    t0 = time.perf_counter()
    model, data, vertex_bodies, straight = build(job)
    n = len(straight) - 1
    loads = [(int(k), np.asarray(f, float), np.asarray(m, float)) for k, f, m in job["loads"]]
    check = max(1, int(job["check_every"]))
    steps, ok, msg, v = 0, False, "", np.inf
    slide = np.concatenate([np.arange(model.body_dofadr[b], model.body_dofadr[b] + 3) for b in vertex_bodies.values()])
    while time.perf_counter() - t0 < job["max_time"]:
        for _ in range(check):
            data.xfrc_applied[:] = 0.0
            pos = None
            for k, f, m in loads:
                if k in vertex_bodies:
                    data.xfrc_applied[vertex_bodies[k], :3] += f
                if np.any(m):  # half the moment on each edge at vertex k, as a couple (its part normal to the edge)
                    pos = vertex_positions(data, vertex_bodies, straight) if pos is None else pos
                    edges = [j for j in (k - 1, k) if 0 <= j < n]
                    for j in edges:
                        e = pos[j + 1] - pos[j]
                        couple = np.cross(m / len(edges), e) / float(e @ e)
                        for idx, sign in ((j + 1, 1.0), (j, -1.0)):
                            if idx in vertex_bodies:
                                data.xfrc_applied[vertex_bodies[idx], :3] += sign * couple
            mujoco.mj_step(model, data)
        steps += check
        v = float(np.abs(data.qvel[slide]).max())
        if not np.isfinite(v) or v > job["v_max"]:
            msg = f"blew up after {steps} steps (dt = {job['dt']:.2e} s)"
            break
        if v < job["v_tol"] and data.time > job["t_min"]:
            ok, msg = True, f"settled at t = {data.time:.3g} s"
            break
    else:
        msg = f"not settled after {steps} steps (speed {v:.2e})"
    wall = time.perf_counter() - t0
    pos = vertex_positions(data, vertex_bodies, straight)
    return {"ok": ok, "nodes": pos.tolist(), "message": msg, "wall_s": wall, "steps": steps, "sim_time": float(data.time),
            "mujoco": mujoco.__version__}


def main() -> None:
    # the answers get their own descriptor; fd 1 (where MuJoCo's C library may print) goes to stderr
    answers = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
    for line in sys.stdin:
        if not line.strip():
            continue
        try:
            answer = relax(json.loads(line))
        except Exception as exc:  # noqa: BLE001 - reported to the parent, which records it as the method's error
            answer = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
        answers.write(json.dumps(answer) + "\n")
        answers.flush()


if __name__ == "__main__":
    main()
