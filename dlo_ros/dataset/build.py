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

import contextlib
import itertools
import os
import time
import warnings
from collections import Counter
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

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
    in_flight: int | None = None,
    resume: bool = False,
    progress: bool = True,
    compile: str = "on_query",
) -> DatasetSummary:
    """Solve every sample of ``plan`` on ``scene`` into the folder ``out`` (module docstring).

    ``workers``: the local pool's processes (default: the CPU count), unless ``executor`` is
    given (e.g. a Dask client's ``get_executor()``; ``executor_name`` says which in the
    manifest).  ``in_flight``: chunks handed out at once (default: twice the workers; give a
    cluster's twice its worker threads).  ``resume``: continue a data set in ``out`` made with the
    same scene and plan; without it ``out`` must be new or empty.  Raises DatasetError or
    PlanError with the reason.  KeyboardInterrupt stops the run; the shards written so far stay.
    Called from a script's top level, the local pool's workers run the call again while they
    start: there it returns at once (a warning says why) and never touches ``out``.
    """
    out = Path(out)
    if executor is None and starting_as_worker():  # the script's own call is the one that runs
        warnings.warn(f"build_dataset: {MODULE_LEVEL_CALL}", RuntimeWarning, stacklevel=2)
        return DatasetSummary(out, plan.samples, {}, 0, 0, 0.0)
    if plan.resolution:
        scene = replace(scene, options=replace(scene.options, output_points=plan.resolution))
    plan.check(scene.problem, scene.options.output_points)
    name = executor_name or ("local" if executor is None else type(executor).__name__)
    manifest = _open(out, scene, plan, name, resume)
    counts, todo = _stored(out, plan)
    resumed = sum(counts.values())
    payload = scene_payload(make_solver, scene.problem, scene.options)
    own, pool = executor is None, executor or WorkerPool(workers)
    window = in_flight or 2 * (
        getattr(pool, "max_workers", None) or workers or os.cpu_count() or 1
    )
    t0 = time.monotonic()
    written, failed, shards = 0, {}, plan.chunks - len(todo)
    bar = _bar(plan.samples, resumed, progress)
    saved = time.monotonic()
    try:
        jobs: dict[Future, int] = {}
        queue = iter(todo)
        while True:
            for k in itertools.islice(queue, max(0, window - len(jobs))):
                a, b = plan.span(k)
                targets, values = plan.targets(scene.problem, a, b), plan.values(a, b)
                job = _submit(pool, own, payload, a, targets, plan.start, compile, values)
                jobs[job] = k
            if not jobs:
                break
            done, _ = wait(list(jobs), return_when=FIRST_COMPLETED)
            for job in done:
                k = jobs.pop(job)
                try:
                    rows = job.result()
                except Exception as exc:  # noqa: BLE001 - a dead worker: resume redoes it
                    failed[k] = f"{type(exc).__name__}: {exc}"
                    continue
                _write(out, k, rows, shards)
                counts.update(r["status"] for r in rows)
                written, shards = written + len(rows), shards + 1
                bar.update(len(rows))
            if time.monotonic() - saved > MANIFEST_EVERY_S:  # what a killed run leaves
                store.write_manifest(out, M.finished(manifest, counts, shards, name))
                saved = time.monotonic()
    finally:
        bar.close()
        if own:
            pool.stop()  # type: ignore[attr-defined]  # our WorkerPool: its workers end now
        with contextlib.suppress(OSError):  # never hide why the run stopped: shards are the truth
            store.write_manifest(out, M.finished(manifest, counts, shards, name))
    return DatasetSummary(
        out, plan.samples, dict(counts), written, resumed, time.monotonic() - t0, failed
    )


def _write(out: Path, k: int, rows: list[dict[str, Any]], shards: int) -> None:
    """Store chunk ``k``'s rows; a full or read-only disk stops the run (the rest stays)."""
    try:
        store.write_shard(out, k, rows_table(rows))
    except OSError as exc:
        why = exc.strerror or type(exc).__name__
        raise DatasetError(
            f"{out}: cannot write chunk {k}'s shard ({why}); the {shards} shards written stay "
            "readable, --resume continues once there is room"
        ) from None


def _submit(pool: Executor, own: bool, *args: Any) -> Future:
    """Hand one chunk to ``pool``; our WorkerPool retries it once if its worker dies.

    A chunk is a pure function of its arguments, so a retry gives the same rows.
    """
    if own:
        return pool.submit(solve_samples, *args, retries=1)  # type: ignore[call-arg]
    return pool.submit(solve_samples, *args)


#: the manifest's counts are rewritten at least this often during a run [s]
MANIFEST_EVERY_S = 10.0


def _stored(out: Path, plan: DatasetPlan) -> tuple[Counter, list[int]]:
    """Return the statuses of the chunks already stored in ``out`` and the chunks still to do.

    A shard counts when it holds exactly its chunk's samples (``store.shard_statuses``); a damaged
    or foreign one is done again.
    """
    present = store.shard_names(out)
    counts: Counter[str] = Counter()
    todo = []
    for k in range(plan.chunks):
        a, b = plan.span(k)
        statuses = store.shard_statuses(out, k, a, b) if store.shard_name(k) in present else None
        if statuses is None:
            todo.append(k)
        else:
            counts.update(statuses)
    return counts, todo


def _open(out: Path, scene: Scene, plan: DatasetPlan, executor: str, resume: bool) -> dict:
    """Create (or reopen, resuming) the output folder; return the manifest to update."""
    fresh = M.new_manifest(scene, plan, executor)
    if out.exists() and not out.is_dir():
        raise DatasetError(f"{out}: exists and is not a folder")
    has_manifest = (out / store.MANIFEST).exists()
    occupied = out.exists() and any(out.iterdir())
    if resume and has_manifest:
        try:
            old = store.read_manifest(out)
        except (OSError, ValueError) as exc:
            raise DatasetError(f"{out}: cannot resume: its manifest.json is unreadable ({exc})")
        why = M.same_job(old, fresh)
        if why:
            raise DatasetError(f"{out}: cannot resume: {why}")
        manifest = {**old, "machine": fresh["machine"], "complete": False}
    elif occupied:
        hint = (
            "it holds no data-set manifest" if resume else "--resume continues the data set there"
        )
        raise DatasetError(f"{out}: not empty; {hint}")
    else:
        manifest = fresh
    try:
        (out / store.SHARDS).mkdir(parents=True, exist_ok=True)
        store.write_manifest(out, manifest)
    except OSError as exc:
        raise DatasetError(f"{out}: cannot write there ({exc.strerror or exc})") from None
    return manifest


def _bar(total: int, initial: int, enabled: bool):
    """Return a tqdm progress bar over the samples (rate and ETA), silent unless ``enabled``."""
    from tqdm import tqdm  # start-up: `import dlo_ros.dataset` stays light for readers

    return tqdm(
        total=total, initial=initial, unit="sample", disable=not enabled, dynamic_ncols=True
    )


__all__ = ["DatasetError", "DatasetSummary", "PlanError", "build_dataset"]
