"""A committed equilibrium of one NLP: the KKT point (z, λ) a solve ended on, and more.

It also keeps what the solve already knows there (derivatives, eigenpair, outputs).

The next solve warm-starts from it: Newton steps reuse the stored Newton matrix and residual when
only the grip targets changed (they enter the constraints linearly), IPOPT restarts from z and its
multipliers, the stability check reuses the stored Hessian and Jacobian.  Everything is in the
NLP's scaled units (z: ``StringNLP`` unknowns, λ: IPOPT's multipliers, λ_SI = λ / (row_scale · σ)).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # for the annotation only: the contact modules' own states are not this module's
    from .contact.obstacle_slots import SlotMotion
    from .contact.self_contact import ContactSlots


class Inertia(Enum):
    """``SolverState.reduced_eigen`` when a compiled loop's verdict came from the inertia alone.

    [∇²L Jᵀ; J 0] of the held rows had inertia (n, m, 0) with no tiny pivot
    (``native/dlo_inertia.h``, ``results/inertia.py``): stable, and no eigenpair was computed.
    """

    STABLE = "stable: [H Jᵀ; J 0] of the held rows has inertia (n, m, 0)"


@dataclass
class SolverState:
    """A committed equilibrium: the warm start of the next solve."""

    z: np.ndarray
    lam_g: np.ndarray
    lam_x: np.ndarray
    p: np.ndarray
    hessian: np.ndarray | None = None  # ∇²L at z, when the solve already has it
    jacobian: np.ndarray | None = None  # ∂g/∂z at z
    energies: np.ndarray | None = None  # bend, twist, stretch, gravity, work at z
    gradient: np.ndarray | None = None  # ∇f at z
    #: constraint values (scaled rows) at z; a moved contact slot's row that carries a force
    #: counts as at its bound (``update/slot_rounds.carry_slots``: Newton keeps it active)
    g: np.ndarray | None = None
    #: eigenvector of the most negative reduced curvature
    unstable_direction: np.ndarray | None = None
    #: (λ_min, its eigenvector in z) of ``hessian`` reduced on the rows that
    #: ``stability.held_rows`` holds, computed with it by a compiled loop (``native/newton.py``),
    #: or ``Inertia.STABLE`` when the loop's inertia settled the verdict without it; cleared with
    #: ``hessian``, None when not computed
    reduced_eigen: tuple[float, np.ndarray] | Inertia | None = None
    kkt: np.ndarray | None = None  # contact-free Newton matrix [∇²L Jᵀ; J 0] at z (free rows)
    residual: np.ndarray | None = None  # contact-free residual [∇f + Jᵀλ; g] at z (free rows)
    #: the self-contact pairs p holds (self-contact models)
    contact: ContactSlots | None = None
    #: the outputs at z as the compiled loop that reached it evaluated them
    #: (``native.outputs.ComputedOutputs``, with the inputs it used), None when not evaluated
    outputs: object | None = None
    #: how the obstacle contact slots moved over the update that reached this state
    #: (``contact/obstacle_slots.SlotMotion``, ``update/slot_rounds.py``), None: not tracked
    slot_motion: SlotMotion | None = None
    #: adopted from another element mesh of the same model (``ShapeSolver.adopt_warm_start``):
    #: that mesh's shape re-expanded on this one, not an equilibrium of this NLP; a saddle Newton
    #: lands on from it is the mapping's, left by IPOPT from the start (``update/ladder.py``)
    remeshed: bool = False

    def copy(self) -> SolverState:
        """Return a copy of z, λ and p (what another thread may adopt later).

        The derivative caches are left out.
        """
        return SolverState(
            self.z.copy(),
            self.lam_g.copy(),
            self.lam_x.copy(),
            self.p.copy(),
            contact=None if self.contact is None else self.contact.copy(),
            slot_motion=self.slot_motion,
            remeshed=self.remeshed,
        )
