"""The contact points of a solved shape, which a refinement knows as kinks.

A point contact is a jump of the internal force, so the curvature has a kink there: the rule
(``rule.py``) splits an element at such a point rather than at its middle.  How smooth a shape is
on each element (its Legendre coefficients' decay) is ``results/element_error.coefficient_decay``.
"""

from __future__ import annotations

from ..shape_solver import ShapeSolver


def contact_kinks(solver: ShapeSolver) -> tuple[float, ...]:
    """Return the arc lengths [m] of the committed state's filled obstacle contact slots.

    A point contact is a jump of the internal force: the curvature has a kink there.
    """
    state = solver.committed_state
    if state is None or not solver.nlp.obstacle_slots:
        return ()
    out: list[float] = []
    for i in range(len(solver.nlp.slot_rows)):
        slots = solver.parameters.slots(state.p, i)
        out += [float(s) for s, on in zip(slots.s, slots.on) if on > 0]
    return tuple(sorted(out))
