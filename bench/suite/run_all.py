"""Issue 5: the speed-vs-accuracy benchmark, the stability map and the paper's examples, in one command.

    bash scripts/dlo-env run pip install -r requirements-bench.txt      # once: matplotlib, tqdm, pyelastica, mujoco
    bash scripts/dlo-env run pip install --no-deps --target .bench-mujoco4 -r requirements-bench-mujoco4.txt   # once: MuJoCo 4
    bash scripts/dlo-env run python bench/suite/run_all.py [--quick] [--only pareto,stability,paper]
    bash scripts/dlo-env run python bench/suite/run_all.py --methods fourier-3d-z   # re-run some rows, merge into raw.json

Writes PNG charts and markdown tables into bench/results/ (see bench/README.md for what each shows).
Timings are wall-clock on this machine while others may share it: compare them only as ratios within
one run (every file records the machine and the load average).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # run as a script: make `bench` importable

from bench.common import RESULTS as OUT, ROOT, machine  # noqa: E402
from bench.methods.runners import METHOD_LABELS  # noqa: E402
from bench.suite import paper_examples as paper  # noqa: E402
from bench.suite import pareto, peer_tuning, stability  # noqa: E402
from bench.suite.report import (_plt, fmt, footnotes, mark, pareto_chart, pareto_table, stability_chart,  # noqa: E402
                                stability_table)


def _bar(total):
    try:
        from tqdm import tqdm

        return tqdm(total=total, dynamic_ncols=True, mininterval=1.0, desc="bench")
    except ImportError:  # pragma: no cover
        class Plain:
            n = 0

            def update(self, k):
                self.n += k
                print(f"[{self.n}/{total}]", flush=True)

            def set_postfix_str(self, s):
                print("  ", s, flush=True)

            def close(self):
                pass

        return Plain()


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.bool_,)):
        return bool(o)
    return str(o)


def header(info: dict, quick: bool, started: float) -> str:
    return (f"Machine: {info.get('cpu')}, {info.get('cpus')} CPUs, Python {info.get('python')}, {info.get('platform')}; "
            f"load average at start {tuple(round(x, 2) for x in info.get('load_average', ()))}; git {info.get('git')}; "
            f"mode {'--quick' if quick else 'full'}; generated {time.strftime('%Y-%m-%d %H:%M', time.localtime(started))}. "
            "Timings are wall-clock with the machine shared: compare them as ratios within this run only.\n")


# ---------------------------------------------------------------------------------------------------
def headline(results: list[dict], mode: str, tol: float, marks=None) -> str:
    """Fastest setting of each method reaching max error ≤ tol·L (right equilibrium), per case."""
    cases = [r["case"] for r in results]
    lines = [f"| method ({mode}, error ≤ {tol:g} L) | " + " | ".join(cases) + " |", "|---" * (len(cases) + 1) + "|"]
    for method, label in METHOD_LABELS.items():
        cells = []
        for res in results:
            best = None
            for r in res["rows"]:
                if r["method"] != method or not r.get(f"{mode}_ok"):
                    continue
                e, t = r.get(f"{mode}_err", np.nan), r.get(f"{mode}_s", np.nan)
                if np.isfinite(e) and e <= tol and (best is None or t < best[0]):
                    best = (t, r["setting"])
            ran = any(r["method"] == method for r in res["rows"])
            cells.append(f"{best[0] * 1e3:.3g} ms ({best[1]})" if best else ("not reached" if ran else "n/a"))
        if any(c != "n/a" for c in cells):
            lines.append(f"| {label}{mark(marks, method, sep='')} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n" + footnotes(marks, [m for m in METHOD_LABELS if any(
        r["method"] == m for res in results for r in res["rows"])])


def run_pareto(quick: bool, bar, log) -> list[dict]:
    results = []
    for case in pareto.cases(quick):
        res = pareto.run_case(case, quick, log=log, bar=bar)
        pareto_chart(res, OUT / f"pareto_{case.name}.png")
        results.append(res)
    return results


def write_pareto(results, info, quick, started, marks=None):
    text = ["# Speed vs accuracy (issue 5)", "", header(info, quick, started),
            "One chart per case: `pareto_<case>.png` (left cold, right warm; log–log; one line per method, "
            "labels = order / segments; build time in the legend).  Error = max over 101 points of "
            "|x(s) − x_ref(s)| / L.  *cold*: from the method's own initial guess (twist case: continuation "
            "from the untwisted state in 8 equal turns, summed).  *warm*: after a converged solve with the far "
            "grip 0.01 L further out.  Times: IPOPT/Nelder–Mead/time stepping only for the bench's own models; "
            "ShapeSolver's include its stability check and outputs; the peers' exclude building the model except "
            "MuJoCo's, which is rebuilt from the vertex list at every solve.  Build = NLP construction (CasADi + "
            "IPOPT set-up; interpreted derivatives, `compile='off'`), or numba JIT for PyElastica.", "",
            "## Fastest setting reaching 1e-3 L", "", headline(results, "cold", 1e-3, marks), "",
            headline(results, "warm", 1e-3, marks), "", "## Fastest setting reaching 1e-5 L", "",
            headline(results, "cold", 1e-5, marks), "", headline(results, "warm", 1e-5, marks), "", "## Every run", ""]
    for res in results:
        text.append(pareto_table(res, marks))
        text.append(f"![{res['case']}](pareto_{res['case']}.png)\n")
    (OUT / "speed_accuracy.md").write_text("\n".join(text))


def run_stability(quick: bool, bar, log) -> list[dict]:
    results = [stability.run_sweep(s, quick, bar=bar, log=log) for s in stability.SWEEPS]
    stability_chart(results, OUT / "stability_map.png")
    return results


def write_stability(results, info, quick, started, marks=None):
    text = ["# Stability map (issue 5)", "", header(info, quick, started),
            "![stability map](stability_map.png)", "",
            "Cells: ✓ right equilibrium (max error to the reference < 0.05 L) with a stable verdict (or none: the "
            "peers), ✓u right but the method called it unstable, ✗ a different equilibrium, ✗u a different and "
            "unstable one, F no convergence; then the error/L and iterations (Nelder–Mead: function evaluations; "
            "peers: time steps).  How each sweep runs and what its reference is: bench/suite/stability.py.", ""]
    for res in results:
        text.append(stability_table(res, marks))
        if res["sweep"] == "weight":
            text.append("Reference energies of the stable equilibria found (J): "
                        + "; ".join(f"ρ={v:g}: {e}" for v, e in zip(res["values"], res["reference_energies"])) + "\n")
    (OUT / "stability.md").write_text("\n".join(text))


# ---------------------------------------------------------------------------------------------------
def run_paper(quick: bool, bar, log) -> dict:
    out = {}
    for name, fn in (("fig2", paper.fig2), ("fig3", paper.fig3), ("fig5", paper.fig5), ("sheets", paper.sheets)):
        bar.set_postfix_str(f"paper {name}")
        out[name] = fn(quick)
        bar.update(1)
    charts_paper(out)
    return out


def _save(plt, fig, name: str, title: str | None = None) -> None:
    """Title (if any), lay out, write ``OUT / name`` and close one of the paper's figures."""
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(OUT / name, dpi=110)
    plt.close(fig)


def charts_paper(out: dict) -> None:
    plt = _plt()
    f2 = out["fig2"]
    chords = f2["chords"]
    fig, axes = plt.subplots(3, len(chords), figsize=(2.3 * len(chords), 6.6))
    views = (("top (x–y)", 0, 1), ("front (x–z)", 0, 2), ("side (y–z)", 1, 2))
    for j, c in enumerate(chords):
        for i, (vname, a, b) in enumerate(views):
            ax = axes[i, j]
            for key, style, lab in (("cont", "-", "default, continuation"), ("cold", ":", "default, cold"),
                                    ("rod", "--", "quaternion rod")):
                pts = f2["shapes"].get((key, round(c, 2)))
                if pts is not None:
                    ax.plot(pts[:, a], pts[:, b], style, lw=1.3, label=lab)
            ax.set_aspect("equal", "datalim")
            ax.tick_params(labelsize=6)
            if i == 0:
                ax.set_title(f"{c}L", fontsize=9)
            if j == 0:
                ax.set_ylabel(vname, fontsize=8)
    axes[0, 0].legend(fontsize=6)
    _save(plt, fig, "paper_fig2.png",
          "Paper Fig. 2: ends brought together (s=0 clamped; s=L tangent held, twist free; Rf/Rt = 100)")

    f3 = out["fig3"]
    floors = f3["floors"]
    fig, axes = plt.subplots(1, len(floors), figsize=(3.2 * len(floors), 3.4), sharey=True)
    for ax, fl in zip(axes, floors):
        for rho in f3["rhos"]:
            pts = f3["shapes"].get((fl, rho))
            if pts is not None:
                ax.plot(pts[:, 0], pts[:, 2], label=f"ρ={rho:g}")
        if fl is not None:
            ax.axhline(fl, color="k", lw=2)
        ax.set_title("no floor" if fl is None else f"floor at {fl}L", fontsize=9)
        ax.set_aspect("equal", "datalim")
        ax.tick_params(labelsize=7)
    axes[0].legend(fontsize=6)
    _save(plt, fig, "paper_fig3.png",
          "Paper Fig. 3: lowest stable shape at chord 0.7L, horizontal clamps, for ρ = 0 … 5000 (planar rod N=200)")

    f5 = out["fig5"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for kind, r in f5.items():
        m = np.array(r["magnitudes"])
        axes[0].plot(m, r["lambda_x"], label=kind)
        axes[1].plot(m, r["x_end"], label=kind)
        if r["critical_from_reaction"]:
            axes[0].axvline(r["critical_from_reaction"], ls=":", lw=0.8)
    axes[0].axhline(0, color="k", lw=0.8)
    axes[0].set_xlabel("magnitude [Rf/L² for the force, Rf/L for the moment]")
    axes[0].set_ylabel("finger's inward push on the right end [Rf/L²]")
    axes[1].set_xlabel("magnitude")
    axes[1].set_ylabel("x(L) with the end free to slide inward [L]")
    for ax in axes:
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    _save(plt, fig, "paper_fig5.png",
          "Paper Fig. 5: when does the right end leave the finger? (pinned ends 0.8L apart on a floor, load at s = 0.5L)")

    sh = out["sheets"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    for (name, chord, th, branch), r in sh.items():
        ax = axes[0] if "rect" in name else axes[1]
        if r["points"] is not None:
            line, = ax.plot(r["points"][:, 0] * 1e3, r["points"][:, 2] * 1e3, "-" if th == 0 else "--",
                            label=f"l = {chord * 1e3:g} mm, θ(0) = {th:g}°, {branch}")
    axes[0].set_title("rectangle 200×30 mm (Fig. 7), planar rod N=200", fontsize=9)
    axes[1].set_title("trapezoid, width 50→100 mm (Fig. 8): Rf and D vary along s", fontsize=9)
    for ax in axes:
        ax.set_aspect("equal", "datalim")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("z [mm]")
        ax.legend(fontsize=6)
        ax.grid(alpha=0.3)
    _save(plt, fig, "paper_sheets.png")


def write_paper(out, info, quick, started):
    t = ["# The paper's examples, reproduced (issue 5)", "", header(info, quick, started)]
    f2 = out["fig2"]
    t += ["## Fig. 2 — transitions as the ends come together", "", "![fig2](paper_fig2.png)", "",
          "Paper: planar at 0.8L and 0.7L; twisted and non-planar at 0.6L and 0.5L; one knot (loop) at 0.4L and 0.3L.", "",
          "| chord | solver | status | stable | energy [J] | out of plane / L | |writhe| | crossings top/front/side | message |",
          "|---|---|---|---|---|---|---|---|---|"]
    for key in ("continuation", "cold", "rod"):
        for r in f2[key]:
            t.append(f"| {r['chord']:.1f} | {key} | {r.get('status', 'ok' if r.get('ok') else 'failed')} | {fmt(r.get('stable'))} | "
                     f"{fmt(r.get('energy'), '.4f')} | {fmt(r.get('out_of_plane'), '.3f')} | {fmt(abs(r.get('writhe', np.nan)), '.2f')} | "
                     f"{r.get('crossings_top', '—')}/{r.get('crossings_front', '—')}/{r.get('crossings_side', '—')} | "
                     f"{str(r.get('message', ''))[:90]} |")
    f3 = out["fig3"]
    t += ["", "## Fig. 3 — weight, and the floor the paper must have had", "", "![fig3](paper_fig3.png)", "",
          "Lowest-energy stable equilibrium among six starts (sag down, sag up, four skewed) of the planar rod "
          "(N = 200), chord 0.7L, horizontal clamps (L = 1 m, Rf = 1 N m², so E is in units of Rf/L; gravity "
          "energy measured from the clamps' height unless stated).  'asymmetric' = lower than every symmetric "
          "equilibrium (the paper's criterion), found by solving with β(s) = −β(L − s) imposed.  Self-contact is "
          "not modelled (nor in the paper): shapes with self-crossings are not physical.", "",
          "| floor [L] | ρ | stable equilibria | lowest | E lowest | U_bend lowest | asymmetry [L] | self-crossings | lowest / highest point [L] | E symmetric-constrained | U_bend sym.-constr. | E_sym/E_lowest, gravity from the floor (paper: 0.746/0.518 = 1.44 at ρ = 3000) |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in f3["rows"]:
        ratio = None
        if r["E_sym_constrained"] is not None and r["E_lowest"] is not None:
            lift = r["rho"] * (-(r["floor"] or 0.0))  # D·h·L: gravity energy measured from the floor
            ratio = (r["E_sym_constrained"] + lift) / (r["E_lowest"] + lift) if (r["E_lowest"] + lift) else None
        t.append(f"| {'none' if r['floor'] is None else r['floor']} | {r['rho']:g} | {r['n_stable']} | {r['lowest']} | "
                 f"{fmt(r['E_lowest'], '.5g')} | {fmt(r['U_bend_lowest'], '.4g')} | {fmt(r['asymmetry'], '.3f')} | "
                 f"{fmt(r['crossings'])} | {fmt(r['min_height'], '.3f')} / {fmt(r['max_height'], '.3f')} | "
                 f"{fmt(r['E_sym_constrained'], '.5g')} | {fmt(r['U_bend_sym_constrained'], '.4g')} | {fmt(ratio, '.4f')} |")
    f5 = out["fig5"]
    t += ["", "## Fig. 5 — force and moment: when the right end leaves the finger", "", "![fig5](paper_fig5.png)", "",
          "| load | critical magnitude (reaction changes sign) | first magnitude at which x(L) < l (sliding model) | paper |",
          "|---|---|---|---|"]
    paper_vals = {"force": "0.14 Rf/L (sic)", "moment+": "0.17 Rf", "moment-": "0.17 Rf"}
    for kind, r in f5.items():
        t.append(f"| {kind} | {fmt(r['critical_from_reaction'], '.3g')} | {fmt(r['first_slide_magnitude'], '.3g')} | {paper_vals[kind]} |")
    sh = out["sheets"]
    t += ["", "## Paper sheets (Figs. 7, 8)", "", "![sheets](paper_sheets.png)", "",
          "Both branches of each sheet (buckled up, hanging down): planar rod N = 200; the default solver "
          "(Chebyshev 16, planar model) finds the branch its gravity-ward guess leads to, compared where it is the same branch.", "",
          "| scene | l [mm] | θ(0) | branch | stable | energy [J] | highest [mm] | lowest [mm] | |z| max at x [mm] | default vs rod [mm] |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for (name, chord, th, branch), r in sh.items():
        t.append(f"| {name} | {chord * 1e3:g} | {th:g}° | {branch} | {fmt(r['stable'])} | {fmt(r['energy_J'], '.4g')} | "
                 f"{fmt(r['peak_mm'], '.3g')} | {fmt(r['lowest_mm'], '.3g')} | {fmt(r['peak_x_mm'], '.3g')} | "
                 f"{fmt(r['default_vs_rod_mm'], '.2g')} |")
    (OUT / "paper_examples.md").write_text("\n".join(t) + "\n")


# ---------------------------------------------------------------------------------------------------
def rerun_marks(raw: dict) -> dict:
    """Footnote marks (†, ††, …) for the method rows that ``--methods`` re-ran after the run behind the rest."""
    marks = {}
    for i, (method, run) in enumerate(raw.get("method_runs", {}).items()):
        sym = "†" * (i + 1)
        marks[method] = {"sym": sym, "short": f"re-run {run['started'][:10]}",
                         "note": f"{sym} Row {METHOD_LABELS[method].split()[0]} (`{method}`) re-run on {run['started']} "
                                 f"(git {run['git']}){' ' + run['note'] if run.get('note') else ''}; the other rows are "
                                 f"from {raw['started']} (git {raw['machine'].get('git')}). Its times are from a "
                                 "different run: compare them with the other rows only roughly."}
    return marks


def render(raw: dict) -> None:
    """The pareto and stability charts and tables from a raw dict (as read from raw*.json)."""
    info, quick, marks = raw["machine"], raw["quick"], rerun_marks(raw)
    started = time.mktime(time.strptime(raw.get("started", time.strftime("%Y-%m-%d %H:%M")), "%Y-%m-%d %H:%M"))
    if "pareto" in raw:
        for res in raw["pareto"]:
            pareto_chart(res, OUT / f"pareto_{res['case']}.png", marks)
        write_pareto(raw["pareto"], info, quick, started, marks)
    if "stability" in raw:
        stability_chart(raw["stability"], OUT / "stability_map.png", marks)
        write_stability(raw["stability"], info, quick, started, marks)


def rerun(methods: set, parts: set, quick: bool, note: str) -> int:
    """Run the pareto and stability parts for ``methods`` only, replace their rows (case by case, sweep by
    sweep) in raw*.json, record the run per method, and re-render every chart and table from the merge."""
    path = OUT / ("raw_quick.json" if quick else "raw.json")
    raw = json.loads(path.read_text())
    if methods - set(METHOD_LABELS):
        sys.exit(f"--methods: unknown {sorted(methods - set(METHOD_LABELS))}; known: {', '.join(METHOD_LABELS)}")
    if raw["quick"] != quick:
        sys.exit(f"--methods: {path.name} does not come from a {'--quick' if quick else 'full'} run")
    started, info = time.time(), machine()
    dirty = subprocess.run(["git", "status", "--porcelain", "--", "dlo_ros"], capture_output=True, text=True,
                           cwd=ROOT).stdout.strip()
    log_file = (OUT / "run_all.log").open("a")  # the earlier run's tracebacks stay: its rows stay too
    log_file.write(f"\n=== --methods {','.join(sorted(methods))}, {time.strftime('%Y-%m-%d %H:%M')} ===\n")

    def log(msg):
        log_file.write(str(msg) + "\n")
        log_file.flush()

    cases = pareto.cases(quick, methods) if "pareto" in parts else []
    sweeps = [s for s in stability.SWEEPS if stability.sweep_methods(s, methods)] if "stability" in parts else []
    bar = _bar(sum(len(pareto.settings(c, quick, methods)) for c in cases)
               + sum(len(stability.sweep_methods(s, methods)) for s in sweeps))
    import warnings

    warnings.filterwarnings("ignore")
    for case in cases:
        new = pareto.run_case(case, quick, log=log, bar=bar, methods=methods)
        old = next((r for r in raw.setdefault("pareto", []) if r["case"] == new["case"]), None)
        if old is None:
            raw["pareto"].append(new)
            continue
        old["rows"] = [r for r in old["rows"] if r["method"] not in methods] + new["rows"]
        old["rows"].sort(key=lambda r: list(METHOD_LABELS).index(r["method"]))  # stable: settings keep their order
    for sweep in sweeps:
        new = stability.run_sweep(sweep, quick, bar=bar, log=log, methods=methods)
        old = next((r for r in raw.setdefault("stability", []) if r["sweep"] == sweep), None)
        if old is None:
            raw["stability"].append(new)
            continue
        if old["values"] != new["values"]:
            sys.exit(f"--methods: the {sweep} sweep's points changed since {path.name}; run everything instead")
        for k in ("reference_stable", "reference_kind"):
            if json.loads(json.dumps(new[k], default=_json_default)) != old[k]:
                log(f"warning: {sweep} sweep: {k} differs from the earlier run's: {new[k]} vs {old[k]}")
        old["cells"].update(new["cells"])
    bar.close()
    elapsed = time.time() - started
    run = {"started": time.strftime("%Y-%m-%d %H:%M", time.localtime(started)),
           "git": info.get("git", "?") + (" + local changes in dlo_ros/" if dirty else ""),
           "load_average": info.get("load_average"), "elapsed_s": elapsed, "note": note}
    raw.setdefault("method_runs", {}).update({m: run for m in sorted(methods)})
    path.write_text(json.dumps(raw, default=_json_default, indent=1))
    render(json.loads(path.read_text()))
    print(f"bench/suite/run_all.py --methods: done in {elapsed / 60:.1f} min; merged into {path}")
    log(f"elapsed {elapsed:.1f} s")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer cases, settings and sweep points (~15 min here)")
    ap.add_argument("--only", default="peers,pareto,stability,paper",
                    help="comma-separated subset of peers (settings study), pareto, stability, paper")
    ap.add_argument("--from-json", metavar="RAW", help="re-render the pareto and stability charts and tables from a "
                    "raw*.json of an earlier run (no solving)")
    ap.add_argument("--methods", metavar="M1,M2", help="run the pareto and stability parts (as limited by --only) for "
                    "these method rows only, e.g. fourier-3d-z; replace their rows in results/raw.json (raw_quick.json "
                    "with --quick), record the run date per method and re-render every chart and table from the merge")
    ap.add_argument("--note", default="", help="with --methods: why the rows were re-run, for raw.json and the "
                    "tables' footnotes (e.g. 'after the pole fix')")
    args = ap.parse_args(argv)
    parts = set(args.only.split(","))
    if args.from_json:
        render(json.loads(Path(args.from_json).read_text()))
        return 0
    if args.methods:
        return rerun(set(args.methods.split(",")), parts, args.quick, args.note)
    OUT.mkdir(parents=True, exist_ok=True)
    started = time.time()
    info = machine()
    log_path = OUT / "run_all.log"
    log_file = log_path.open("w")

    def log(msg):
        log_file.write(str(msg) + "\n")
        log_file.flush()

    total = (peer_tuning.count() if "peers" in parts else 0) + (pareto.count(args.quick) if "pareto" in parts else 0) + \
            (stability.count(args.quick) if "stability" in parts else 0) + (4 if "paper" in parts else 0)
    bar = _bar(total)
    raw = {"machine": info, "quick": args.quick, "started": time.strftime("%Y-%m-%d %H:%M", time.localtime(started))}
    import warnings

    warnings.filterwarnings("ignore")
    if "peers" in parts:
        rows = peer_tuning.run(args.quick, bar)
        (OUT / "peers_tuning.md").write_text(
            "# Dynamic peers: how their settings were chosen (issue 5)\n\n" + header(info, args.quick, started) + "\n"
            + peer_tuning.__doc__.split("\n\n", 1)[1] + "\n" + peer_tuning.table(rows))
        raw["peers"] = rows
    if "pareto" in parts:
        res = run_pareto(args.quick, bar, log)
        write_pareto(res, info, args.quick, started)
        raw["pareto"] = res
    if "stability" in parts:
        res = run_stability(args.quick, bar, log)
        write_stability(res, info, args.quick, started)
        raw["stability"] = res
    if "paper" in parts:
        res = run_paper(args.quick, bar, log)
        write_paper(res, info, args.quick, started)
        raw["paper"] = {k: ({str(kk): vv for kk, vv in v.items() if kk != "shapes"} if isinstance(v, dict) else v)
                        for k, v in res.items() if k != "sheets"}
    bar.close()
    elapsed = time.time() - started
    raw["elapsed_s"] = elapsed
    name = "raw_quick.json" if args.quick else "raw.json"
    (OUT / name).write_text(json.dumps(raw, default=_json_default, indent=1))
    print(f"bench/suite/run_all.py: done in {elapsed / 60:.1f} min; results in {OUT}")
    log(f"elapsed {elapsed:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
