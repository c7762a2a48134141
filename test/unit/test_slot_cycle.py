"""The obstacle slot rounds (``update/slot_rounds.py``) stop where they start to cycle.

A round is a function of its start and its slots: a round that would start where an earlier one
did (the same unknowns to ``SAME_START``, the same slots) gives that round's answer again, and
the rounds after it repeat too.  The paper's Fig. 3 strip on its floor at ρ = 1000, cold, is such
a case (measured): on its fifth mesh a slot placed at the touching minimum gave a saddle, left
by shifted Newton steps to an answer on which the slot held force with no minimum left; the slot
emptied, the first answer came back, and so on until the 8 rounds ran out.

Checked here against the rounds run out (``_repeats`` disabled): the same answer (the kept one
is the rounds' best either way), in fewer saddle escapes; and the rule itself on a made-up cycle
of two answers, with its limits (a start that moved, a slot that moved).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from dlo_ros.scene import load_scene
from dlo_ros.scene.reading import scene_from_dict
from dlo_ros.scene.writing import scene_to_dict
from dlo_ros.solver.auto.factory import make_solver
from dlo_ros.solver.contact.obstacle_slots import SlotPlacement
from dlo_ros.solver.state import SolverState
from dlo_ros.solver.update import ladder, slot_rounds


def fig3_floor(rho: float):
    """config/scenes/bench_fig3_floor.yaml at weight ρ [N/m] (its own solver section)."""
    d = scene_to_dict(load_scene("bench_fig3_floor"))
    d["string"]["weight_per_length"] = rho
    return scene_from_dict(d)


def cold_solve(monkeypatch, cycles_stop: bool):
    """The default's cold solve of Fig. 3 at ρ = 1000: (result, saddle escapes made)."""
    escapes = []
    leave = ladder.leave_newton_saddle

    def counted(*args, **kwargs):
        escapes.append(1)
        return leave(*args, **kwargs)

    with monkeypatch.context() as m:
        m.setattr(ladder, "leave_newton_saddle", counted)
        if not cycles_stop:
            m.setattr(slot_rounds, "_repeats", lambda *args: False)
        scene = fig3_floor(1000.0)
        result = make_solver(scene.problem, scene.options, compile="off", checks="sync").solve()
    return result, len(escapes)


def test_the_strip_on_its_floor_stops_its_cycling_rounds_with_the_same_answer(monkeypatch):
    stopped, few = cold_solve(monkeypatch, cycles_stop=True)
    run_out, many = cold_solve(monkeypatch, cycles_stop=False)
    assert stopped.ok and run_out.ok, (stopped.message, run_out.message)
    assert stopped.stable and run_out.stable
    assert np.max(np.abs(stopped.points - run_out.points)) < 1e-9
    assert stopped.model.variables == run_out.model.variables
    assert stopped.model.tolerance_met and run_out.model.tolerance_met
    # the cycle's saddle is left once per cycle, not once per round
    assert many >= 4, many
    assert few <= many - 2, (few, many)


def placement(s: float, on: float = 1.0) -> list[SlotPlacement]:
    return [SlotPlacement(np.array([s, 0.0]), np.array([on, 0.0]), np.ones(3), np.full(2, 0.0))]


def state(z) -> SolverState:
    return SolverState(np.asarray(z, dtype=float), np.zeros(2), np.zeros(3), np.zeros(1))


def test_a_round_repeats_only_from_the_same_start_with_the_same_slots():
    length = 2.0
    first = (state([0.3, -1.2, 4.0]), placement(0.5))
    same = state([0.3, -1.2, 4.0 + 1e-9])  # Newton's rounding between two answers of one system
    assert slot_rounds._repeats(first, same, placement(0.5 + 1e-10), length)
    # the start moved
    moved = state([0.3, -1.2, 4.0 + 1e-6])
    assert not slot_rounds._repeats(first, moved, placement(0.5), length)
    # a slot moved, emptied, or the mesh changed
    assert not slot_rounds._repeats(first, same, placement(0.5 + 1e-6), length)
    assert not slot_rounds._repeats(first, same, placement(0.5, on=0.0), length)
    assert not slot_rounds._repeats(first, state([0.3, -1.2]), placement(0.5), length)


def test_the_rounds_of_a_two_answer_cycle_stop_at_its_second_lap(monkeypatch):
    """A made-up solve whose answers alternate A, B, A, B: the rounds stop when B comes back
    with the slots it had, and keep the first answer (all offsets equal: the first is best)."""
    answers = [state([1.0, 0.0]), state([0.0, 1.0])]
    calls = []

    class Parts:
        nlp = type("NLP", (), {"length": 1.0, "options": replace_options()})()
        parameters = None

    def offset(parts, problem, s):
        return float("inf")

    def placed(parts, s, history, before):
        return placement(0.25 if s.z[0] == 1.0 else 0.75)

    def solve(ctx, problem, warm):
        calls.append(ctx.start.z.copy())
        nxt = answers[1] if ctx.start.z[0] == 1.0 else answers[0]
        return Result(), replace(nxt)

    monkeypatch.setattr(slot_rounds, "slot_offset", offset)
    monkeypatch.setattr(slot_rounds, "placed_slots", placed)
    monkeypatch.setattr(slot_rounds, "slot_motion", lambda *a: None)
    ctx = Context(Parts())
    result, kept = slot_rounds.place_slots_again(
        ctx, None, Result(), answers[0], solve, rounds=8, start=None
    )
    # rounds from A and from B, then A again with A's slots: a cycle, stopped
    assert len(calls) == 2, calls
    assert kept is answers[0]
    without = []
    monkeypatch.setattr(slot_rounds, "_repeats", lambda *a: False)

    def counted(ctx, problem, warm):
        without.append(1)
        return solve(ctx, problem, warm)

    slot_rounds.place_slots_again(ctx, None, Result(), answers[0], counted, rounds=8)
    assert len(without) == 8


def replace_options():
    return type("Options", (), {"error_tolerance": 1e-3})()


class Result:
    """The fields of a ShapeResult the rounds read and write."""

    def __init__(self):
        self.status, self.iterations, self.ipopt_status = "ok", 1, "Newton"
        self.warm_started, self.message, self.stable = True, "", True


class Context:
    """An UpdateContext's fields the rounds use: parts, streamed, scoped(start, slot_override)."""

    def __init__(self, parts):
        self.parts, self.streamed, self.start, self.slot_override = parts, False, None, None

    def scoped(self, **fields):
        ctx = self

        class Scope:
            def __enter__(self):
                self.saved = {k: getattr(ctx, k) for k in fields}
                for k, v in fields.items():
                    setattr(ctx, k, v)

            def __exit__(self, *exc):
                for k, v in self.saved.items():
                    setattr(ctx, k, v)

        return Scope()
