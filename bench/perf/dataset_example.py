"""#39's example: a certified data set of the main job's scene (the default cable and the post it is laid on),
10,000 samples, its manifest, and a chart of what it holds.

    bash scripts/dlo-env run python bench/perf/dataset_example.py [--samples 10000] [--out shapes_main_job/]

The scene is the main job's (``dlo_ros.node.demo.write_demo_scene``: ``default_cable`` plus the sphere 'post');
the plan (``config/plans/main_job_on_post.yaml``) puts both grips anywhere in boxes around the main job's last
pose, above the post, orientations kept.  The data set is written to ``--out`` (resumable: run the same
command with ``--resume``); its manifest is copied to ``bench/results/dataset_example_manifest.json`` and a
summary to ``bench/results/dataset_example.md``.  With matplotlib (``requirements-bench.txt``) it also draws
``bench/results/dataset_example.png``: the grip forces of stable and unstable answers, where the right grip was
for each status, and a sample of centrelines with the unstable equilibria the solver met beside them.
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # as a script: `bench` importable

from bench.common import machine  # noqa: E402

from dlo_ros.dataset import build_dataset, load_arrays, plan_from_dict, read_plan  # noqa: E402
from dlo_ros.node import demo  # noqa: E402
from dlo_ros.scene import load_scene  # noqa: E402

RESULTS = ROOT / "bench" / "results"


def chart(a: dict, path: Path) -> bool:
    """Draw the data set's chart to ``path``; False when matplotlib is not installed."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    ok = a["status"] == "ok"
    stable = ok & np.array([s is True for s in a["stable"]])
    unstable = ok & np.array([s is False for s in a["stable"]])
    fig, ax = plt.subplots(1, 3, figsize=(16, 5))
    force = np.linalg.norm(a["grip_force"], axis=2)  # (N, grips)
    bins = np.linspace(0.0, np.nanmax(force[ok]) if ok.any() else 1.0, 40)
    for g, name in enumerate(("left", "right")):
        ax[0].hist(force[stable, g], bins=bins, alpha=0.5, label=f"{name} grip, stable ({stable.sum()})")
    if unstable.any():
        ax[0].hist(force[unstable].ravel(), bins=bins, alpha=0.8, label=f"unstable ({unstable.sum()})")
    ax[0].set_xlabel("grip force |F| [N]")
    ax[0].set_ylabel("samples")
    ax[0].legend()
    right = a["targets"][:, 1, :3]
    for status in sorted(set(a["status"])):
        pick = a["status"] == status
        ax[1].scatter(right[pick, 0], right[pick, 2], s=3, label=f"{status} ({pick.sum()})")
    ax[1].set_xlabel("right grip x [m]")
    ax[1].set_ylabel("right grip z [m]")
    ax[1].legend(markerscale=4)
    shown = np.flatnonzero(stable)[:150]
    for i in shown:
        ax[2].plot(a["points"][i, :, 1], a["points"][i, :, 2], color="tab:blue", lw=0.4, alpha=0.5)
    met = np.flatnonzero(np.isfinite(a["unstable_energy_total"]))[:40]
    for i in met:
        ax[2].plot(a["unstable_points"][i, :, 1], a["unstable_points"][i, :, 2], color="tab:red", lw=0.8)
    post = plt.Circle((demo.POST["center"][1], demo.POST["center"][2]), demo.POST["radius"], color="grey")
    ax[2].add_patch(post)
    ax[2].set_aspect("equal")
    ax[2].set_xlabel("y [m]")
    ax[2].set_ylabel("z [m]")
    ax[2].set_title(f"{len(shown)} stable centrelines (blue), {len(met)} unstable ones met (red)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return True


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--samples", type=int, default=10_000)
    ap.add_argument("--out", default="shapes_main_job")
    ap.add_argument("--resume", action="store_true")
    args = ap.parse_args()
    plan = plan_from_dict({**read_plan(ROOT / "config" / "plans" / "main_job_on_post.yaml").as_dict(),
                           "samples": args.samples})
    with tempfile.TemporaryDirectory() as tmp:
        scene = load_scene(str(demo.write_demo_scene(Path(tmp))))
    t0 = time.perf_counter()
    summary = build_dataset(scene, plan, args.out, resume=args.resume)
    seconds = time.perf_counter() - t0
    print(summary.text())
    a = load_arrays(args.out)
    shutil.copy(Path(args.out) / "manifest.json", RESULTS / "dataset_example_manifest.json")
    counts = Counter(a["status"])
    ok = a["status"] == "ok"
    verdicts = Counter("stable" if s is True else "unstable" if s is False else "unknown" for s in a["stable"][ok])
    met = int(np.isfinite(a["unstable_energy_total"]).sum())
    drawn = chart(a, RESULTS / "dataset_example.png")
    info = machine()
    lines = [
        "# A data set of the main job's scene (#39's example)", "",
        f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores, Python {info.get('python')}; "
        f"git {info.get('git', '?')}; {time.strftime('%Y-%m-%d %H:%M')}.",
        f"Command: `bash scripts/dlo-env run python bench/perf/dataset_example.py --samples {args.samples}` "
        f"({seconds:.0f} s this run, {summary.written} samples solved, {summary.resumed} there already).", "",
        "Scene: `default_cable` plus the main job's post; plan: `config/plans/main_job_on_post.yaml`. "
        "Manifest: [dataset_example_manifest.json](dataset_example_manifest.json).", "",
        "| what | samples |", "|---|---|",
        *[f"| status {s} | {n} |" for s, n in sorted(counts.items())],
        *[f"| ok and {v} | {n} |" for v, n in sorted(verdicts.items())],
        f"| an unstable equilibrium met beside it | {met} |",
        "", ("![the data set](dataset_example.png)" if drawn else
             "(no chart: matplotlib is not installed; `pip install -r requirements-bench.txt`)"),
    ]
    (RESULTS / "dataset_example.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(json.dumps(dict(counts)))


if __name__ == "__main__":
    main()
