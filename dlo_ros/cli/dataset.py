"""``dlo dataset``: solve a plan of grip poses into a certified shape data set (Parquet).

    dlo dataset SCENE --plan PLAN.yaml --out DIR [--workers N] [--scheduler ADDRESS] [--resume]
                [--quiet]

Exit codes: 0 every sample stored (whatever each one's status: the rows say it), 1 some chunks
got no answers (a worker died twice; ``--resume`` redoes them), 2 a malformed scene or plan, or an
output folder that cannot be used, 130 interrupted by Ctrl-C or SIGTERM (the shards written stay;
``--resume``).
Documented in msg_docs/dataset.md.
"""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path

from .common import EXIT_NOT_OK, EXIT_OK, UsageError, load_scene_arg

EXIT_INTERRUPTED = 130

HELP = "solve a plan of grip poses into a certified shape data set (Parquet shards)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="scene file or shipped scene name")
    p.add_argument("--plan", required=True, help="the plan (YAML: samples, seed, grips, ...)")
    p.add_argument("--out", required=True, help="output folder (new, or with --resume)")
    p.add_argument(
        "--workers", type=int, default=None, help="local worker processes (default: CPU count)"
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="a Dask scheduler (tcp://HOST:PORT): run the chunks on its cluster",
    )
    p.add_argument(
        "--resume", action="store_true", help="continue the data set in --out (same scene, plan)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    # start-up (cli/__init__)
    from ..dataset import DatasetError, PlanError, build_dataset, read_plan

    if args.workers is not None and not 1 <= args.workers <= 1024:
        raise UsageError(f"--workers: must be in [1, 1024], got {args.workers}")
    scene = load_scene_arg(args.scene)
    try:
        plan = read_plan(args.plan)
    except PlanError as exc:
        raise UsageError(str(exc)) from None
    executor, client, window = None, None, None
    if args.scheduler:
        client = _dask_client(args.scheduler)
        executor = client.get_executor()
        window = 2 * max(1, sum(client.nthreads().values()))  # two chunks per worker thread
    # a batch scheduler's SIGTERM stops the run as Ctrl-C does: the shards written stay
    signal.signal(signal.SIGTERM, _as_interrupt)
    try:
        summary = build_dataset(
            scene,
            plan,
            args.out,
            workers=args.workers,
            executor=executor,
            executor_name=f"dask {args.scheduler}" if args.scheduler else "",
            in_flight=window,
            resume=args.resume,
            progress=not args.quiet,
        )
    except (DatasetError, PlanError) as exc:
        raise UsageError(str(exc)) from None
    except KeyboardInterrupt:
        _interrupted(args.out, plan.samples)
        return EXIT_INTERRUPTED
    finally:
        if client is not None:
            client.close()
    print(summary.text())
    return EXIT_OK if summary.complete else EXIT_NOT_OK


def _as_interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def _dask_client(address: str):
    """Connect to the Dask scheduler at ``address`` (UsageError naming it if that fails)."""
    try:
        from distributed import Client  # start-up: only with --scheduler (1 s of imports)
    except ImportError:
        raise UsageError("--scheduler: needs dask[distributed] (pip install 'dask[distributed]')")
    try:
        return Client(address, timeout=10)
    except (OSError, TimeoutError, ValueError) as exc:
        raise UsageError(f"--scheduler: cannot reach {address}: {exc}") from None


def _interrupted(out: str, samples: int) -> None:
    """Say on stderr what an interrupted run left (the manifest's counts)."""
    from ..dataset import read_manifest  # start-up (cli/__init__)

    try:
        stored = sum(read_manifest(Path(out)).get("counts", {}).values())
    except (OSError, ValueError):
        stored = 0
    print(
        f"dlo: interrupted: {stored} of {samples} samples stored in {out}; "
        "run the same command with --resume to continue",
        file=sys.stderr,
    )
