"""Console-script entry points (``dlo``, ``dlo_node``), kept free of heavy imports.

Console-script entry points (``dlo``, ``dlo_node``), kept free of heavy imports: ``dlo node``
installs its SIGINT/SIGTERM handling (dlo_ros.node.signals) before the CLI imports numpy, CasADi
and rclpy, so that a SIGTERM in the first second stops it with exit code 0 instead of Python's
default −15.  A crash in native code prints every thread's Python stack (``faulthandler``), and a
CasADi the solver refuses (``casadi_threads.py``) is one line naming the fix, not a traceback.
"""

from __future__ import annotations

import faulthandler
import sys

from .casadi_threads import CasadiUnsupported


def dlo() -> int:
    """``dlo ...``: dlo_ros.cli.main."""
    faulthandler.enable()
    node = sys.argv[1:2] == ["node"]
    if node:
        # start-up (module docstring): the signal handling before anything heavy is imported
        from .node.signals import stop_on_first_signal

        stop_on_first_signal()
    try:
        from .cli import main  # start-up: after the signal handling above

        return main()
    except CasadiUnsupported as exc:
        print(f"dlo: error: {exc}", file=sys.stderr)
        return 1
    except (
        KeyboardInterrupt
    ):  # Ctrl-C (for `dlo node` also SIGTERM) while importing or starting: a clean stop
        if not node:
            return 130
        from .node.signals import ignore_signals_at_exit  # start-up: see above

        ignore_signals_at_exit()
        return 0


def dlo_node() -> int:
    """``dlo_node ...``: dlo_ros.node.main."""
    from .node import main  # start-up: rclpy is imported only by the command that needs it

    return main()
