"""``solver.model: auto``: model no more than a scene needs.

AutoShapeSolver picks the smallest model the scene allows a priori (planar or 3D, twist, stretch,
gravity, the obstacles within reach), solves on it, and checks the committed shape a posteriori
against ``error_tolerance`` (δ, default 1e-3·L), switching to a richer model (or a finer, in a
stream also a coarser, element mesh) when a rule fires.  Self-contact is modelled once a shape
reaches or passes through itself.  The whole policy — what it chooses, the triggers in order, the
check schedule, what it never does and what the tolerance means — is one page of
``msg_docs/model_and_solver.md`` ("auto's policy"); the a-posteriori rule is one function,
:func:`.policy.decide`.

The modules: :mod:`.auto_solver` (AutoShapeSolver, the coordinator), :mod:`.factory`
(make_solver), :mod:`.choice` (the first model and the model ladder), :mod:`.reach` (what a scene
lets auto leave out), :mod:`.reduced` and :mod:`.pool` (the reduced models and the pool of built
ones), :mod:`.background` (the check worker), :mod:`.follow` (a richer model when the targets need
one, and models built ahead), :mod:`.escalate` (escalations inside one update), :mod:`.policy`
(the a-posteriori rule), :mod:`.checks`, :mod:`.mesh_check` and :mod:`.shadows` (its evidence),
:mod:`.stream_checks` and :mod:`.check_schedule` (when a check runs and its verdict takes
effect), :mod:`.query_refine` and :mod:`.query_verify` (a query's refinement and what it may
claim), :mod:`.report` (a result's ``model`` summary).
"""

from .auto_solver import AutoShapeSolver
from .background import SWITCH_INTERVAL_S
from .choice import MAX_SAMPLES, ORDERS, ModelChoice
from .factory import make_solver

__all__ = [
    "AutoShapeSolver",
    "make_solver",
    "ModelChoice",
    "MAX_SAMPLES",
    "ORDERS",
    "SWITCH_INTERVAL_S",
]
