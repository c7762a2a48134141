"""An NLP on another mesh of a built NLP's topology, sharing every function it built.

A director model's functions read the element mesh's geometry (j = 2/h and the weights w at the
quadrature nodes) from p (``mesh_parameters.py``), so the functions built for mesh A, evaluated
with mesh B's p, are mesh B's when both meshes have one topology (``mesh_geometry.MeshTopology``:
the same node counts per element and quadrature) and the scene's own arc lengths (grips, loads,
relative positions' ends, material knots) sit on the same breakpoints of both.  :func:`clone_nlp`
makes the NLP of mesh B from A's without building anything symbolic: it shares A's CasADi
functions, IPOPT's problem and derivatives, p's layout and every row table, and makes its own the
parts numpy computes from the geometry:

* the model (``DirectorModel`` on mesh B: positions, slot placement, transfer of shapes);
* the obstacle rows' arc lengths, weights and spacing (the rows on the mesh's nodes);
* the node map E (``node_map_of`` with B's B and B') and its dense blocks (the compiled drivers');
* the reference frame R0, chosen from its own scene as a build would (the cold start's plane; a
  3D director model's functions do not depend on it): with A's, a data set's answers depended on
  the order its samples came to a worker.

What stays A's: the flattened SX graph (``nlp['f']``, ``g_sym``, ``z_sym``, ``p_sym``), whose sizes
and sparsity hold for B and whose values do not.  ``own_symbols`` is False on a clone, and
:func:`symbolic_nlp` gives the NLP whose graph is B's (built on first use) to the one module that
differentiates that graph (``results/sensitivity.py``).

Refused (``ValueError``, the caller builds instead): a non-director model, another topology, a
scene arc length on another breakpoint, obstacle rows at uniform samples (their interpolation rows
depend on the geometry).
"""

from __future__ import annotations

import numpy as np

from ...model.director import DirectorModel
from ...model.mesh_geometry import MeshTopology
from ...model.problem import Problem
from ..contact.obstacle_points import obstacle_arc_lengths, row_spacing, row_weights
from .mesh import MeshSpec, element_mesh
from .mesh_parameters import node_map_of
from .nlp import StringNLP, choose_reference_frame
from ..options import SolverOptions
from .structure import breakpoints, models_twist

#: attributes a clone computes for itself, or drops (functools.cached_property values of the
#: template that depend on its geometry, and its symbolic stand-in)
_OWN = ("node_blocks", "_symbolic")


def clone_or_build(
    problem: Problem,
    options: SolverOptions,
    reference_frame: np.ndarray | None,
    mesh_spec: MeshSpec | None,
    template: StringNLP | None,
) -> StringNLP:
    """Return ``template``'s clone on ``mesh_spec`` where it fits, else a new ``StringNLP``.

    ``template``: an NLP of ``problem``'s structure with ``options`` (the caller's
    ``structure_key``), or None.
    """
    if template is not None and mesh_spec is not None and template.options == options:
        try:
            return clone_nlp(template, problem, mesh_spec, reference_frame)
        except ValueError:
            pass  # another topology or layout: built below
    return StringNLP(problem, options, reference_frame, mesh_spec)


def clone_nlp(
    template: StringNLP,
    problem: Problem,
    mesh_spec: MeshSpec,
    reference_frame: np.ndarray | None = None,
) -> StringNLP:
    """Return the NLP of ``problem`` on ``mesh_spec``, sharing ``template``'s functions.

    ``problem`` must have ``template.problem``'s structure (the caller's ``structure_key``);
    raise ValueError when the mesh does not fit ``template``'s functions (module docstring).
    ``reference_frame``: R0 (default: chosen from ``problem``, as a build would; a 3D director
    model's functions do not depend on it, its cold start does).
    """
    if not template.director or template.planar:
        raise ValueError("a clone needs a 3D director model (its functions read the mesh from p)")
    problem.validate()
    if models_twist(problem, template.options) != template.twist:
        raise ValueError("the scene's twist field differs from the template's")
    old = template.model.mesh
    mesh = element_mesh(problem, template.options, mesh_spec)
    if MeshTopology.of(mesh) != MeshTopology.of(old):
        raise ValueError("the mesh's topology differs from the template's")
    own, built = breakpoints(problem), breakpoints(template.problem)
    if _indices(mesh.breakpoints, own) != _indices(old.breakpoints, built):
        raise ValueError("the scene's arc lengths sit on another breakpoint than the template's")
    if problem.obstacles and template.options.obstacle_points != "nodes":
        raise ValueError("obstacle rows at uniform samples depend on the mesh's geometry")
    clone = object.__new__(StringNLP)
    clone.__dict__.update({k: v for k, v in template.__dict__.items() if k not in _OWN})
    clone.problem, clone.mesh_spec = problem, mesh_spec
    clone.r0 = (
        np.asarray(reference_frame, dtype=float)
        if reference_frame is not None
        else choose_reference_frame(problem, template.options.frame)
    )
    base = template.model
    clone.model = DirectorModel(
        template.length, mesh, base.layout.frame, base.layout.stretch, lateral=base.lateral
    )
    clone.obstacle_s = obstacle_arc_lengths(problem, template.options, clone.model)
    if len(clone.obstacle_s) != len(template.obstacle_s):
        raise ValueError("the mesh gives another number of obstacle rows")
    clone.obstacle_weights = row_weights(clone.obstacle_s, template.options, clone.model)
    clone.obstacle_spacing = row_spacing(clone.obstacle_s)
    clone.node_map = node_map_of(clone.model.layout, template.node_width, mesh.B, mesh.dB)
    # the flattened energies are the template mesh's (tests build them for their own mesh)
    clone.__dict__["energy_fn"] = None
    clone.own_symbols = False
    return clone


def symbolic_nlp(nlp: StringNLP) -> StringNLP:
    """Return an NLP whose flattened SX graph (``nlp['f']``, ``g_sym``) is ``nlp``'s mesh's.

    ``nlp`` itself when it built its graph; for a clone, a full build of its mesh (made once).
    """
    if nlp.own_symbols:
        return nlp
    built = nlp.__dict__.get("_symbolic")
    if built is None:
        built = StringNLP(nlp.problem, nlp.options, nlp.r0, nlp.mesh_spec)
        nlp.__dict__["_symbolic"] = built
    return built


def _indices(points: np.ndarray, arc_lengths: list[float]) -> list[int]:
    """Return the index of the breakpoint nearest each of ``arc_lengths``."""
    return [int(np.argmin(np.abs(np.asarray(points) - s))) for s in arc_lengths]
