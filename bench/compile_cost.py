"""What compiling a scene's Newton system costs and what it buys (issue #14, "compile time in seconds").

    bash scripts/dlo-env run python bench/compile_cost.py [--models planar:8 full:8 full:12 full:16]
        [--out bench/results/compile_cost.md]

For ``default_cable`` with each fixed model, the contact-free KKT function a warm update evaluates
(``StringNLP.kkt_free_fn``: the Newton matrix and residual): its CasADi instruction count, the size of
the generated C, the time to generate it and to compile it with gcc -O1 (as ``solver/compiled.py``
does), and the time per call interpreted (``InterpretedFunction``) and compiled (``NativeFunction``) at
the solved equilibrium, with their ratio measured in the same run.  Nothing is cached: the C is built
in a temporary directory each time.
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

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from common import machine  # noqa: E402

from dlo_ros.scene import load_scene  # noqa: E402
from dlo_ros.solver.compiled import InterpretedFunction, NativeFunction  # noqa: E402
from dlo_ros.solver.options import SolverOptions  # noqa: E402
from dlo_ros.solver.shape_solver import ShapeSolver  # noqa: E402


def per_call_ms(fn, args, calls: int = 200) -> float:
    fn(*args)
    t0 = time.perf_counter()
    for _ in range(calls):
        fn(*args)
    return (time.perf_counter() - t0) / calls * 1e3


def measure(model: str, order: int) -> dict:
    scene = load_scene("default_cable")
    solver = ShapeSolver(scene.problem, SolverOptions(model=model, order=order), compile="off")
    result = solver.solve()
    fn = solver.nlp.kkt_free_fn
    state = solver.snapshot()
    args = [state.z, state.p, state.lam_g[: solver.nlp.n_free_rows]]
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        gen = ca.CodeGenerator(fn.name() + ".c")
        gen.add(fn)
        gen.generate(tmp + "/")
        generate_s = time.perf_counter() - t0
        source = Path(tmp, fn.name() + ".c")
        t0 = time.perf_counter()
        subprocess.run(["gcc", "-shared", "-fPIC", "-O1", "-o", str(Path(tmp, "lib.so")), str(source), "-lm"],
                       check=True)
        gcc_s = time.perf_counter() - t0
        native = NativeFunction(Path(tmp, "lib.so"), fn)
        interpreted = InterpretedFunction(fn)
        t_int, t_nat = per_call_ms(interpreted, args), per_call_ms(native, args)
        return {"model": f"{model} {order}", "status": result.status, "unknowns": state.z.size,
                "instructions": fn.n_instructions(), "c_kb": source.stat().st_size // 1024,
                "generate_s": generate_s, "gcc_s": gcc_s, "interpreted_ms": t_int, "compiled_ms": t_nat}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", nargs="+", default=["planar:8", "full:8", "full:12", "full:16"])
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "compile_cost.md"))
    args = ap.parse_args()
    info = machine()
    t0 = time.time()
    rows = []
    for spec in args.models:
        model, order = spec.split(":")
        rows.append(measure(model, int(order)))
        r = rows[-1]
        print(f"{r['model']}: {r['instructions']} instructions, gcc {r['gcc_s']:.1f} s, "
              f"{r['interpreted_ms']:.3f} / {r['compiled_ms']:.3f} ms", flush=True)
    lines = [
        "# Compiling the Newton system: cost and gain (issue #14)",
        "",
        f"Machine: {info.get('cpu')}, {info.get('cpus')} cores (shared; load average "
        f"{', '.join(f'{v:.2f}' for v in info.get('load_average', ()))} at the end), Python {info['python']}; "
        f"git {info.get('git')}.",
        f"Command: `bash scripts/dlo-env run python bench/compile_cost.py --models {' '.join(args.models)}` "
        f"({(time.time() - t0) / 60:.1f} min).",
        "",
        "`default_cable`, the contact-free KKT function of a warm update (`kkt_free_fn`), evaluated at the "
        "solved equilibrium. gcc -O1 as `solver/compiled.py` runs it. Times per call: mean of 200 calls.",
        "",
        "| model | unknowns | CasADi instructions | C [KB] | generate C [s] | gcc -O1 [s] | interpreted [ms] "
        "| compiled [ms] | interpreted / compiled |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['model']} | {r['unknowns']} | {r['instructions']} | {r['c_kb']} | {r['generate_s']:.1f} "
                     f"| {r['gcc_s']:.1f} | {r['interpreted_ms']:.3f} | {r['compiled_ms']:.3f} "
                     f"| {r['interpreted_ms'] / r['compiled_ms']:.2f} |")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
