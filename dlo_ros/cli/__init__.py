"""``dlo``: command-line access to scenes and the shape solver (no ROS needed).

    dlo solve SCENE [--json] [--points N] [--basis B] [--order N] [--compile] [--rrd FILE]
    [--spawn] [--connect [ADDR]] dlo scenes dlo demo [--scene NAME] [--steps N] [--json]
    [--compile] [--rrd FILE] [--spawn] [--connect [ADDR]] dlo replay FILE.rrd [--resolve
    [--tolerance M] [--json]] [--web] [--screenshot PNG] dlo fit OBSERVATIONS [--scene SCENE]
    [--json] [--write-scene FILE] [--rrd FILE] dlo dataset SCENE --plan PLAN.yaml --out DIR
    [--workers N] [--scheduler ADDRESS] [--resume]

SCENE is a scene file path or the name of a shipped scene (config/scenes/<name>.yaml).
Exit codes: 0 success (solve: status ok), 1 the solve (or a demo step) did not reach status ok,
2 malformed scene or bad usage (the message names the offending key, on stderr, no traceback).
Documented in msg_docs/cli.md; also runs as ``python -m dlo_ros.cli``.

One module per subcommand (solve, scenes, demo, node, replay, fit, dataset), each with ``HELP``,
``add_arguments(parser)`` and ``run(args) -> exit code``; :data:`SUBCOMMANDS` below lists them, and
:func:`register_subcommand` adds more.  Shared: ``common`` (exit codes, UsageError) and ``record``
(the recording flags).

Start-up: the subcommand modules import the heavy layers (scene, solver, recording, the node and
rclpy, identify) inside the functions that use them, marked ``# start-up``, because every ``dlo``
command imports every subcommand module to build its parser.  Measured with
``python -X importtime -m dlo_ros.cli --help`` (5 runs, this 2-core machine): imports 0.50-1.06 s
(median 0.65 s) with them lazy, 0.69-1.53 s (median 1.26 s) before ``dlo fit``'s module stopped
importing ``dlo_ros.identify`` at the top.  What ``--help`` still pays is mostly
``recording.replay``'s ``DEFAULT_TOLERANCE`` (the recording reader reaches the scene package, which
imports the solver).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from typing import Callable

from .. import blas_threads  # noqa: F401  (importing it asks for one BLAS thread: before numpy)
from ..text import one_line_warnings, safe_text
from . import dataset, demo, fit, node, replay, scenes, solve
from .common import EXIT_NOT_OK, EXIT_OK, EXIT_USAGE, UsageError, print_error
from .demo import demo_path, format_demo, run_demo
from .scenes import scene_summaries
from .solve import JSON_KEYS, format_summary, max_sag

__all__ = [
    "EXIT_NOT_OK",
    "EXIT_OK",
    "EXIT_USAGE",
    "JSON_KEYS",
    "SUBCOMMANDS",
    "UsageError",
    "build_parser",
    "demo_path",
    "format_demo",
    "format_summary",
    "main",
    "max_sag",
    "register_subcommand",
    "run_demo",
    "scene_summaries",
]

# =================================================================================================
# SUBCOMMAND REGISTRY — add new subcommands here (or call register_subcommand() from your module).
#   name -> (help, add_arguments(parser) -> None, handler(args) -> exit code)
# The handler may raise SceneError / FileNotFoundError / UsageError: main() prints them as "dlo:
# error: ..." and returns exit code 2.  "node": main() hands its arguments to the node unparsed
# (dlo_ros/node/params/ checks them).
# =================================================================================================
Subcommand = tuple[
    str, Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]
]

SUBCOMMANDS: dict[str, Subcommand] = {
    name: (module.HELP, module.add_arguments, module.run)
    for name, module in (
        ("solve", solve),
        ("scenes", scenes),
        ("demo", demo),
        ("node", node),
        ("replay", replay),
        ("fit", fit),
        ("dataset", dataset),
    )
}


def register_subcommand(
    name: str,
    help: str,
    add_arguments: Callable[[argparse.ArgumentParser], None],
    handler: Callable[[argparse.Namespace], int],
) -> None:
    """Add (or replace) a subcommand of ``dlo``."""
    SUBCOMMANDS[name] = (help, add_arguments, handler)


def build_parser() -> argparse.ArgumentParser:
    """Return the ``dlo`` parser: one subparser per entry of :data:`SUBCOMMANDS`."""
    parser = argparse.ArgumentParser(
        prog="dlo",
        description=(
            "Static shape of a cable/rope/paper strip held by grippers (Hirai & Wakamatsu)."
        ),
        epilog="Exit codes: 0 ok, 1 solve status not ok, 2 malformed scene or usage.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, (help_text, add_arguments, handler) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        add_arguments(p)
        p.set_defaults(_handler=handler)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``dlo`` with ``argv`` (default: sys.argv[1:]) and return its exit code.

    Bad input (SceneError, FileNotFoundError, UsageError, an unreadable file) is one line
    ``dlo: error: ...`` on stderr and exit code 2, never a traceback.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    one_line_warnings()
    entry = SUBCOMMANDS.get("node")
    if argv[:1] == ["node"] and entry is not None and entry[2] is node.run:
        # everything after `node` is the node's (and rclpy's): argparse would refuse `--scene` here
        return node.run_node(argv[1:])
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or a usage error (2)
        return int(exc.code or 0) if isinstance(exc.code, int) else EXIT_USAGE
    # start-up: after parsing, so that --help and usage errors do not pay for the scene reader
    # (0.58 s of imports: python -X importtime -m dlo_ros.cli --help)
    from ..scene import SceneError

    try:
        return int(args._handler(args))
    except (SceneError, FileNotFoundError, UsageError) as exc:
        # FileNotFoundError/KeyError-style messages may come quoted; SceneError's never start with
        # a quote
        text = (
            exc.args[0] if isinstance(exc, FileNotFoundError) and len(exc.args) == 1 else str(exc)
        )
        print_error(str(text))
        return EXIT_USAGE
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # e.g. `dlo scenes | head -1`
        with contextlib.suppress(OSError):
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - silence the flush at exit
        return EXIT_OK
    except (
        OSError
    ) as exc:  # a file the command was given cannot be read or written: its name and why
        name = f"{safe_text(exc.filename)}: " if exc.filename is not None else ""
        print_error(f"{name}{exc.strerror or type(exc).__name__}")
        return EXIT_USAGE
