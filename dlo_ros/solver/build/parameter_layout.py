"""The layout of the NLP's parameter vector p.

The layout of the NLP's parameter vector p: a named slice per material, grip, load, obstacle,
contact slot and self-contact slot.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ...model.director import DirectorModel
from ...model.obstacles import OBSTACLE_TYPES
from ...model.problem import Problem
from ...model.ritz import RitzModel
from ..contact.obstacle_points import obstacle_arc_lengths
from ..options import SolverOptions


@dataclass
class ParameterLayout:
    """Named slices of the parameter vector p."""

    slices: dict[str, slice] = field(default_factory=dict)
    size: int = 0

    def add(self, name: str, n: int) -> None:
        self.slices[name] = slice(self.size, self.size + n)
        self.size += n

    def __getitem__(self, name: str) -> slice:
        return self.slices[name]


@dataclass(frozen=True)
class ContactSlots:
    """How many contact slots the NLP carries: per obstacle, and self-contact pairs."""

    #: contact slots per obstacle (solver/contact/obstacle_slots.py), 0 without obstacles
    obstacle: int
    #: self-contact slots (director 3D models only), 0: none
    self_contact: int


def parameter_layout(
    problem: Problem,
    model: DirectorModel | RitzModel,
    director: bool,
    options: SolverOptions,
) -> tuple[ParameterLayout, ContactSlots]:
    """Lay out p for ``problem`` on ``model``: every slice's name and size, and the slot counts.

    The order is the materials' (Rf, Rt, Re, D per quadrature node, a strip's Rl, the model's
    material terms), gravity, the radius, the grips, the loads, the relative positions, the
    obstacles' parameters, their contact slots, and the self-contact slots.
    """
    P, M = problem, model.quad.count
    lay = ParameterLayout()
    for name in ("Rf", "Rt", "Re", "D"):
        lay.add(name, M)
    if getattr(model, "lateral", False):  # a strip: its stiffness about d2 (director.py)
        lay.add("Rl", M)
    for name, size in model.material_sizes().items():  # filled by material_parameters
        lay.add(name, size)
    lay.add("gravity", 3)
    lay.add("radius", 1)
    for g in P.grips:
        lay.add(f"grip:{g.name}:position", 3)
        if director:
            lay.add(f"grip:{g.name}:frame", 9)  # R_g column-major: t_g, d1_g, d2_g
        else:
            lay.add(f"grip:{g.name}:angles", 3)
    for i, _ in enumerate(P.loads):
        lay.add(f"load:{i}:force", 3)
        if director:
            lay.add(f"load:{i}:moment", 3)
            # q_ref (or t_ref) of the moment's pseudo-potential
            lay.add(f"load:{i}:reference", 4)
        else:
            lay.add(f"load:{i}:moment", 1)
    for i, _ in enumerate(P.relative_positions):
        lay.add(f"relative:{i}", 3)
    for i, ob in enumerate(P.obstacles):
        lay.add(f"obstacle:{i}", OBSTACLE_TYPES[ob.type].size)
    # contact slots per obstacle (solver/contact/obstacle_slots.py): rows at arc lengths σ that
    # are parameters, placed at the string's closest approaches; per slot σ, on (1 or 0: an empty
    # slot reads −1 ≤ 0) and the row W(σ) of the integration matrix, x(σ) = x0 + T W(σ)ᵀ
    n_slots = options.obstacle_slots if P.obstacles else 0
    for i, _ in enumerate(P.obstacles):
        if n_slots:
            # 0: the row a slot replaces (one per obstacle row: uniform samples or mesh nodes)
            lay.add(f"samples:{i}:on", len(obstacle_arc_lengths(P, options, model)))
            lay.add(f"slots:{i}:s", n_slots)
            lay.add(f"slots:{i}:on", n_slots)
            lay.add(f"slots:{i}:w", n_slots * M)  # slot k's row at k M … (k + 1) M
            # x'(σ) = T Pᵀ and x''(σ) = T P'ᵀ, laid out as W (build/slot_envelope.py)
            lay.add(f"slots:{i}:t", n_slots * M)
            lay.add(f"slots:{i}:k", n_slots * M)
    n_self = options.self_contact_pairs if director else 0
    for k in range(n_self):
        lay.add(f"self:{k}", M + 1)
    return lay, ContactSlots(n_slots, n_self)


def slot_parameter_names(i: int) -> tuple[str, ...]:
    """Return obstacle i's slot parameters in p: σ, on, W(σ), P(σ), P'(σ), the rows' switches."""
    return tuple(f"slots:{i}:{part}" for part in ("s", "on", "w", "t", "k")) + (f"samples:{i}:on",)


def slot_matrix(p, params: ParameterLayout, i: int, slots: int, nodes: int, part: str = "w"):
    """W(σ) (``slots`` × ``nodes``) of obstacle i's contact slots, from p (numpy or CasADi).

    ``part`` "t": P(σ) instead, "k": P'(σ) (``slot_envelope.py``).
    """
    w = p[params[f"slots:{i}:{part}"]]
    return w.reshape(slots, nodes) if isinstance(w, np.ndarray) else ca.reshape(w, nodes, slots).T
