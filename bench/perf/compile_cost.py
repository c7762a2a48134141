"""What compiling a scene's Newton system costs and what it buys (issue #14, "compile time in seconds").

    bash scripts/dlo-env run python bench/perf/compile_cost.py [--models planar:8 full:8 full:12 full:16 full:32]
        [--flattened-up-to 12]
        [--out bench/results/compile_cost.md]

For ``default_cable`` with each fixed model, every function a solve evaluates — the contact-free KKT
function of a warm update (``kkt_free``: Newton matrix and residual), the KKT function over every row
(``kkt``) and the inequality rows' values (``obstacle_g``) — built two ways, side by side:

* assembled: what the package builds (``solver/build/assembled.py`` for director models,
  ``solver/build/assembled_euler.py`` for the planar and Euler-angle models: a loop over quadrature nodes plus
  sparse products);
* flattened: CasADi SX AD of the whole NLP expression (what the package built before).

For each: CasADi instructions, size of the generated C, time to generate it and to compile it with gcc
(``compiled.FLAGS`` as ``solver/build/compiled.py`` does; the flattened ones at -O1, as the package did), and
the time per call interpreted (``InterpretedFunction``) and compiled (``NativeFunction``) at the solved
equilibrium, all measured in the same run.  Then "start-up to full speed": a ShapeSolver of the scene
with ``compile='blocking'`` and an empty cache, from the constructor to every function compiled and the
first solve done.  Nothing is cached between rows.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # the repository
sys.path.insert(0, str(ROOT))  # run as a script: make `bench` importable

from bench.common import machine  # noqa: E402

from dlo_ros.scene import load_scene  # noqa: E402
from dlo_ros.solver.build.compiled import FLAGS, InterpretedFunction, NativeFunction  # noqa: E402
from dlo_ros.solver.native import cache_store  # noqa: E402
from dlo_ros.solver.options import SolverOptions  # noqa: E402
from dlo_ros.solver.shape_solver import ShapeSolver  # noqa: E402


def per_call_ms(fn, args, calls: int = 200) -> float:
    fn(*args)
    t0 = time.perf_counter()
    for _ in range(calls):
        fn(*args)
    return (time.perf_counter() - t0) / calls * 1e3


def flattened(nlp) -> dict[str, ca.Function]:
    """The three functions by SX AD of the whole NLP (as StringNLP built them for every model)."""
    z, p, f, g = (nlp.nlp[k] for k in ("x", "p", "f", "g"))
    nf, rows = nlp.n_free_rows, g.shape[0]
    energies = ca.densify(ca.vertcat(*nlp.energy_fn(z, p)))
    grad_f = ca.densify(ca.gradient(f, z))
    lam, lam_free = ca.SX.sym("lam", rows), ca.SX.sym("lam_free", nf)
    hess = ca.hessian(f + ca.dot(lam, g), z)[0]
    hess_free = ca.hessian(f + ca.dot(lam_free, g[:nf]), z)[0]
    jac_free, jac = ca.jacobian(g[:nf], z), ca.jacobian(g, z)
    kkt = ca.blockcat([[hess_free, jac_free.T], [jac_free, ca.SX(nf, nf)]])
    out = {"kkt_free": ca.Function("flat_kkt_free", [z, p, lam_free],
                                   [ca.densify(kkt), ca.densify(ca.vertcat(grad_f + ca.mtimes(jac_free.T, lam_free),
                                                                           g[:nf])), grad_f, energies]),
           "kkt": ca.Function("flat_kkt", [z, p, lam], [grad_f, ca.densify(g), ca.densify(jac), ca.densify(hess),
                                                         energies])}
    if nf < rows:
        out["obstacle_g"] = ca.Function("flat_obstacle_g", [z, p], [ca.densify(g[nf:])])
    return out


#: gcc's flags for the flattened functions: -O1, as the package compiled them (at -O3 gcc ran for minutes on
#: planar 8's flattened kkt)
FLATTENED_FLAGS = ("-O1",)


def cost(fn: ca.Function, args: list, flags: tuple[str, ...] = FLAGS) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        gen = ca.CodeGenerator(fn.name() + ".c", {"with_header": False})
        gen.add(fn)
        gen.generate(tmp + os.sep)
        generate_s = time.perf_counter() - t0
        source = Path(tmp, fn.name() + ".c")
        t0 = time.perf_counter()
        built = Path(tmp, "built.so")
        subprocess.run(["gcc", "-shared", "-fPIC", *flags, "-o", str(built), str(source), "-lm"], check=True)
        gcc_s = time.perf_counter() - t0
        # the cache loads a library only with its sha256 record (cache_store.py): stored as the package does
        lib = Path(tmp, "cache", "lib.so")
        if not cache_store.store(lib, built.read_bytes()):
            raise RuntimeError(f"could not store {lib}")
        native = NativeFunction(lib, fn)
        interpreted = InterpretedFunction(fn)
        error = max(float(np.max(np.abs(a - b))) for a, b in zip(native(*args), interpreted(*args)))
        return {"instructions": fn.n_instructions(), "c_kb": source.stat().st_size // 1024, "generate_s": generate_s,
                "gcc_s": gcc_s, "interpreted_ms": per_call_ms(interpreted, args),
                "compiled_ms": per_call_ms(native, args), "error": error}


def measure(model: str, order: int, flattened_up_to: int) -> list[dict]:
    scene = load_scene("default_cable")
    solver = ShapeSolver(scene.problem, SolverOptions(model=model, order=order), compile="off")
    solver.solve()
    nlp, state = solver.nlp, solver.snapshot()
    nf = nlp.n_free_rows
    args = {"kkt_free": [state.z, state.p, state.lam_g[:nf]], "kkt": [state.z, state.p, state.lam_g],
            "obstacle_g": [state.z, state.p]}
    built = {"kkt_free": nlp.kkt_free_fn, "kkt": nlp.kkt_fn, "obstacle_g": nlp.obstacle_g_fn}
    rows = []
    flat = flattened(nlp) if order <= flattened_up_to else {}
    for name, fn in built.items():
        if fn is None:
            continue
        for how, f in (("assembled", fn), ("flattened", flat.get(name))):
            if f is None:
                continue
            rows.append({"model": f"{model} {order}", "unknowns": state.z.size, "function": name, "how": how,
                         **cost(f, args[name], FLAGS if how == "assembled" else FLATTENED_FLAGS)})
            r = rows[-1]
            print(f"{r['model']} {name} {how}: {r['instructions']} instr, gcc {r['gcc_s']:.1f} s, "
                  f"{r['interpreted_ms']:.3f} / {r['compiled_ms']:.3f} ms", flush=True)
    return rows


def start_up(model: str, order: int) -> dict:
    """Constructor → every function compiled and loaded (blocking, empty cache) → first solve."""
    scene = load_scene("default_cable")
    with tempfile.TemporaryDirectory() as cache:
        os.environ["DLO_CACHE_DIR"] = cache
        t0 = time.perf_counter()
        solver = ShapeSolver(scene.problem, SolverOptions(model=model, order=order), compile="blocking")
        result = solver.solve()
        seconds = time.perf_counter() - t0
        return {"model": f"{model} {order}", "seconds": seconds, "compiled": solver.functions.compiled,
                "status": result.status}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", nargs="+", default=["planar:8", "full:8", "full:12", "full:16", "full:32"])
    ap.add_argument("--flattened-up-to", type=int, default=12,
                    help="build the flattened functions only up to this order (gcc takes minutes beyond)")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "compile_cost.md"))
    args = ap.parse_args()
    t0 = time.time()
    rows, starts = [], []
    for spec in args.models:
        model, order = spec.split(":")
        rows += measure(model, int(order), args.flattened_up_to)
    for spec in args.models:
        model, order = spec.split(":")
        starts.append(start_up(model, int(order)))
        print(f"start-up {starts[-1]}", flush=True)
    info = machine()
    lines = [
        "# Compiling the Newton system: cost and gain (issue #14)",
        "",
        f"Machine: {info.get('cpu')}, {info.get('cpus')} cores (shared; load average "
        f"{', '.join(f'{v:.2f}' for v in info.get('load_average', ()))} at the end), Python {info['python']}; "
        f"git {info.get('git')}.",
        f"Command: `bash scripts/dlo-env run python bench/perf/compile_cost.py --models {' '.join(args.models)} "
        f"--flattened-up-to {args.flattened_up_to}` "
        f"({(time.time() - t0) / 60:.1f} min).",
        "",
        "`default_cable`, every function a solve evaluates, at the solved equilibrium: `kkt_free` (the Newton "
        "matrix and residual of a contact-free warm update), `kkt` (every row), `obstacle_g` (the inequality "
        "rows' values). *assembled*: what the package builds (`solver/build/assembled.py`, `solver/build/assembled_euler.py`); "
        "*flattened*: SX AD of the whole NLP, what it built before. "
        f"gcc {' '.join(FLAGS)} as `solver/build/compiled.py` runs it (the flattened functions: "
        f"{' '.join(FLATTENED_FLAGS)}, as the package compiled them); times per call: mean of 200 calls; "
        "|compiled − interpreted| "
        "is the largest difference of any output.",
        "",
        "| model | unknowns | function | built | CasADi instructions | C [KB] | generate C [s] | gcc [s] "
        "| interpreted [ms] | compiled [ms] | interpreted / compiled | \\|compiled − interpreted\\| |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['model']} | {r['unknowns']} | {r['function']} | {r['how']} | {r['instructions']} "
                     f"| {r['c_kb']} | {r['generate_s']:.1f} | {r['gcc_s']:.1f} | {r['interpreted_ms']:.3f} "
                     f"| {r['compiled_ms']:.3f} | {r['interpreted_ms'] / r['compiled_ms']:.2f} | {r['error']:.1e} |")
    lines += ["", "Ratios of the two constructions, same run (flattened / assembled):", "",
              "| model | function | gcc time | interpreted call | compiled call |", "|---|---|---|---|---|"]
    for r in rows:
        if r["how"] != "assembled":
            continue
        f = next((x for x in rows if x["model"] == r["model"] and x["function"] == r["function"]
                  and x["how"] == "flattened"), None)
        if f is None:
            continue
        lines.append(f"| {r['model']} | {r['function']} | {f['gcc_s'] / r['gcc_s']:.0f}× "
                     f"| {f['interpreted_ms'] / r['interpreted_ms']:.2f}× | {f['compiled_ms'] / r['compiled_ms']:.2f}× |")
    lines += ["", "Start-up to full speed (a new scene structure, empty cache, `compile='blocking'`: build the NLP, "
              "generate and compile every function, first solve):", "",
              "| model | seconds | all compiled | first solve |", "|---|---|---|---|"]
    for s in starts:
        lines.append(f"| {s['model']} | {s['seconds']:.1f} | {s['compiled']} | {s['status']} |")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
