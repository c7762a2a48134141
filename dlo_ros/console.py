"""Console-script entry points (``dlo``, ``dlo_node``), kept free of heavy imports: ``dlo node`` installs
its SIGINT/SIGTERM handling (dlo_ros.node.signals) before the CLI imports numpy, CasADi and rclpy, so
that a SIGTERM in the first second stops it with exit code 0 instead of Python's default −15."""
from __future__ import annotations

import sys


def dlo() -> int:
    """``dlo ...``: dlo_ros.cli.main."""
    if sys.argv[1:2] == ["node"]:
        from .node.signals import stop_on_first_signal

        stop_on_first_signal()
    try:
        from .cli import main
    except KeyboardInterrupt:  # Ctrl-C while importing (only `dlo node` turns SIGTERM into this)
        return 130 if sys.argv[1:2] != ["node"] else 0
    return main()


def dlo_node() -> int:
    """``dlo_node ...``: dlo_ros.node.main."""
    from .node import main

    return main()
