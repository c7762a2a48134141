"""Charts (PNG, matplotlib) and markdown tables for bench/suite/run_all.py."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from bench.methods.runners import METHOD_LABELS, PEERS

COLORS = {"paper": "#000000", "fourier": "#1f77b4", "fourier-3d": "#17becf", "fourier-3d-z": "#bcbd22", "default": "#d62728", "default-planar": "#ff7f0e",
          "rod": "#2ca02c", "pyelastica": "#9467bd", "mujoco": "#8c564b",
          "mujoco-rod": "#e377c2"}
MARKERS = {"paper": "*", "fourier": "s", "fourier-3d": "x", "fourier-3d-z": "+", "default": "o", "default-planar": "D", "rod": "^", "pyelastica": "v",
           "mujoco": "P", "mujoco-rod": "X"}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def fmt(x, spec=".2g"):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "—"
    if isinstance(x, (bool, np.bool_)):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return str(x)
    return format(float(x), spec)


def mark(marks, method: str, key: str = "sym", sep: str = " ") -> str:
    """The footnote mark (or its short text) of a method row re-run later than the rest (see run_all.rerun_marks)."""
    return sep + marks[method][key] if marks and method in marks else ""


def footnotes(marks, methods) -> str:
    """The footnotes of the marked rows among ``methods``, to put under a table."""
    return "".join(f"\n{marks[m]['note']}\n" for m in dict.fromkeys(methods) if marks and m in marks)


# ---------------------------------------------------------------------------------------------------
def pareto_chart(result: dict, path: Path, marks=None) -> None:
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(13, 6.2), sharey=True)
    rows = result["rows"]
    floor = max(result["reference"].get("spread", 0.0), 1e-12)
    for ax, mode in zip(axes, ("cold", "warm")):
        for method in COLORS:
            rs = [r for r in rows if r["method"] == method and f"{mode}_s" in r]
            if not rs:
                continue
            xs = np.array([r.get(f"{mode}_s", np.nan) for r in rs], float)
            ys = np.array([r.get(f"{mode}_err", np.nan) for r in rs], float)
            oks = [bool(r.get(f"{mode}_ok")) and r.get(f"{mode}_stable") is not False for r in rs]
            builds = [r.get("build_s", np.nan) for r in rs]
            good = np.isfinite(xs) & np.isfinite(ys)
            if not good.any():
                continue
            label = (f"{METHOD_LABELS[method]} (build {np.nanmin(builds):.2g}–{np.nanmax(builds):.2g} s)"
                     + mark(marks, method, "short"))
            ax.plot(xs[good], np.maximum(ys[good], 1e-12), "-", color=COLORS[method], alpha=0.6, lw=1.2)
            for x, y, ok, r in zip(xs, ys, oks, rs):
                if not (np.isfinite(x) and np.isfinite(y)):
                    continue
                ax.plot(x, max(y, 1e-12), MARKERS[method], color=COLORS[method], ms=7 if method != "paper" else 12,
                        mfc=COLORS[method] if ok else "white")
                ax.annotate(str(r["setting"]), (x, max(y, 1e-12)), fontsize=6, xytext=(3, 2), textcoords="offset points")
            ax.plot([], [], MARKERS[method] + "-", color=COLORS[method], label=label)
        ax.set_xscale("log")
        if floor > 1e-9:
            ax.axhline(floor, color="gray", ls=":", lw=1)
            ax.text(0.01, floor * 1.15, "reference uncertainty", fontsize=7, color="gray",
                    transform=ax.get_yaxis_transform())
        ax.set_yscale("log")
        ax.set_xlabel(f"time per solve, {mode} [s]")
        ax.grid(True, which="both", alpha=0.25)
        ax.set_title(f"{mode}" + (" (from the 1 % L neighbour)" if mode == "warm" else ""))
    axes[0].set_ylabel("max centreline error / L")
    handles, labels = axes[1].get_legend_handles_labels()
    fig.suptitle(result["title"] + "   (hollow marker: failed, or stationary point called unstable)", fontsize=10)
    fig.tight_layout(rect=(0, 0.16, 1, 1))
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=7, frameon=False)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def pareto_table(result: dict, marks=None) -> str:
    ref = result["reference"]
    lines = [f"### {result['title']}", "",
             f"Reference: {ref.get('kind')}, energy {fmt(ref.get('energy'), '.6g')} J, own uncertainty "
             f"{fmt(ref.get('spread'), '.1e')} L (computed in {result['reference_time_s']:.1f} s)."
             + (" Errors are taken after the best rotation about the chord (neutral without gravity)." if result.get("align") else ""),
             "",
             "| method | setting | build [s] | cold [s] | cold error/L | cold iters | stable | E − E_ref [J] | warm [s] | warm error/L | warm iters | note |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        note = r.get("error") or ("" if r.get("cold_ok") else str(r.get("cold_msg", ""))[:60])
        if r["method"] in PEERS and "peer" in r:
            pe = r["peer"]
            note = (note + " " if note else "") + f"dt {pe.get('dt', np.nan):.1e} s, {int(pe.get('steps', 0))} steps"
        lines.append(
            f"| {r['method']}{mark(marks, r['method'], sep='')} | {r['setting']} | {fmt(r.get('build_s'))} | "
            f"{fmt(r.get('cold_s'), '.3g')} | "
            f"{fmt(r.get('cold_err'), '.1e')} | {fmt(r.get('cold_iter'))} | {fmt(r.get('cold_stable'))} | {fmt(r.get('dE'), '.2g')} | "
            f"{fmt(r.get('warm_s'), '.3g')} | {fmt(r.get('warm_err'), '.1e')} | {fmt(r.get('warm_iter'))} | {note} |")
    return "\n".join(lines) + "\n" + footnotes(marks, [r["method"] for r in result["rows"]])


# ---------------------------------------------------------------------------------------------------
CAT_TEXT = {3.0: "✓", 2.0: "✓u", 1.25: "↓", 1.0: "✗", 0.5: "✗u", 0.0: "F"}


def sweep_labels(res: dict, pi_digits: int, weight_prefix: str = "") -> list[str]:
    """The labels of a sweep's values: turns in π, weights ρ, chords and jumps in L."""
    if res["sweep"] == "rotation":
        return [f"{v / np.pi:.{pi_digits}g}π" for v in res["values"]]
    if res["sweep"] == "weight":
        return [f"{weight_prefix}{v:g}" for v in res["values"]]
    return [f"{v:g}L" for v in res["values"]]


def stability_chart(results: list[dict], path: Path, marks=None) -> None:
    plt = _plt()
    from matplotlib.colors import BoundaryNorm, ListedColormap

    cmap = ListedColormap(["#d62728", "#ff9896", "#ffdd57", "#c5b0d5", "#9ecae1", "#2ca02c"])
    norm = BoundaryNorm([-0.1, 0.25, 0.75, 1.1, 1.5, 2.5, 3.1], cmap.N)
    fig, axes = plt.subplots(len(results), 1, figsize=(13, 3.0 * len(results)))
    for ax, res in zip(np.atleast_1d(axes), results):
        keys = list(res["cells"])
        grid = np.array([[c.get("cat", 0.0) for c in res["cells"][k]] for k in keys])
        ax.imshow(grid, cmap=cmap, norm=norm, aspect="auto")
        for i, k in enumerate(keys):
            for j, c in enumerate(res["cells"][k]):
                txt = CAT_TEXT[c.get("cat", 0.0)]
                if c.get("iters") is not None and c.get("cat", 0) > 0:
                    txt += f"\n{c['iters']}"
                ax.text(j, i, txt, ha="center", va="center", fontsize=6)
        ax.set_yticks(range(len(keys)))
        ax.set_yticklabels([k + mark(marks, k.split()[0], "short", "\n") for k in keys], fontsize=7)
        labels = sweep_labels(res, pi_digits=2)
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels(labels, fontsize=7)
        ax.set_title({"compression": "compression: chord (cold solves)", "rotation": "end rotation τ at chord 0.6L (continuation)",
                      "weight": "weight ρ = D L³/Rf, table at −0.25L (cold solves)",
                      "jump": "single jump of the right grip by δ (warm from chord 0.7L)"}[res["sweep"]], fontsize=9)
    fig.suptitle("Stability map — ✓ right equilibrium (stable or no verdict), ✓u right but called unstable, ↓ another "
                 "equilibrium of lower energy than the reference,\n✗ wrong equilibrium, ✗u wrong and unstable, F failed; "
                 "number = iterations (Nelder–Mead: function evaluations; peers: time steps)", fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def stability_table(res: dict, marks=None) -> str:
    vals = res["values"]
    head = sweep_labels(res, pi_digits=3, weight_prefix="ρ=")
    lines = [f"### {res['sweep']}", "", "| method | " + " | ".join(head) + " |", "|---" * (len(vals) + 1) + "|"]
    for k, cells in res["cells"].items():
        entries = []
        for c in cells:
            t = CAT_TEXT[c.get("cat", 0.0)]
            if c.get("cat", 0) > 0:
                t += f" {fmt(c.get('err'), '.0e')} ({c.get('iters')})"
            entries.append(t)
        lines.append(f"| {k}{mark(marks, k.split()[0], sep='')} | " + " | ".join(entries) + " |")
    lines.append("| reference stable | " + " | ".join(fmt(s) for s in res["reference_stable"]) + " |")
    if any(res.get("reference_kind", [])):
        lines.append("| reference | " + " | ".join(k or "—" for k in res["reference_kind"]) + " |")
    return "\n".join(lines) + "\n" + footnotes(marks, [k.split()[0] for k in res["cells"]])
