"""The recording flags of ``dlo solve`` and ``dlo demo`` (msg_docs/recording.md).

The recording flags of ``dlo solve`` and ``dlo demo`` (``--rrd``, ``--spawn``, ``--connect``;
msg_docs/recording.md).
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the type only: start-up (cli/__init__)
    from ..recording import Recorder

from .common import UsageError


def add_record_arguments(p: argparse.ArgumentParser) -> None:
    """Add the recording flags (--rrd, --spawn, --connect) to a subcommand's parser."""
    g = p.add_argument_group("rerun recording (any combination; default off)")
    g.add_argument(
        "--rrd",
        metavar="FILE",
        help="save a rerun recording to FILE (.rrd); `dlo replay FILE` opens it",
    )
    g.add_argument(
        "--spawn", action="store_true", help="start a rerun viewer and stream the recording to it"
    )
    g.add_argument(
        "--connect",
        nargs="?",
        const="",
        default=None,
        metavar="ADDR",
        help="stream to a running rerun viewer: HOST[:PORT] or rerun+http://HOST:PORT/proxy "
        "(no ADDR: 127.0.0.1:9876)",
    )


def make_recorder(args: argparse.Namespace):
    """Return the Recorder the recording flags ask for (a disabled one when none is given)."""
    from ..recording import Recorder, RecordingUnavailable  # start-up (cli/__init__)

    try:
        return Recorder(rrd=args.rrd, spawn=args.spawn, connect=args.connect)
    except (RecordingUnavailable, ValueError) as exc:
        raise UsageError(str(exc)) from None
    except (
        RuntimeError
    ) as exc:  # e.g. no display for --spawn, or the recorder process did not start
        raise UsageError(f"{'--spawn' if args.spawn else 'recording'}: {exc}") from None


def close_recorder(recorder: Recorder) -> None:
    """Close the recorder and say on stderr where the recording went and how many errors it had."""
    recorder.close()
    if recorder.enabled and recorder.errors:
        print(
            f"dlo: warning: recording: {recorder.errors} error(s), last: {recorder.last_error}",
            file=sys.stderr,
        )
    if recorder.enabled and recorder.rrd is not None:
        print(f"dlo: recording saved to {recorder.rrd}", file=sys.stderr)
