"""Run a data set's plan: samples solved on any executor, written shard by shard, resumable.

:func:`build_dataset` cuts the plan's samples into its chunks (``plan.chunk`` samples each, the
same on every run), skips the chunks whose shard is already there when resuming, sends the others
to the executor (:mod:`.work`; a bounded number in flight) and writes each shard as its answers
come back (:mod:`.store`, atomic), with a progress bar (tqdm: rate and ETA).  The executor is a
local pool of worker processes by default (``WorkerPool``: a dead worker fails only its chunk,
which the run reports and ``--resume`` redoes), or any ``concurrent.futures.Executor`` whose
workers import dlo_ros: a Dask ``distributed`` client's ``get_executor()`` for a cluster
(``scheduler``).  The manifest is written first and updated at the end (:mod:`.manifest`).
"""

from __future__ import annotations

import time
import warnings
from collections import Counter
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from dataclasses import dataclass, field, replace
from pathlib import Path

import pyarrow.parquet as pq

from ..scene import Scene
from ..solver import make_solver
from ..solver.parallel.batch import scene_payload
from ..solver.parallel.worker_pool import MODULE_LEVEL_CALL, WorkerPool, starting_as_worker
from . import manifest as M
from . import store
from .plan import DatasetPlan, PlanError
from .rows import rows_table
from .work import solve_samples


class DatasetError(ValueError):
    """A data set that cannot be written where asked (the message says why)."""


@dataclass
class DatasetSummary:
    """What a run did.

    ``counts`` per status over the whole data set, ``written`` and ``resumed`` samples of this
    run, ``failed_chunks`` (chunk index → why its worker gave no rows), ``seconds`` of this run.
    """

    out: Path
    samples: int
    counts: dict[str, int]
    written: int
    resumed: int
    seconds: float
    failed_chunks: dict[int, str] = field(default_factory=dict)

    @property
    def complete(self) -> bool:
        """Whether every sample of the plan is stored."""
        return sum(self.counts.values()) == self.samples

    def text(self) -> str:
        """Return the one-paragraph summary ``dlo dataset`` prints."""
        counts = ", ".join(f"{n} {s}" for s, n in sorted(self.counts.items())) or "none"
        rate = self.written / self.seconds if self.seconds > 0 else 0.0
        lines = [
            f"{sum(self.counts.values())} of {self.samples} samples stored in {self.out} "
            f"({counts}); this run solved {self.written} in {self.seconds:.1f} s "
            f"({rate:.1f} samples/s)"
            + (f", {self.resumed} were there already" if self.resumed else "")
        ]
        for k, why in sorted(self.failed_chunks.items()):
            lines.append(f"chunk {k}: no answers ({why}); run again with --resume to redo it")
        return "\n".join(lines)


def build_dataset(
    scene: Scene,
    plan: DatasetPlan,
    out: Path | str,
    *,
    workers: int | None = None,
    executor: Executor | None = None,
    executor_name: str = "",
    resume: bool = False,
    progress: bool = True,
    compile: str = "on_query",
) -> DatasetSummary:
    """Solve every sample of ``plan`` on ``scene`` into the folder ``out`` (module docstring).

    ``workers``: the local pool's processes (default: the CPU count), unless ``executor`` is
    given (e.g. a Dask client's ``get_executor()``; ``executor_name`` says which in the
    manifest).  ``resume``: continue a data set in ``out`` made with the same scene and plan;
    without it ``out`` must be new or empty.  Raises DatasetError or PlanError with the reason.
    KeyboardInterrupt stops the run; the shards written so far stay.  Called from a script's top
    level, the local pool's workers run the call again while they start: there it returns at once
    (a warning says why) and never touches ``out``.
    """
    out = Path(out)
    if executor is None and starting_as_worker():  # the script's own call is the one that runs
        warnings.warn(f"build_dataset: {MODULE_LEVEL_CALL}", RuntimeWarning, stacklevel=2)
        return DatasetSummary(out, plan.samples, {}, 0, 0, 0.0)
    if plan.resolution:
        scene = replace(scene, options=replace(scene.options, output_points=plan.resolution))
    plan.targets(scene.problem, 0, 0)  # checks the plan's grips against the scene
    name = executor_name or ("local" if executor is None else type(executor).__name__)
    manifest = _open(out, scene, plan, name, resume)
    todo = [k for k in range(plan.chunks) if not store.shard_done(out, k, _size(plan, k))]
    resumed = plan.samples - sum(_size(plan, k) for k in todo)
    payload = scene_payload(make_solver, scene.problem, scene.options)
    own = executor is None
    pool: Executor = WorkerPool(workers) if executor is None else executor
    t0 = time.monotonic()
    written, failed = 0, {}
    bar = _bar(plan.samples, resumed, progress)
    try:
        in_flight: dict[Future, int] = {}
        queue = list(reversed(todo))
        window = 2 * (getattr(pool, "max_workers", None) or workers or 2)
        while queue or in_flight:
            while queue and len(in_flight) < window:
                k = queue.pop()
                a, b = plan.span(k)
                targets = plan.targets(scene.problem, a, b)
                job = pool.submit(solve_samples, payload, a, targets, plan.start, compile)
                in_flight[job] = k
            done, _ = wait(list(in_flight), return_when=FIRST_COMPLETED)
            for job in done:
                k = in_flight.pop(job)
                try:
                    rows = job.result()
                except Exception as exc:  # noqa: BLE001 - a dead worker: resume redoes it
                    failed[k] = f"{type(exc).__name__}: {exc}"
                    continue
                store.write_shard(out, k, rows_table(rows))
                written += len(rows)
                bar.update(len(rows))
    finally:
        bar.close()
        if own:
            pool.stop()  # type: ignore[attr-defined]  # our WorkerPool: its workers end now
        counts = _counts(out)
        store.write_manifest(out, M.finished(manifest, counts, len(store.shard_files(out)), name))
    return DatasetSummary(
        out, plan.samples, counts, written, resumed, time.monotonic() - t0, failed
    )


def _size(plan: DatasetPlan, k: int) -> int:
    a, b = plan.span(k)
    return b - a


def _open(out: Path, scene: Scene, plan: DatasetPlan, executor: str, resume: bool) -> dict:
    """Create (or reopen, resuming) the output folder; return the manifest to update."""
    fresh = M.new_manifest(scene, plan, executor)
    if out.exists() and not out.is_dir():
        raise DatasetError(f"{out}: exists and is not a folder")
    if resume and (out / store.MANIFEST).exists():
        old = store.read_manifest(out)
        why = M.same_job(old, fresh)
        if why:
            raise DatasetError(f"{out}: cannot resume: {why}")
        return {**old, "machine": fresh["machine"]}
    if out.exists() and any(out.iterdir()) and not resume:
        raise DatasetError(f"{out}: not empty; --resume continues the data set there")
    (out / store.SHARDS).mkdir(parents=True, exist_ok=True)
    store.write_manifest(out, fresh)
    return fresh


def _counts(out: Path) -> dict[str, int]:
    """Count the samples per status over every shard in ``out``."""
    counts: Counter[str] = Counter()
    for f in store.shard_files(out):
        counts.update(pq.read_table(f, columns=["status"]).column("status").to_pylist())
    return dict(counts)


def _bar(total: int, initial: int, enabled: bool):
    """Return a tqdm progress bar over the samples (rate and ETA), silent unless ``enabled``."""
    from tqdm import tqdm  # start-up: `import dlo_ros.dataset` stays light for readers

    return tqdm(
        total=total, initial=initial, unit="sample", disable=not enabled, dynamic_ncols=True
    )


__all__ = ["DatasetError", "DatasetSummary", "PlanError", "build_dataset"]
