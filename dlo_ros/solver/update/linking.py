"""Stage: the linking-number check of the clamped span (``topology.py``).

Contract:

* ``ClampTurnTracker.advance(start, clamp_turns, problem)`` gives the clamps' turns after a target
  (``ctx.turns``), from the clamp frames of ``start`` (the committed shape) and the turns since it;
  it caches the frames between calls (queries from one shape ask the same);
* ``linking_jump(ctx, problem, start, state)`` gives the change of the linking number Tw + Wr
  between ``start`` and ``state`` when it is a jump the clamps' own turns (``ctx.turns``, known
  when ``start`` is ``ctx.start``) do not explain, else None;
* ``needs_check`` says when an update without self-contact is checked; ``linking_failure`` is the
  'failed' result of a jump.

``linking_jump`` is called through this module's attribute, so a test may wrap it.
"""

from __future__ import annotations

import numpy as np

from ...model.director import quat_to_frame
from ...model.problem import Grip, Problem
from ..build.nlp import StringNLP
from ..contact import topology as TP
from ..results.outputs import no_shape
from ..results.result import ShapeResult
from ..state import SolverState
from .context import UpdateContext


def linking_clamps(nlp: StringNLP, problem: Problem) -> list[Grip]:
    """Return the first and the last clamp (by s) when the linking number is conserved.

    That is when the twist is modelled and two clamps sit at different s; [] otherwise.
    """
    clamps = sorted((g for g in problem.grips if g.mode == "clamp"), key=lambda g: g.s)
    if (
        not nlp.director
        or not nlp.model.layout.frame
        or len(clamps) < 2
        or clamps[0].s == clamps[-1].s
    ):
        return []
    return [clamps[0], clamps[-1]]


class ClampTurnTracker:
    """The clamps' turns over a stream's targets, and the frames computed last (one per NLP)."""

    def __init__(self, nlp: StringNLP) -> None:
        """Track turns of ``nlp``'s clamps; nothing is cached yet."""
        self.nlp = nlp
        # (z, clamp names, ClampTurns): committed_turns' last answer
        self._turns_start: tuple | None = None
        # (the clamps' target quaternions as bytes, their frames, (ClampTurns, it advanced to
        # them) or None)
        self._clamp_frames: tuple | None = None
        # ((name, s, mode) of every grip, the indices of linking_clamps' grips among them): the
        # clamps of the grips last seen (a stream's grips differ in their poses alone)
        self._clamp_index: tuple[tuple, list[int]] | None = None
        # clamp name → (its target quaternion as bytes, its frame): a grip that did not turn keeps
        # its frame (the same object, so ``topology._turn`` sees it unchanged at once)
        self._frame_of: dict[str, tuple[bytes, np.ndarray]] = {}

    def advance(
        self, start: SolverState | None, clamp_turns: TP.ClampTurns | None, problem: Problem
    ) -> TP.ClampTurns | None:
        """Return the clamps' turns after ``problem``'s targets (``topology.ClampTurns``).

        ``clamp_turns``: the turns since the committed shape ``start`` (None: none asked for
        since; then from ``start``'s own clamp frames).  None without a committed shape.
        """
        if start is None:
            return None
        clamps = self.clamps(problem)
        if not clamps:
            return None
        turns = clamp_turns
        if turns is None or set(turns.frames) != {g.name for g in clamps}:
            turns = self.committed_turns(start, clamps)
        keys = [np.asarray(g.pose.orientation, dtype=float).tobytes() for g in clamps]
        key = b"".join(keys)
        if self._clamp_frames is None or self._clamp_frames[0] != key:
            # grips that moved without turning: kept
            self._clamp_frames = (key, self._frames(clamps, keys), None)
        key, frames, last = self._clamp_frames
        if last is not None and last[0] is turns:
            # the same step as the last time (queries from one shape)
            return last[1]
        advanced = turns.advanced({g.name: f for g, f in zip(clamps, frames)})
        self._clamp_frames = (key, frames, (turns, advanced))
        return advanced

    def clamps(self, problem: Problem) -> list[Grip]:
        """Return the clamps ``linking_clamps`` picks of ``problem`` (remembered per layout)."""
        layout = tuple((g.name, g.s, g.mode) for g in problem.grips)
        known = self._clamp_index
        if known is None or known[0] != layout:
            chosen = linking_clamps(self.nlp, problem)
            index = [next(i for i, g in enumerate(problem.grips) if g is c) for c in chosen]
            known = self._clamp_index = (layout, index)
        return [problem.grips[i] for i in known[1]]

    def _frames(self, clamps: list[Grip], keys: list[bytes]) -> list[np.ndarray]:
        """Return the clamps' target frames (``quat_to_frame``), a clamp that did not turn kept.

        Each frame is ``quat_to_frame`` of its quaternion alone (the same numbers as a row of
        several: ``quaternion_frames._few_quat_to_frame`` works row by row).
        """
        frames = []
        for g, key in zip(clamps, keys):
            known = self._frame_of.get(g.name)
            if known is None or known[0] != key:
                frame = quat_to_frame(np.frombuffer(key)[None, :])[0]
                frame.flags.writeable = False  # kept in every ClampTurns advanced to it
                known = self._frame_of[g.name] = (key, frame)
            frames.append(known[1])
        return frames

    def committed_turns(self, start: SolverState, clamps: list[Grip]) -> TP.ClampTurns:
        """Return no turn yet, from ``start``'s own clamp frames.

        Kept while that shape is the same (queries start from it every time).
        """
        z, names = start.z, tuple(g.name for g in clamps)
        cached = self._turns_start
        if cached is None or cached[1] != names or not np.array_equal(cached[0], z):
            s = np.array([g.s for g in clamps])
            frames = self.nlp.model.pose_frames(z, s)
            cached = (z.copy(), names, TP.ClampTurns({g.name: f for g, f in zip(clamps, frames)}))
            self._turns_start = cached
        return cached[2]


def linking_jump(
    ctx: UpdateContext, problem: Problem, start: SolverState, state: SolverState
) -> TP.LinkChange | None:
    """Return ΔLk of the clamped span from ``start`` to ``state`` when it is a jump, else None.

    ΔLk is ``topology.link_change`` between the first and the last clamp; a jump is |ΔLk| >
    ``topology.JUMP``.  None also when the twist is not modelled or fewer than two grips are
    clamps (Lk is then not conserved: a free roll lets the twist out).  The clamps' turns are
    those summed over every target since the committed shape (``ctx.turns``), known when ``start``
    is the update's own start.
    """
    nlp = ctx.parts.nlp
    clamps = linking_clamps(nlp, problem)
    if not clamps:
        return None
    s = np.linspace(clamps[0].s, clamps[-1].s, TP.SAMPLES)
    turns = ctx.turns
    known = turns is not None and start is ctx.start
    m = nlp.model
    change = TP.link_change(
        m.positions(start.z, s),
        m.pose_frames(start.z, s),
        m.positions(state.z, s),
        m.pose_frames(state.z, s),
        (turns.turns[clamps[0].name], turns.turns[clamps[-1].name])
        if turns is not None and known
        else None,
    )
    return change if change.jumped else None


def needs_check(ctx: UpdateContext, result: ShapeResult, newton_only: bool) -> bool:
    """Whether an update without self-contact is checked for a linking-number jump.

    Where a warm update left the Newton path (IPOPT, continuation or the cold fallback can land a
    whole turn away; Newton converges from next to the committed shape) or Newton went far from
    it (substeps, leaving a saddle: ``ctx.newton_far``), and where the clamps turned more than a
    quarter turn since the committed shape (after refused updates: Newton then follows the clamp
    frame, which cannot tell a turn from its opposite): a stream must not lose turns of twist to
    a cold start.
    """
    turns = ctx.turns
    lagging = turns is not None and any(abs(a) > np.pi / 2 for a in turns.turns.values())
    return result.status in ("ok", "unverified") and (lagging or ctx.newton_far or not newton_only)


def linking_failure(
    ctx: UpdateContext, jump: TP.LinkChange, iterations: int, warm: bool
) -> ShapeResult:
    """Return 'failed': the update changed the clamped string's linking number."""
    return no_shape(
        ctx.parts.options,
        ctx.parts.summary(),
        "failed",
        (
            f"topology: the linking number of the clamped string changed by "
            f"{jump.unexplained:+.2f} turns in one update (twist {jump.twist:+.3f}, writhe "
            f"{jump.writhe:+.3f} by {jump.method}, clamps turned {jump.clamps:+.3f}): the solver "
            f"jumped to another branch (whole turns of twist released, or the string passed "
            f"through itself); not published"
        ),
        iterations=iterations,
        warm_started=warm,
    )
