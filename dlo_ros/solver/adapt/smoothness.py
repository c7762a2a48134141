"""How smooth a solution is on each element: the decay rate of its Legendre coefficients.

On element k the rotation field (quaternions or tangents, each component) is a polynomial of
degree n_k − 1 with Legendre coefficients a_j.  A field analytic on the element has |a_j| ~ C ρ^j
with ρ < 1; one with a kink inside (a jump of a derivative) decays algebraically, which over the
last degrees looks like ρ near 1.  ρ_k is exp of the least-squares slope of log max_c |a_j| over
the upper half of the degrees, leaving out coefficients at rounding level (below ``FLOOR`` times
the largest): an element resolved to rounding gives 0.  Also the contact points a caller knows as
kinks (``contact_kinks``).
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial import legendre as Leg

from ...model.director import DirectorModel
from ..shape_solver import ShapeSolver

#: coefficients below this fraction of an element's largest are rounding noise
FLOOR = 1e-13


def element_decay(values: np.ndarray, tau: np.ndarray) -> float:
    """Return ρ of one element from nodal ``values`` (n, c) at its LGL nodes ``tau`` in [−1, 1]."""
    n = values.shape[0]
    coeffs = np.linalg.solve(Leg.legvander(tau, n - 1), values)  # (n, c)
    size = np.max(np.abs(coeffs), axis=1)
    top = float(size.max())
    j = np.arange(n)
    use = (j >= n // 2) & (size > FLOOR * top)
    if top == 0.0 or np.count_nonzero(use) < 2:
        return 0.0
    slope = np.polyfit(j[use], np.log(size[use]), 1)[0]
    return float(min(1.0, np.exp(slope)))


def decay_rates(model: DirectorModel, z: np.ndarray) -> np.ndarray:
    """Return ρ_k of the rotation field of ``z`` on each element of ``model``'s mesh."""
    mesh, values = model.mesh, model.node_values(z)
    rates = []
    for e, el in enumerate(mesh.elements):
        rows = values[mesh.first[e] : mesh.first[e] + el.count]
        rates.append(element_decay(rows, el.tau))
    return np.array(rates)


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
