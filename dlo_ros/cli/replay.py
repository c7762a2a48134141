"""``dlo replay FILE.rrd``: view, render or re-solve a recording.

``dlo replay FILE.rrd``: open a recording in the rerun viewer, render it, or re-solve it as a
regression case.

    dlo replay FILE.rrd                       open it in the native viewer (needs a display;
                                              else says what to do)
    dlo replay FILE.rrd --web                 serve it to a browser (rerun --web-viewer)
    dlo replay FILE.rrd --screenshot PNG      render it headlessly to a PNG (a Vulkan driver)
    dlo replay FILE.rrd --resolve [--tolerance M] [--json]
                                              re-run today's solver on the recorded targets;
                                              compare statuses, and ok shapes by distance

Exit codes: 0 ok (``--resolve``: every update agrees: the same status as recorded, and ``ok``
shapes within the tolerance); 1 with ``--resolve`` a shape deviation above the tolerance or a
status change (also ``unverified -> ok``; a differing model history alone does not count), or the
viewer / the renderer failed; 2 unreadable file or bad usage. Reading and re-solving:
dlo_ros.recording.replay (the report: dlo_ros.recording.resolve_report); viewing:
dlo_ros.recording.viewer.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

from ..jsonio import json_safe, stdout_to_stderr
from .common import EXIT_NOT_OK, EXIT_OK, UsageError

HELP = (
    "open a rerun recording (.rrd) in the viewer, or re-solve it and compare the shapes "
    "(--resolve)"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ..recording.replay import DEFAULT_TOLERANCE  # start-up (cli/__init__)

    p.add_argument(
        "file",
        metavar="FILE.rrd",
        help="a recording made with --rrd (dlo solve / dlo demo / the node)",
    )
    p.add_argument(
        "--resolve",
        action="store_true",
        help="re-run the solver on the recorded targets and compare: statuses, and ok shapes "
        "by distance (exit 1 on a status change or an ok shape beyond --tolerance)",
    )
    p.add_argument(
        "--tolerance",
        type=float,
        default=DEFAULT_TOLERANCE,
        metavar="M",
        help=(
            f"with --resolve: largest allowed centreline deviation [m] (default "
            f"{DEFAULT_TOLERANCE:g})"
        ),
    )
    p.add_argument(
        "--json", action="store_true", help="with --resolve: print the report as one JSON object"
    )
    p.add_argument(
        "--compile",
        action="store_true",
        help="with --resolve: compile the solver's derivatives to C first (slow first build)",
    )
    p.add_argument(
        "--web", action="store_true", help="serve the recording to a browser (rerun --web-viewer)"
    )
    p.add_argument(
        "--screenshot", metavar="PNG", help="render the recording headlessly into PNG and exit"
    )
    p.add_argument(
        "--update",
        type=int,
        metavar="N",
        help="with --screenshot: show update N (default: the last)",
    )


def _read(path: Path, details: bool):
    """Read the recording, or raise UsageError with its one-line reason; note an early end."""
    from ..recording import replay  # start-up (cli/__init__)

    try:
        rec = replay.read_recording(path, details=details)
    except ValueError as exc:  # RecordingError and the like: one line naming the file
        raise UsageError(str(exc)) from None
    if rec.truncated:
        _note_truncated(path, len(rec.results), rec.file_bytes, rec.complete_bytes)
    return rec


def _note_truncated(path: Path, updates: int, file_bytes: int, complete_bytes: int) -> None:
    print(
        f"dlo replay: note: {path} ends early (a cut-off recording, {file_bytes} bytes): read "
        f"{updates} updates from its first {complete_bytes} bytes, up to the last complete "
        "message",
        file=sys.stderr,
    )


def run(args: argparse.Namespace) -> int:
    from ..recording import replay, viewer  # start-up (cli/__init__)

    path = Path(args.file)
    if args.resolve:
        if not (args.tolerance >= 0 and math.isfinite(args.tolerance)):
            raise UsageError(f"--tolerance: must be a finite number >= 0, got {args.tolerance}")
        rec = _read(path, details=False)
        try:
            with stdout_to_stderr():  # IPOPT's banner must not mix with the report
                report = replay.resolve_report(
                    rec, args.tolerance, compile="blocking" if args.compile else "cached"
                )
        except UsageError:
            raise
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        text = (
            json.dumps(json_safe(report.as_dict())) if args.json else replay.format_resolve(report)
        )
        print(text)
        return EXIT_OK if report.ok else EXIT_NOT_OK
    try:  # a clear error for a file that is not a recording, before starting a viewer
        check = replay.check_recording(path)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if check.truncated:
        _note_truncated(path, check.updates, check.file_bytes, check.complete_bytes)
    if args.screenshot:
        try:
            out = viewer.screenshot(path, args.screenshot, update=args.update)
        # any exception: the viewer's reasons are varied (no GPU, port, ...)
        except Exception as exc:
            print(
                f"dlo replay: could not render {path} headlessly: {type(exc).__name__}: {exc}\n"
                "  the headless viewer needs a Vulkan adapter; a software one is Debian's "
                "mesa-vulkan-drivers "
                "(lavapipe)",
                file=sys.stderr,
            )
            return EXIT_NOT_OK
        print(f"dlo replay: screenshot saved to {out}")
        return EXIT_OK
    if args.web:
        return _run_viewer([*viewer.rerun_command(), "--web-viewer", str(path)])
    if not viewer.has_display():
        print(viewer.no_display_message(path))
        return EXIT_OK
    return _run_viewer([*viewer.rerun_command(), str(path)])


def _run_viewer(cmd: list[str]) -> int:
    try:
        code = subprocess.call(cmd)
    except OSError as exc:
        print(
            f"dlo replay: could not start the rerun viewer ({' '.join(cmd)}): {exc}",
            file=sys.stderr,
        )
        return EXIT_NOT_OK
    if code not in (0, -2, 130):  # Ctrl-C in the viewer is a normal way out
        print(
            f"dlo replay: the rerun viewer exited with code {code} ({' '.join(cmd)})",
            file=sys.stderr,
        )
        return EXIT_NOT_OK
    return EXIT_OK
