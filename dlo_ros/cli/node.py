"""``dlo node ARGS``: the ROS 2 node, its arguments passed on unparsed.

``dlo node ARGS``: the ROS 2 node (its arguments reach it unparsed; dlo_ros/node/params/
checks them).
"""

from __future__ import annotations

import argparse

from .common import EXIT_OK, EXIT_USAGE

HELP = (
    "run the ROS 2 node: dlo node [--params-file FILE] [--scene NAME_OR_PATH] [--managed] "
    "[--check] [--ros-args ...] "
    "(`dlo node --help`)"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("node_args", nargs=argparse.REMAINDER)


def run(args: argparse.Namespace) -> int:
    """Run the built-in ``node`` subcommand.

    The built-in ``node`` subcommand (``main`` passes its arguments to :func:`run_node`
    unparsed).
    """
    return run_node(args.node_args)


def run_node(argv: list[str]) -> int:
    """Run the node with its own command line (``dlo node ARGS``).

    ``dlo node ARGS``: the node's own command line (``--params-file``, ``--scene``, ``--check``,
    ``--ros-args ...``), parsed and checked by dlo_ros.node.params.prepare_node_args; ``main``
    hands everything after ``node`` here untouched (argparse cannot pass ``--scene`` through a
    subparser).
    """
    from ..node.signals import stop_on_first_signal  # start-up (cli/__init__): rclpy

    # before the node's imports (CasADi, rclpy): SIGTERM then stops it with 0, not −15
    stop_on_first_signal()
    from ..node.params import node_argument_parser  # start-up (cli/__init__)

    if any(
        a in ("-h", "--help")
        for a in argv[: argv.index("--ros-args") if "--ros-args" in argv else None]
    ):
        node_argument_parser("dlo node").print_help()  # without importing rclpy
        return EXIT_OK
    from ..node import main as node_main  # start-up (cli/__init__): rclpy

    try:
        result = node_main(argv, prog="dlo node")
    except SystemExit as exc:  # argparse: an unknown option of the node's own (usage printed)
        return int(exc.code) if isinstance(exc.code, int) else EXIT_USAGE
    return int(result or 0)
