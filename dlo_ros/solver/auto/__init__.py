"""``solver.model: auto``: model no more than a scene needs.

AutoShapeSolver picks the smallest model for the scene, runs a ShapeSolver on it, and checks the
choice a posteriori against ``error_tolerance`` (δ, default 1e-3·L), escalating on its own when a
check fails.  Reductions and their checks:

* planar — grips, held tangents, gravity, forces, relative offsets and obstacles in one plane,
  moments
  along its normal, and the clamps impose no twist about the tangent: solve for φ alone.  Exact by
  symmetry *if* the planar equilibrium is stable in 3D: checked by the smallest eigenvalue of the
  full model's reduced Hessian at the embedded planar shape (a twist-free strip under compression
  leaves its plane); unstable → full model.
* twist — ψ is an unknown only when two clamps and Rt > 0 can hold it (otherwise ω ≡ 0 exactly).
* stretch — inextensible first; the elongation bound max|F_grip|·L / min Re > δ/2 → extensible
  model. Grips farther apart than the inextensible string between them reaches, or taut within
  δ/2 of it (the inextensible model leaves a taut string only the straight line: Greenhill's
  twisted rod could not buckle), choose the extensible model at once, or switch to it when a
  stream carries them there.
* gravity — dropped when D_max L⁴ / (8 Rf_min) (a cantilever's tip deflection, the largest a string
  held at ≥ 1 point sags under its weight at small deflection) is below δ/10.
* obstacles — an obstacle is in the NLP only if the string can reach it: within max(s_g, L − s_g) +
  L/4
  of every grip g (the L/4 margin adds it a move before it can touch).  A move that brings a new
  one within that range rebuilds the NLP with it, keeping the warm start.
* mesh (element models: the director model and the planar model, basis 'elements', split at
  grips, loads and material knots) — starts with order 12 shared out by element length; its
  a-posteriori estimate comes from the committed shape itself (``results/element_error.py``: the
  strong-form equilibrium residual per element, times 2, or 4 when an element's Legendre
  coefficients decay too slowly for a smooth field: a kink inside), no second model is solved.
  Over δ/2 → the mesh ``adapt/rule.py`` proposes: elements split where not smooth or at a known
  contact point, more nodes where smooth (``mesh_check.py``, at most MAX_UNKNOWNS nodes per field);
  in a stream's check, under δ/50 a coarser one (hysteresis: a refined element lands at a fifth of
  its share).  The estimate is reported as estimated_error_m.
* order (a planar or Euler-angle model in another basis the scene chose) — the lowest of 8, 12,
  16, 24, 32 whose centreline moves by less than δ/2 when the order is raised to the next one (a
  warm shadow solver), re-checked every ``recheck_every`` updates; over δ/2 → next order; once per
  model the next lower order is tried and kept within δ/4.  The topology and stability escalations
  inside one update (``escalate.py``) also step up this ladder, with the default mesh of the
  order.
* reference frame (3D with ``rotation: euler`` only) — when a tangent of the checked shape comes
  within
  POLE_MIN_DEG of the Euler angles' pole n = R0 e_z, the same model with n turned to the direction
  farthest from every tangent (near the pole the basis order stops converging).  The default 3D
  model (``rotation: director``) has no pole and never turns.
* equilibrium residual — every check also takes the checked result's strong-form residual
  (ShapeResult.equilibrium_residual_m) as an error estimate: the order's estimate is the larger of
  the shadow's centreline change and the residual, so a shape that is not an equilibrium raises the
  order.
* obstacle samples — obstacles are enforced at ``obstacle_samples`` points (41), an error the order
  shadows cannot see (they share the samples).  Two parts, the larger counts: between the samples
  the string can cut into an obstacle (a chord of spacing h cuts a sphere of radius R by about
  h²/8R), measured over 8× as many points; and, while the shape touches an obstacle, the samples
  shadow: the same model with 2n − 1 samples solved from the checked shape, whose centreline
  change, doubled (the sampled contact converges to first order in h: a string lying over a sphere
  can slide along it with almost no change of energy, and each sample spacing leaves its own
  shallow well along that slide), estimates the error of the n-sample answer.  The sampling part is
  added to estimated_error_m; over δ/2 the samples go to 2n − 1 (81, 161, 321, 641: the old samples
  stay), the model the shadow already built and warmed.  At MAX_SAMPLES the last shadow's change
  (undoubled: the error of the finer model) stays the sampling estimate.
* self-contact — modelled only once a committed shape comes within reach of itself (two samples the
  exclusion arc apart closer than the candidate reach D + max(4h, 0.03 L),
  solver/contact/self_contact.py): then the 3D director model with ``self_contact_pairs`` slots
  (the option's value, or AUTO_SELF_CONTACT_PAIRS when it is 0) replaces the current one and the
  update is solved again on it, so no shape that passes through itself is published; it says so in
  ``reasons`` ("self-contact: …").  Not with ``rotation: euler`` (self-contact needs the director
  model).  Once in, it stays.

Switching models maps the previous solution into the new one (ShapeSolver.adopt_warm_start), so a
stream keeps its warm start.  Every change is kept in ``changes`` (time, reason) and reported in
ShapeResult.model (``changed``: the changes made during that solve).

Checks run on a worker thread from a snapshot of the solve (``checks='background'``, the default:
the library and the node) or synchronously inside ``solve`` (``checks='sync'``: the CLI's one-shot
answers).  A cold solve (and ``check_now``) is checked before it returns; a streamed update k's
check takes effect just before update k + CHECK_LAG in both modes (:mod:`.check_schedule`), so
that a stream's models and shapes do not depend on timing: the worker builds the refined mesh (or
the order shadow) and the 3D checker into a pool of models, and the verdict switches to the pooled
model the check already built. The 3D model of a planar choice is built
ahead (at start, and again after any change), so targets leaving the plane switch without a build;
an obstacle within L/2 of reach is built ahead, and enters the NLP at L/4.  Only the basis order
goes down during a run (tried once per model); a 3D model never returns to planar, and an obstacle,
once in, stays (a scene change re-chooses).

The modules: :mod:`.auto_solver` (AutoShapeSolver, the coordinator), :mod:`.factory`
(make_solver), :mod:`.choice` (the model ladder), :mod:`.reach` (what a scene lets auto leave
out), :mod:`.reduced` and :mod:`.pool` (the reduced models and the pool of built ones),
:mod:`.background` (the check worker), :mod:`.follow` (a richer model when the targets need one,
and models built ahead), :mod:`.checks`, :mod:`.mesh_check` and :mod:`.shadows` (the checks),
:mod:`.check_schedule` (when a stream's check takes effect),
:mod:`.escalate` (escalations inside one update), :mod:`.query_refine` and :mod:`.query_verify`
(a query's refinement and what it may claim), :mod:`.report` (a result's ``model`` summary).
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
