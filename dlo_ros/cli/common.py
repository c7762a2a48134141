"""What every ``dlo`` subcommand shares: exit codes, errors, scene loading, compile mode.

What every ``dlo`` subcommand shares: exit codes, the usage error, scene loading, the compile
mode.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the type only: start-up (cli/__init__)
    from ..scene import Scene

EXIT_OK = 0
EXIT_NOT_OK = 1
EXIT_USAGE = 2


class UsageError(Exception):
    """Bad command-line input: printed as ``dlo: error: ...`` and exit code 2."""


def print_error(message: str) -> None:
    """Print ``dlo: error: <message>`` on stderr: the one line a refused input gets."""
    print(f"dlo: error: {message}", file=sys.stderr)


def compile_mode(enabled: bool) -> str:
    """Return ShapeSolver's compile mode for a one-shot command.

    ShapeSolver's compile mode for a one-shot command: 'blocking' with --compile (compile the
    KKT function to C now, about a minute per new scene structure, cached), else 'cached' (use a
    library an earlier run compiled, never wait for gcc).
    """
    return "blocking" if enabled else "cached"


def load_scene_arg(scene_arg: str) -> Scene:
    """Load the scene a command names: a file path or a shipped scene's name (``load_scene``)."""
    from ..scene import load_scene  # start-up (cli/__init__)

    return load_scene(scene_arg)
