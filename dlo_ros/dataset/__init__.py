"""Certified shape data sets: many equilibria of one scene, each with the residual that proves it.

    from dlo_ros.dataset import build_dataset, read_plan, load
    summary = build_dataset(load_scene("default_cable"), read_plan("plan.yaml"), "out/")
    table = load("out/")            # a pyarrow Table, one row per sample (rows.SCHEMA)

``plan`` (the samples), ``positions`` (where a grip goes: box, grid, path), ``work`` (what a
worker solves), ``rows`` (one row per sample), ``store`` (Parquet shards, the manifest file, the
reader), ``manifest`` (its content) and ``build`` (the run: executors, progress, resume).
``dlo dataset`` is the command line (msg_docs/dataset.md).
"""

from .build import DatasetError, DatasetSummary, build_dataset
from .plan import DatasetPlan, PlanError, plan_from_dict, read_plan
from .positions import AroundPath, PositionBox, PositionGrid
from .store import load, load_arrays, read_manifest

__all__ = [
    "AroundPath",
    "DatasetError",
    "DatasetPlan",
    "DatasetSummary",
    "PlanError",
    "PositionBox",
    "PositionGrid",
    "build_dataset",
    "load",
    "load_arrays",
    "plan_from_dict",
    "read_manifest",
    "read_plan",
]
