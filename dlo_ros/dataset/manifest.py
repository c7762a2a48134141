"""The manifest of a data set: the scene, the plan, the code and the machine that made it.

``manifest.json`` at the top of the output folder (``store.py``) holds:

* ``format`` ("dlo_ros dataset 1"), ``created`` and ``updated`` (UTC, ISO 8601);
* ``scene``: the scene as ``dlo_ros.scene.scene_to_dict`` writes it, with the solver options the
  samples were solved with (``solver``); ``plan``: the plan (``plan.DatasetPlan.as_dict``);
* ``plan_grips``, ``scene_grips``, ``scene_obstacles``: the orders of the list columns
  (``rows.py``); ``columns``: the column names;
* ``package``: dlo_ros's version and git revision (null outside a git checkout);
* ``machine``: platform, Python, CPU count, and the executor the last run used;
* ``chunks`` (shards in all), ``shards_written``, ``counts`` (samples per status), ``complete``.

A run that resumes (``--resume``) must find the same scene and plan there, else it refuses.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
from importlib import metadata
from pathlib import Path
from typing import Any

from ..jsonio import json_safe
from ..scene import Scene
from ..scene.writing import scene_to_dict
from .plan import DatasetPlan
from .rows import SCHEMA

FORMAT = "dlo_ros dataset 1"


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def _git_revision() -> str | None:
    """Return the git revision of the dlo_ros checkout this code runs from, if it is one."""
    root = Path(__file__).resolve().parents[2]
    if not (root / ".git").exists():
        return None
    try:
        out = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None if out.returncode == 0 else None


def _version() -> str | None:
    try:
        return metadata.version("dlo_ros")
    except metadata.PackageNotFoundError:
        return None


def new_manifest(scene: Scene, plan: DatasetPlan, executor: str) -> dict[str, Any]:
    """Return the manifest of a new data set of ``scene`` (with its options) and ``plan``."""
    problem = scene.problem
    return {
        "format": FORMAT,
        "created": _now(),
        "updated": _now(),
        "scene": json_safe(scene_to_dict(scene)),
        "plan": plan.as_dict(),
        "plan_grips": list(plan.grips),
        "scene_grips": [g.name for g in problem.grips],
        "scene_obstacles": [o.name for o in problem.obstacles],
        "columns": list(SCHEMA.names),
        "package": {"name": "dlo_ros", "version": _version(), "git": _git_revision()},
        "machine": {
            "platform": platform.platform(),
            "python": platform.python_version(),
            "cpus": os.cpu_count(),
            "executor": executor,
        },
        "chunks": plan.chunks,
        "shards_written": 0,
        "counts": {},
        "complete": False,
    }


def same_job(old: dict[str, Any], new: dict[str, Any]) -> str:
    """Return why the data set ``old`` cannot be resumed as ``new`` ('' when it can)."""
    if old.get("format") != FORMAT:
        return f"it is not a data set of this format ({old.get('format')!r})"
    for key in ("scene", "plan"):
        if json.dumps(old.get(key), sort_keys=True) != json.dumps(new[key], sort_keys=True):
            return f"it was made with another {key}"
    return ""


def finished(
    manifest: dict[str, Any], counts: dict[str, int], shards: int, executor: str
) -> dict[str, Any]:
    """Return ``manifest`` updated with the run's end: counts per status, shards, completeness."""
    out = dict(manifest)
    out["updated"] = _now()
    out["counts"] = dict(sorted(counts.items()))
    out["shards_written"] = shards
    out["complete"] = shards == manifest["chunks"]
    out["machine"] = {**manifest["machine"], "executor": executor}
    out["package"] = {**manifest["package"], "git": _git_revision(), "version": _version()}
    return out
