"""``dlo solve SCENE``: solve a scene once and print the shape (a summary, or one JSON object)."""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import time
from dataclasses import replace
from typing import Any

import numpy as np

from ..jsonio import json_safe, stdout_to_stderr
from ..solver.options import BASES
from ..solver.results.contacts import pressed_obstacles
from ..solver.results.envelope import Envelope, EnvelopeUnavailable, envelope
from ..solver.results.uncertainty import Uncertainty, UncertaintyError
from .common import EXIT_NOT_OK, EXIT_OK, UsageError, compile_mode, load_scene_arg
from .record import add_record_arguments, close_recorder, make_recorder

HELP = "solve a scene once and print the shape (exit 0 if status ok)"

#: Keys of ``dlo solve --json`` output (ShapeResult.to_dict() plus scene and frame_id).
JSON_KEYS = (
    "scene",
    "frame_id",
    "status",
    "message",
    "stable",
    "min_eigenvalue",
    "s",
    "points",
    "orientations",
    "energy",
    "energy_note",
    "grips",
    "contact_forces",
    "passes_through_itself",
    "solver",
)


def _with_overrides(
    options, points: int | None, basis: str | None, order: int | None, model: str | None = None
):
    """Return SolverOptions with the command-line overrides; raises UsageError naming the option.

    An explicit --order pins the order, so it implies --model full unless --model is given
    (model 'auto' chooses the order itself).
    """
    changes: dict[str, Any] = {}
    if model is not None:
        changes["model"] = model
    elif order is not None and options.model == "auto":
        changes["model"] = "full"
    if points is not None:
        changes["output_points"] = points
    if basis is not None:
        changes["basis"] = basis
    if order is not None:
        changes["order"] = order
        # keep the default ratio of quadrature nodes to basis functions (40 for 12)
        needed = max(8, order + 2, math.ceil(10 * order / 3))
        if options.quadrature_nodes < needed:
            changes["quadrature_nodes"] = min(400, needed)
    new = replace(options, **changes)
    try:
        new.validate()
    except ValueError as exc:
        flag = {
            "solver.output_points": "--points",
            "solver.basis": "--basis",
            "solver.order": "--order",
            "solver.model": "--model",
        }
        key = str(exc).split(":", 1)[0]
        raise UsageError(f"{flag.get(key, key)}: {str(exc).split(':', 1)[-1].strip()}") from None
    return new


def max_sag(points: np.ndarray, grip_positions: list[np.ndarray], gravity: np.ndarray) -> float:
    """How far the lowest point of the string hangs below the lowest grip, along gravity [m].

    Negative when the whole string is above its lowest grip (e.g. buckled upward).
    """
    g = np.asarray(gravity, dtype=float)
    g = g / np.linalg.norm(g)
    if len(points) == 0 or not grip_positions:
        return float("nan")
    depth = np.asarray(points) @ g
    return float(depth.max() - max(float(np.dot(p, g)) for p in grip_positions))


def _vec(a: Any, digits: int = 4) -> str:
    return (
        "["
        + ", ".join(f"{float(v) + 0.0:+.{digits}g}" for v in np.asarray(a, dtype=float).ravel())
        + "]"
    )


def format_summary(scene, result, spread: Envelope | EnvelopeUnavailable | None = None) -> str:
    """Short human-readable summary of one solve (``spread``: the envelope's line when given)."""
    lines = [
        f"scene   {scene.name}  ({scene.source})",
        f"status  {result.status}: {result.message}",
    ]
    if result.ok:
        eig = (
            ""
            if result.min_eigenvalue is None
            else f"  (min reduced eigenvalue {result.min_eigenvalue:.4g})"
        )
        lines.append(f"stable  {result.stable}{eig}")
        lines.append(
            "energy  "
            + "  ".join(
                f"{k} {'null' if v is None else f'{v + 0.0:.6g}'}"
                for k, v in result.energy.items()
            )
            + "  [J]"
        )
        if result.energy_note:
            lines.append(f"        {result.energy_note}")
        width = max(len(n) for n in result.grips) if result.grips else 0
        for name, w in result.grips.items():
            lines.append(
                f"grip    {name:<{width}}  force {_vec(w.force)} N  torque {_vec(w.torque)} N m"
            )
        # a force the string is not within the answer's tolerance of is barrier residue
        contacts = pressed_obstacles(result, scene.problem, scene.options.error_tolerance)
        for i, f in contacts.items():
            ob = scene.problem.obstacles[i]
            lines.append(f"contact obstacles[{i}] {ob.name or ob.type}: total force {_vec(f)} N")
        for c in result.self_contacts:
            lines.append(
                f"self    s = {c.s_a:.4g} m and {c.s_b:.4g} m pressed together: force "
                f"{_vec(c.force)} N "
                f"(on s = {c.s_a:.4g} m; gap {c.gap:.4g} m)"
            )
        sag = max_sag(
            result.points, [g.pose.position for g in scene.problem.grips], scene.problem.gravity
        )
        lines.append(f"sag     {sag:.4g} m  (lowest point below the lowest grip, along gravity)")
    if result.status in ("ok", "unverified"):
        lines.append(
            f"check   equilibrium residual {result.equilibrium_residual_m:.3g} m (equivalent "
            f"centreline error)"
        )
    lines.append(
        f"solver  {result.iterations} iterations, {result.solve_time_ms:.1f} ms, "
        f"{result.basis} order {result.order}"
        + (f", IPOPT {result.ipopt_status}" if result.ipopt_status else "")
    )
    m = result.model
    if m is not None:
        kinds = ["planar" if m.planar else "3D"] + [
            k for k in ("twist", "stretch", "gravity") if getattr(m, k)
        ]
        err = m.estimated_error_m
        lines.append(
            f"model   {'auto' if m.auto else 'fixed'}: {', '.join(kinds)}; order {m.order}, "
            f"{m.obstacles} obstacle(s) in the NLP, {m.variables} unknowns"
            + (
                f", estimated error {err:.2g} m (tolerance {m.tolerance_m:.2g} m"
                + ("" if m.tolerance_met else ": NOT met, even at the highest order")
                + ")"
                if err is not None
                else ""
            )
        )
        for change in m.changes:
            lines.append(f"        model change: {change}")
    if spread is not None:
        lines.append(envelope_line(spread))
    return "\n".join(lines)


def envelope_line(spread: Envelope | EnvelopeUnavailable) -> str:
    """One summary line of an envelope: its largest σ and each grip's force σ, or why none."""
    if isinstance(spread, EnvelopeUnavailable):
        return f"envelope unavailable: {spread.reason}"
    k = int(np.argmax(spread.sigma))
    forces = ", ".join(f"{n} {_vec(g.force_sigma, 2)} N" for n, g in spread.grips.items())
    return (
        f"envelope max sigma {spread.max_sigma:.3g} m at s = {spread.s[k]:.4g} m (first "
        f"order, 1 sigma); force sigma {forces}"
    )


def parse_uncertainty(items: list[str] | None) -> dict[str, float]:
    """Return {key: σ} of ``--uncertainty KEY=SIGMA ...``; UsageError naming the bad item."""
    out: dict[str, float] = {}
    for item in items or ():
        key, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError
            out[key.strip()] = float(value)
        except ValueError:
            raise UsageError(
                f"--uncertainty: expected KEY=SIGMA (e.g. bend_stiffness=0.002), got {item!r}"
            ) from None
    return out


def scene_uncertainty(scene, sigmas: dict[str, float]) -> Uncertainty | None:
    """Return the scene's ``string.uncertainty`` with ``--uncertainty``'s σ over it, or None.

    Raises UsageError naming ``--uncertainty.<key>`` for an unknown key or a bad σ.
    """
    if not sigmas:
        return scene.uncertainty
    string = scene.problem.string
    merged = {} if scene.uncertainty is None else scene.uncertainty.marginal_sigmas(string)
    try:
        uncertainty = Uncertainty.from_sigmas({**merged, **sigmas}, "--uncertainty")
        uncertainty.check_string(string, "--uncertainty")
    except UncertaintyError as exc:
        raise UsageError(str(exc)) from None
    return uncertainty


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "scene",
        metavar="SCENE",
        help="scene file path, or the name of a shipped scene (see `dlo scenes`)",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print exactly one JSON object (schema in msg_docs/cli.md)",
    )
    p.add_argument(
        "--points",
        type=int,
        metavar="N",
        help="number of output samples along s (solver.output_points)",
    )
    p.add_argument("--basis", choices=BASES, help="Ritz basis (solver.basis)")
    p.add_argument(
        "--order",
        type=int,
        metavar="N",
        help="basis functions per field (solver.order); raises solver.quadrature_nodes to "
        "ceil(10 N / 3) if the scene's is smaller; implies --model full unless --model is given",
    )
    p.add_argument(
        "--model",
        choices=["auto", "full", "planar"],
        help="solver.model: auto (default: the smallest model the scene needs), full or planar",
    )
    p.add_argument(
        "--compile",
        action="store_true",
        help=(
            "compile the solver's KKT function to C (slow first build; only useful for benchmarks)"
        ),
    )
    p.add_argument(
        "--uncertainty",
        nargs="+",
        metavar="KEY=SIGMA",
        help="standard deviations of string keys in their units (e.g. bend_stiffness=0.002 "
        "weight_per_length=0.01), over the scene's string.uncertainty: adds the first-order "
        "shape and grip-wrench envelope (msg_docs/cli.md)",
    )
    add_record_arguments(p)


def run(args: argparse.Namespace) -> int:
    from ..solver import make_solver  # start-up (cli/__init__)

    scene = load_scene_arg(args.scene)
    options = _with_overrides(scene.options, args.points, args.basis, args.order, args.model)
    uncertainty = scene_uncertainty(scene, parse_uncertainty(args.uncertainty))
    guard = stdout_to_stderr() if args.json else contextlib.nullcontext()
    with guard:
        try:
            solver = make_solver(
                scene.problem, options, compile=compile_mode(args.compile), checks="sync"
            )
        except (
            ValueError
        ) as exc:  # the solver's own checks (e.g. loads[i].moment); they name the field
            raise UsageError(str(exc)) from None
        recorder = make_recorder(args)
        try:
            if recorder.enabled:
                recorder.log_scene(replace(scene, options=options), solver=solver)
                targets = {g.name: g.pose for g in scene.problem.grips}
                stamp = time.time_ns()
                recorder.log_targets(targets, update=0, ros_time_ns=stamp)
            result = solver.solve()
            # of the committed answer, before anything else solves
            spread = None if uncertainty is None else envelope(solver, result, uncertainty)
            if recorder.enabled:
                recorder.log_result(
                    result, update=0, ros_time_ns=stamp, targets=targets, warm=False
                )
                if isinstance(spread, Envelope):  # its 2 sigma tube, as the node records it
                    recorder.log_envelope(
                        spread.points,
                        2.0 * spread.sigma,
                        text=envelope_line(spread),
                        update=0,
                        ros_time_ns=stamp,
                    )
        finally:
            close_recorder(recorder)
    if args.json:
        out = {"scene": scene.name, "frame_id": scene.frame_id, **result.to_dict()}
        if spread is not None:
            out["envelope"] = spread.to_dict()
        print(json.dumps(json_safe(out), allow_nan=False))
    else:
        print(format_summary(scene, result, spread))
    return EXIT_OK if result.ok else EXIT_NOT_OK
