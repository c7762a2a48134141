"""``dlo fit OBSERVATIONS``: identify string parameters from observed shapes.

Usage: ``dlo fit OBSERVATIONS [--scene SCENE] [--json] [--write-scene FILE] [--rrd FILE]``
(msg_docs/cli.md, fitting.md).  The fitting itself is ``dlo_ros.identify``.

Exit codes as every ``dlo`` subcommand: 0 the fit converged and explains the points, 1 it ran but
did not converge, an equilibrium failed, or the fitted shapes do not explain the points (status
``misfit``: one line ``dlo fit: misfit: ...`` on stderr says why, and ``--write-scene`` writes
nothing), 2 malformed observation file or scene, or bad usage (one line on stderr naming the key
path, no traceback).

Start-up: ``dlo_ros.identify`` and ``dlo_ros.scene`` are imported inside :func:`cmd_fit`, not
here, because every ``dlo`` command imports this module to build its parser: importing
``dlo_ros.identify`` costs about 1.0 s (``python -X importtime -m dlo_ros.cli --help``: 1.01 of
its 1.18 s of imports), which ``dlo --help``, ``dlo scenes`` and ``dlo replay`` need not pay.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import yaml

from ..jsonio import json_safe, stdout_to_stderr
from ..text import safe_text
from .common import EXIT_NOT_OK, EXIT_OK, UsageError

if TYPE_CHECKING:  # types only: importing them costs the start-up the module docstring measures
    from ..identify.fit import FitResult
    from ..identify.observations import ObservationSet

HELP = (
    "identify Rf, Rt, D, Re from observed shapes (exit 0 if the fit converged and explains "
    "the points)"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add ``dlo fit``'s arguments to its parser."""
    p.add_argument(
        "observations",
        metavar="OBSERVATIONS",
        help="observation file (YAML or JSON, msg_docs/fitting.md)",
    )
    p.add_argument(
        "--scene",
        default=None,
        metavar="SCENE",
        help="scene name or file (default: the file's `scene`, relative to the file)",
    )
    p.add_argument(
        "--json", action="store_true", help="print exactly one JSON object (FitResult.to_dict())"
    )
    p.add_argument(
        "--write-scene",
        default=None,
        metavar="FILE",
        help="write the scene with the fitted values",
    )
    p.add_argument(
        "--rrd",
        default=None,
        metavar="FILE",
        help="save a rerun drawing: observed points, fitted centrelines, residuals (.rrd)",
    )


def _scene_argument(args: argparse.Namespace, data: ObservationSet) -> str:
    """Return the scene to fit: --scene, else the observation file's ``scene``.

    The file's ``scene`` is a path relative to the observation file, or a shipped scene's name.
    """
    from ..identify.observations import ObservationError  # start-up: see the module docstring

    if args.scene:
        return args.scene
    if not data.scene:
        raise ObservationError(
            f"{args.observations}: scene: no scene given (use --scene or a `scene:` key in "
            "the observation file)"
        )
    relative = Path(args.observations).parent / data.scene
    return str(relative) if relative.is_file() else data.scene


def format_fit(result: FitResult) -> str:
    """Return the human-readable summary of a FitResult, one line per fact."""
    lines = [
        f"status: {result.status} ({result.message})",
        f"equilibrium solves: {result.equilibrium_solves}, iterations: {result.iterations}, "
        f"time: {result.time_s:.2f} s, reduced chi2: {result.chi2_reduced:.3g}",
    ]
    for name, est in {**result.parameters, **result.ratios}.items():
        lines.append(f"{name:6s} = {est.value:.6g} ± {est.std:.2g} {est.unit}")
    for name, value in result.fixed.items():
        lines.append(f"{name:6s} = {value:.6g} (fixed: the scene's value)")
    for name, why in result.not_identifiable.items():
        lines.append(f"{name:6s}: not identifiable (kept at the scene's value): {why}")
    for o in result.observations:
        force = (
            "" if o.force_residual_n is None else f", force residual {o.force_residual_n:.3g} N"
        )
        if o.torque_residual_nm is not None:
            force += f", torque residual {o.torque_residual_nm:.3g} N·m"
        lines.append(
            f"observation {o.name}: {o.points} points, rms {o.rms_m * 1e3:.3g} mm, median "
            f"{o.median_m * 1e3:.3g} mm, max {o.max_m * 1e3:.3g} mm, {o.downweighted} "
            f"down-weighted{force}"
        )
    return "\n".join(lines)


def cmd_fit(args: argparse.Namespace) -> int:
    """Fit the observations to the scene, print the result, write what the flags ask for.

    Returns EXIT_OK when the fit converged and explains the points, else EXIT_NOT_OK; raises
    ObservationError, SceneError or FileNotFoundError on bad input (:func:`run` and ``cli.main``
    turn them into exit code 2).
    """
    # start-up: see the module docstring
    from ..identify.fit import fit
    from ..identify.observations import ObservationError, load_observations
    from ..scene import load_scene, scene_to_dict

    data = load_observations(args.observations)  # its errors name the file
    scene = load_scene(_scene_argument(args, data))
    guard = stdout_to_stderr() if args.json else contextlib.nullcontext()
    with guard:
        try:
            result = fit(scene.problem, scene.options, data)
        except ObservationError as exc:
            raise ObservationError(f"{args.observations}: {exc}") from None
    if args.write_scene and result.status == "misfit":
        print("dlo fit: --write-scene: not written: the fit is a misfit", file=sys.stderr)
    elif args.write_scene and result.string is not None:
        fitted = replace(
            scene,
            problem=replace(scene.problem, string=result.string),
            description=(scene.description + "\n" if scene.description else "")
            + f"String fitted by `dlo fit {Path(args.observations).name}` ({result.status}).",
        )
        Path(args.write_scene).write_text(
            yaml.safe_dump(scene_to_dict(fitted), sort_keys=False), encoding="utf-8"
        )
    summary = format_fit(result)
    if args.rrd:
        from ..identify.drawing import save_fit  # optional: rerun, only with --rrd

        try:
            save_fit(args.rrd, result, data, summary)
        except RuntimeError as exc:
            raise ObservationError(f"--rrd: {exc}") from None
    if args.json:
        print(json.dumps(json_safe(result.to_dict()), allow_nan=False))
    else:
        print(summary)
    if result.status == "misfit":
        print(f"dlo fit: {safe_text(result.message, 1000)}", file=sys.stderr)
    return EXIT_OK if result.ok else EXIT_NOT_OK


def run(args: argparse.Namespace) -> int:
    """Run :func:`cmd_fit`; an ObservationError (a ValueError) is a usage error (exit code 2)."""
    from ..scene import SceneError  # start-up: see the module docstring

    try:
        return cmd_fit(args)
    except SceneError:  # cli.main reports it
        raise
    except ValueError as exc:  # ObservationError
        raise UsageError(str(exc)) from None
