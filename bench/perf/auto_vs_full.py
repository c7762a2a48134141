"""Warm-update time of solver.model auto against full, same run, same targets (issue 6's benchmark).

Five streams, each paced at 50 Hz (the solve time is measured; the rest of each 20 ms period is slept,
as in a node, so that auto's background checks get the time a real stream gives them):

* ``demo``: the main job's manoeuvre (dlo_ros.node.demo: the default cable plus a post, the ends
  brought together, the right end twisted by half a turn, the cable carried over the post), 450 targets.
  auto starts planar and must switch to 3D when the twist starts, and add the post when it comes within
  reach — the stream must not stall at those switches (the max column).
* ``planar``: the default cable, the right grip moving 1 % of L per update on a circle in its plane.
* ``twisted_3d``: the default cable with the right clamp turned 1.5 rad about its tangent and moved
  0.1 m out of plane, then the same circle.
* ``path3d hanging`` / ``path3d on the table``: #37's stream, the closed 3D path of
  test/unit/test_director_stream.py (2,000 updates), the cable hanging or lying on the table.

Methods: auto (checks on the worker thread, as the node runs it; given its start-up builds before the
stream starts — a switch within the first 2–3 s after start waits for them, about 1 s here), full at
the default order 16, and
the fixed model auto ends on ("same mesh": its reduced scene, options and element mesh, streamed
from the start: the ratio is auto's overhead alone, which #37 asks to keep within 1.1x).  Also
auto's updates over 20 ms and its end against a cold solve of the same mesh (#37: none, 1e-6 m).
Error: max centreline deviation at the last target from a full order-32 solve
warm-started from that method's own answer (same branch), with auto's largest obstacle sampling
(MAX_SAMPLES) and its Euler-angle pole turned to the direction farthest from that shape's tangents.  Times are ratios within one run.

    bash scripts/dlo-env run python bench/perf/auto_vs_full.py [--compile]
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

# one BLAS thread, as the `dlo` and `dlo_node` executables ask (dlo_ros/blas_threads.py): before
# numpy loads OpenBLAS.  Without it this bench measured OpenBLAS's thread wake-ups: table stream
# updates of 2-3 Newton steps at 40-50 ms while the check worker ran
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # as a script: `bench` importable
from bench.common import machine  # noqa: E402

from dlo_ros.model.problem import GripPose
from dlo_ros.model.rotations import farthest_pole, frame_with_pole
from dlo_ros.node import demo
from dlo_ros.scene import load_scene, scene_from_dict, scene_to_dict
from dlo_ros.solver import ShapeSolver, make_solver
from dlo_ros.solver.auto import MAX_SAMPLES
from dlo_ros.solver.shape_solver import with_checked_poses

PERIOD = 0.02  # s: 50 Hz, the demo driver's rate
SLOW_MS = 20.0  # #37: no single streamed update over 20 ms


def cold_gap(res, solver_args, solver_kw, poses) -> float:
    """Max centreline distance [m] of ``res`` from a cold solve of the same fixed model at
    ``poses`` (a new solver, no warm start; #37 asks for 1e-6 m: a stream's end must not depend on
    its path).  A cold solve that is not ok gives inf."""
    cold = ShapeSolver(with_checked_poses(solver_args[0], poses), *solver_args[1:], compile="off",
                       **solver_kw).solve()
    if not cold.ok:
        return float("inf")
    return float(np.max(np.linalg.norm(res.points - cold.points, axis=1)))


def cold_auto_gap(res, problem, options, poses) -> float:
    """Max centreline distance [m] of ``res`` from auto's own cold answer at ``poses`` (checks
    inline, as the CLI's one-shot solve): the same targets should give the same shape."""
    solver = make_solver(with_checked_poses(problem, poses), replace(options, model="auto"),
                         compile="off", checks="sync")
    try:
        cold = solver.solve()
    finally:
        solver.close()
    if not cold.ok:
        return float("inf")
    return float(np.max(np.linalg.norm(res.points - cold.points, axis=1)))


def demo_stream():
    d = scene_to_dict(load_scene("default_cable"))
    d["obstacles"] = list(d.get("obstacles", [])) + [dict(demo.POST)]
    scene = scene_from_dict(d)
    n = int(demo.duration() / PERIOD)
    targets = []
    for i in range(1, n + 1):
        (pl, ql), (pr, qr) = demo.targets_at(i * PERIOD)
        targets.append({"left": GripPose(pl, ql), "right": GripPose(pr, qr)})
    return "demo (default scene + post, main job's manoeuvre)", scene, targets


def circle(problem, updates=150):
    """Steps of 1 % of L around a circle of radius 0.05 L above the right grip's start."""
    L = problem.string.length
    right = problem.grip("right").pose
    r, da = 0.05 * L, 0.01 * L / (0.05 * L)
    return [{"right": GripPose(right.position + np.array([-r * np.sin(i * da), 0.0, r * (1 - np.cos(i * da))]),
                               right.orientation)} for i in range(1, updates + 1)]


def planar_stream():
    scene = load_scene("default_cable")
    return "planar (default cable, in-plane circle)", scene, circle(scene.problem)


def twisted_stream():
    scene = load_scene("default_cable")
    p = scene.problem
    right = p.grip("right")
    q = np.array([np.sin(0.75), 0.0, 0.0, np.cos(0.75)])  # 1.5 rad about x (the tangent)
    p = p.with_grip_poses({"right": GripPose(right.pose.position + np.array([0.0, 0.1, 0.0]), q)})
    scene = replace(scene, problem=p)
    return "twisted_3d (right clamp turned 1.5 rad, 0.1 m out of plane)", scene, circle(p)


def path3d_stream(on_table: bool):
    """#37's stream: default_cable, the right grip along the closed 3D path of
    test/unit/test_director_stream.py (2,000 updates: translation, yaw, pitch, ±1.2 rad of twist),
    hanging or with both grips lowered 0.32 m so that it lies on the table."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "test" / "unit"))
    from test_director_stream import UPDATES, path  # why here: test/unit is on the path only now

    scene = load_scene("default_cable")
    p = scene.problem
    if on_table:
        down = np.array([0.0, 0.0, 0.32])
        p = p.with_grip_poses({g.name: GripPose(g.pose.position - down, g.pose.orientation)
                               for g in p.grips})
        scene = replace(scene, problem=p)
    start = p.grip("right").pose.position
    targets = [{"right": GripPose(*path(k, start))} for k in range(1, UPDATES + 1)]
    where = "on the table" if on_table else "hanging"
    return f"path3d {where} (default cable, closed 3D path, {UPDATES} updates)", scene, targets


class Timed:
    """A solver's derivative function with the seconds spent in it added up."""

    def __init__(self, fn):
        self.fn, self.seconds = fn, 0.0

    def __call__(self, *args):
        t0 = time.perf_counter()
        out = self.fn(*args)
        self.seconds += time.perf_counter() - t0
        return out


def instrument(solver) -> list[Timed]:
    """Time ``solver``'s derivative evaluations (its compile must be finished or off)."""
    timers = []
    for name in ("newton_step", "kkt_free", "kkt", "obstacle_g"):
        fn = getattr(solver.functions, name, None)
        if fn is not None:
            timers.append(Timed(fn))
            setattr(solver.functions, name, timers[-1])
    return timers


def stream(solver, targets):
    """Solve every target at 50 Hz; (solve times [ms], last result, model changes with update index;
    index -1: the first, cold solve).  An update may be 'unverified' (a converged equilibrium whose residual
    is over the tolerance, published as such, which makes auto's check raise the order): it is counted
    as a change '<n> unverified', and a 'failed' one (past ``update_time_limit``) as '<n> failed';
    anything else stops the benchmark."""
    r = solver.solve()
    assert r.ok, r.message
    times, changes = [], [(-1, c) for c in r.model.changed or ()]
    unverified = failed = 0
    for i, poses in enumerate(targets):
        t0 = time.perf_counter()
        r = solver.solve(poses)
        dt = time.perf_counter() - t0
        assert r.status in ("ok", "unverified", "failed"), f"update {i}: {r.status}: {r.message}"
        unverified += r.status == "unverified"
        failed += r.status == "failed"
        times.append(dt * 1e3)
        changes += [(i, c) for c in r.model.changed or ()]
        time.sleep(max(0.0, PERIOD - dt))
    if unverified:
        changes.append((len(targets), f"{unverified} update(s) published unverified"))
    if failed:  # a streamed update past solver.update_time_limit: counted, the stream goes on
        changes.append((len(targets), f"{failed} update(s) failed"))
    return np.array(times), r, changes


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--compile", action="store_true", help="compiled KKT functions (blocking compile, cached)")
    ap.add_argument("--out", default="bench/results/auto_vs_full.md")
    ap.add_argument("--compiled-planar", action="store_true",
                    help="the planner's loop also with compiled derivatives for planar 12, full 12 and full 16 "
                         "(gcc: about a minute per model the first time, cached after)")
    ap.add_argument("--loop-only", action="store_true", help="only the planner's-loop table (printed, not written)")
    ap.add_argument("--only", default="", help="only the streams whose label contains this text (e.g. 'table')")
    args = ap.parse_args()
    mode = "blocking" if args.compile else "off"
    if not args.compile:
        os.environ["DLO_NO_COMPILE"] = "1"
    rows, notes = [], []
    streams = () if args.loop_only else (demo_stream(), planar_stream(), twisted_stream(),
                                         path3d_stream(False), path3d_stream(True))
    for label, scene, targets in (st for st in streams if args.only in st[0]):
        prob, opts = scene.problem, scene.options
        print(f"{label}: auto …", flush=True)
        auto = make_solver(prob, replace(opts, model="auto"), compile=mode, checks="background")
        auto.solve()
        auto._wait_for_check()  # its start-up builds (as in a node that has been up a few seconds)
        ta, ra, changes = stream(auto, targets)
        # let the checks of the last target finish, so the model and estimate describe the final answer
        for _ in range(40):  # a check takes effect CHECK_LAG updates after the one it checks
            auto._wait_for_check()
            ra = auto.solve(targets[-1])
            changes += [(len(targets), c) for c in ra.model.changed]
            if ra.model.checked and not auto.checks_pending:
                break
        m = ra.model.as_dict()
        # the fixed model auto ends on: its reduced scene, options and element mesh
        same_args = (auto.reduced.reduce(auto.choice, prob)[0], auto.inner.options)
        same_kw = dict(mesh=auto.inner.mesh_spec, reference_frame=auto.choice.reference_frame())
        auto.close()
        order = m["order"]
        print(f"{label}: full 16, full {order} …", flush=True)
        full16 = ShapeSolver(prob, replace(opts, model="full", order=16), compile=mode)
        tf, rf, _ = stream(full16, targets)
        end_vs_cold = cold_gap(ra, same_args, same_kw, targets[-1])
        end_vs_auto = cold_auto_gap(ra, prob, opts, targets[-1])
        same = ShapeSolver(*same_args, compile=mode, **same_kw)
        ts, rs, _ = stream(same, targets)
        def err(res, solver):
            """Deviation from the reference on ``solver``'s own branch: order 32, warm-started from its last
            shape, with the Euler-angle pole turned to the direction farthest from that shape's tangents
            (near the pole the order does not converge: on the post, order 32 in the scene's first frame
            is 56 mm off).  Each method gets its own reference: the post has mirror-image branches."""
            frame = None
            if not solver.nlp.director:  # an Euler-angle model: its reference gets the pole turned away
                tangents = solver.model.node_tangents(solver.snapshot().z).T
                frame = frame_with_pole(farthest_pole(tangents)[0], solver.nlp.r0[:, 0])
            # the reference's scene is at the last target: adopt_warm_start maps a shape onto the adopting
            # solver's own poses (and its topology check counts clamp turns from them)
            # and the obstacle samples auto may go up to: a string resting on the post slides along it
            # with almost no change of energy, so the sampled contact moves it by millimetres (the
            # default 41 samples: 1 cm; see the auto module docstring)
            ref_solver = ShapeSolver(with_checked_poses(prob, targets[-1]),
                                     replace(opts, model="full", order=32, quadrature_nodes=80,
                                             obstacle_samples=MAX_SAMPLES, update_time_limit=0.0),
                                     compile="off",
                                     reference_frame=frame)
            ref_solver.adopt_warm_start(solver)
            ref = ref_solver.solve(targets[-1])
            assert ref.ok, ref.message
            return float(np.max(np.linalg.norm(res.points - ref.points, axis=1)))

        rows.append(dict(label=label, m=m, ta=ta, tf=tf, ts=ts, ea=err(ra, auto.inner), ef=err(rf, full16), es=err(rs, same),
                         nf=full16.model.layout.size, ns=same.model.layout.size, order=order,
                         cold=end_vs_cold, cold_auto=end_vs_auto))
        notes.append((label, changes))

    # The planner's loop: the same planar targets solved back to back (no pacing), one model at a time (as a
    # planner runs one), the three fixed models taking turns for 5 passes; the time spent evaluating
    # derivatives (the model-dependent part) is measured inside each update.
    loop_rows = []
    label, scene, targets = planar_stream()
    modes = ["off"] + (["blocking"] if args.compiled_planar else [])
    for mode in modes:
        if mode == "blocking":
            os.environ.pop("DLO_NO_COMPILE", None)
        print(f"planner loop ({'compiled' if mode == 'blocking' else 'interpreted'}) …", flush=True)
        solvers = {f"{model}, order {order}": ShapeSolver(scene.problem, replace(scene.options, model=model, order=order),
                                                          compile=mode)
                   for model, order in (("planar", 12), ("full", 12), ("full", 16))}
        timers = {name: instrument(solver) for name, solver in solvers.items()}
        total = {name: [] for name in solvers}
        deriv = {name: [] for name in solvers}
        for _ in range(5):
            for name, solver in solvers.items():
                solver.reset()
                assert solver.solve().ok
                for poses in targets:
                    d0 = sum(t.seconds for t in timers[name])
                    t0 = time.perf_counter()
                    r = solver.solve(poses)
                    total[name].append((time.perf_counter() - t0) * 1e3)
                    deriv[name].append((sum(t.seconds for t in timers[name]) - d0) * 1e3)
                    assert r.ok, r.message
        for name, solver in solvers.items():
            loop_rows.append(dict(mode="compiled (gcc -O1)" if solver.kkt_compiled else "interpreted", name=name,
                                  n=solver.model.layout.size, instr=solver.nlp.kkt_free_fn.n_instructions(),
                                  total=np.array(total[name]), deriv=np.array(deriv[name])))

    def stats(t):
        return f"{np.median(t):.2f} / {np.percentile(t, 99):.1f} / {t.max():.0f}"

    def slow(t):
        return f"{int(np.sum(t > SLOW_MS))} (max at {int(np.argmax(t))})"

    info = machine()
    load = ", ".join(f"{x:.2f}" for x in info.get("load_average", ()))

    lines = [
        "# solver.model auto vs full: streamed warm updates", "",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; derivatives "
        f"{'compiled (gcc -O1)' if args.compile else 'interpreted CasADi'}; targets streamed at 50 Hz; "
        f"auto with background checks (as the node runs it). Run {time.strftime('%Y-%m-%d %H:%M')}, "
        f"git {info.get('git', '?')}, load average at the end {load} (1/5/15 min).",
        f"Times per update in ms: median / p99 / max. Error: max centreline deviation at the last target from a "
        f"full order-32 solve with {MAX_SAMPLES} obstacle samples at the last target, warm-started from that method's answer (same branch; an "
        "Euler-angle model's with its pole turned away from the shape); the tolerance is 1 mm. "
        f"Over {SLOW_MS:g} ms: auto's updates slower than that (#37: none), and the index of its "
        "slowest. "
        "End vs cold: auto's last shape against a cold solve at the last target (#37: within "
        "1e-6 m), of the fixed same mesh / of auto itself (checks inline, as `dlo solve`).", "",
        "| stream | auto's final model | unknowns auto / full 16 / same mesh | auto | full 16 | fixed, same mesh | "
        "full 16 / auto (median) | same mesh / auto (median) | error auto / full 16 / same mesh [m] | auto estimate [m] "
        "| auto over 20 ms | auto end vs cold: same mesh / auto [m] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        m = r["m"]
        kind = ", ".join(k for k in ("planar", "twist", "stretch", "gravity") if m[k]) or "3D"
        kind = ("" if m["planar"] else "3D, ") + kind + f", order {m['order']}, {m['obstacles']} obstacle(s)"
        est = m["estimated_error_m"]
        lines.append(
            f"| {r['label']} | {kind} | {m['variables']} / {r['nf']} / {r['ns']} | {stats(r['ta'])} | {stats(r['tf'])} | "
            f"{stats(r['ts'])} | {np.median(r['tf']) / np.median(r['ta']):.2f} | {np.median(r['ts']) / np.median(r['ta']):.2f} | "
            f"{r['ea']:.1e} / {r['ef']:.1e} / {r['es']:.1e} | {'—' if est is None else f'{est:.1e}'} | "
            f"{slow(r['ta'])} | {r['cold']:.1e} / {r['cold_auto']:.1e} |")
    lines += ["", "## The planner's loop: the planar stream back to back", "",
              "The same 150 in-plane targets solved one after another without pacing (a planner evaluating "
              "candidates), one fixed model at a time, the three taking turns for 5 passes. *Derivatives* is the time "
              "spent in the KKT and obstacle-value functions inside each update (what the model costs); "
              "*rest* is the per-update work common to every model (pose checks, parameters, the Newton "
              "solves, output sampling, the stability eigenvalue, grip wrenches). Medians in ms.", "",
              "| derivatives | model | unknowns | KKT instructions (contact-free) | update | derivatives | rest "
              "| full 16 / this (update) | full 16 / this (derivatives) |", "|---|---|---|---|---|---|---|---|---|"]
    for mode in dict.fromkeys(r["mode"] for r in loop_rows):
        rows_m = [r for r in loop_rows if r["mode"] == mode]
        ref = rows_m[-1]
        for r in rows_m:
            lines.append(
                f"| {mode} | {r['name']} | {r['n']} | {r['instr']} | {np.median(r['total']):.3f} | "
                f"{np.median(r['deriv']):.3f} | {np.median(r['total'] - r['deriv']):.3f} | "
                f"{np.median(ref['total']) / np.median(r['total']):.2f} | {np.median(ref['deriv']) / np.median(r['deriv']):.2f} |")
    lines += ["", "Model changes auto made while streaming (update index: reason; "
              f"{len(rows[0]['ta']) if rows else 0} = after the stream, while the last checks finished):", ""]
    for label, changes in notes:
        lines.append(f"* {label}: " + ("; ".join(f"{i}: {c}" for i, c in changes) if changes else "none"))
    flags = (" --compile" if args.compile else "") + (" --compiled-planar" if args.compiled_planar else "")
    lines += ["", f"Command: `bash scripts/dlo-env run python bench/perf/auto_vs_full.py{flags}`", ""]
    if args.loop_only:
        print("\n".join(lines))
        return
    Path(args.out).write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
