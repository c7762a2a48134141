"""``dlo fit OBSERVATIONS``: identify string parameters from observations (the command is
dlo_ros.identify.command).
"""

from __future__ import annotations

import argparse

from ..identify import command
from .common import UsageError

HELP = command.HELP
add_arguments = command.add_arguments


def run(args: argparse.Namespace) -> int:
    """:func:`dlo_ros.identify.command.cmd_fit`; an ObservationError (a ValueError) is a usage
    error.
    """
    try:
        return command.cmd_fit(args)
    except (
        ValueError
    ) as exc:  # ObservationError (a ValueError; SceneError is caught by main first)
        from ..scene import SceneError

        if isinstance(exc, SceneError):
            raise
        raise UsageError(str(exc)) from None
