"""Paper Fig. 3 with its floor: the planar element model on a fixed mesh converges to the
independent floor reference (test/reference/floor_rod.py) as nodes are added.

The mesh is given by hand (``MeshSpec``) with breakpoints at the reference's lift-off points, the
obstacle rows on the mesh nodes.  This checks that the model CAN represent the strip's answer
(shape, lift-off points, energy); whether ``auto`` finds that mesh by itself is another question
(bench/results/fig3_floor_default.md).  A start near the wanted equilibrium is the reference's own
discrete rod (its tangent angles at the mesh nodes): at ρ = 1000 and 2000 several planar
equilibria exist and a cold start from the generic buckled guess reaches another one.
"""

from __future__ import annotations

import numpy as np
import pytest
from reference.floor_rod import fig3_floor, shoot, solve_discrete, start_angles

from dlo_ros.model.elements import element_mesh_of
from dlo_ros.scene import load_scene
from dlo_ros.scene.reading import scene_from_dict
from dlo_ros.scene.writing import scene_to_dict
from dlo_ros.solver.build import initial_guess as guess_module
from dlo_ros.solver.build.mesh import MeshSpec
from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.shape_solver import ShapeSolver
from dlo_ros.solver.update import attempts, contact_rounds


def reference(rho: float, which: str):
    """(discrete rod, shooting solution) of one equilibrium of the floor reference."""
    pr = fig3_floor(rho)
    if which == "symmetric":
        rod = solve_discrete(pr, 100, start_angles(100, 0.5), symmetric=True)
        kinds = ["point"] * len(rod.runs) if rho <= 1000 else None
        return rod, shoot(rod, kinds, symmetric=kinds is None)
    rod = solve_discrete(pr, 100, start_angles(100, 0.2))  # 'right': the curl near s = 0
    return rod, shoot(rod)


def problem_at(rho: float):
    scene = load_scene("bench_fig3_floor")
    d = scene_to_dict(scene)
    d["string"]["weight_per_length"] = rho
    return scene_from_dict(d, source=scene.source).problem


def solve_on_mesh(rho, rod, lift_off, order, monkeypatch, start_near=True):
    """Cold solve of the planar element model with breakpoints at ``lift_off``."""
    opts = SolverOptions(
        model="planar",
        basis="elements",
        obstacle_points="nodes",
        order=order,
        quadrature_nodes=order + 8,
        output_points=1001,
    )
    solver = ShapeSolver(problem_at(rho), opts, mesh=MeshSpec(tuple(lift_off)))
    if start_near:
        nodes = element_mesh_of(solver.nlp.model).nodes

        def near_reference(nlp, parameters, problem):
            z = guess_module.initial_guess(nlp, parameters, problem)
            # the planar model's φ at the nodes is −θ of the reference's x–z angle
            mid = rod.s[:-1] + rod.h / 2
            z[3:] = -np.interp(nodes, mid, rod.theta)
            return z

        monkeypatch.setattr(attempts, "initial_guess", near_reference)
        monkeypatch.setattr(contact_rounds, "initial_guess", near_reference)
    return solver.solve()


# ρ = 1000 is left out: its contacts are touches (the reference's point contacts, curvature near
# 0 there, clearance 1.8e-6 L beside them), and the fixed mesh converges to it only slowly:
# 7.3e-3 L at 32 nodes, 3.7e-3 L at 48 (a second node beside each touch also presses).
# ρ = 3000: the lowest equilibrium (curl right, E = −56.145 J; the symmetric one is −19.437 J).
CASES = [(2000.0, "symmetric"), (3000.0, "right")]


@pytest.mark.parametrize("rho,which", CASES)
def test_fixed_mesh_converges_to_the_floor_reference(rho, which, monkeypatch):
    rod, ref = reference(rho, which)
    assert ref.residual < 1e-10 and ref.clearance > 0
    lift_off = np.unique(ref.lift_off.round(12))
    errors, energies = [], []
    for order in (32, 48):
        res = solve_on_mesh(rho, rod, lift_off, order, monkeypatch)
        err = np.max(np.linalg.norm(res.points[:, [0, 2]] - ref.at(res.s), axis=1))
        errors.append(err)
        energies.append(abs(res.energy["total"] - ref.energy))
        print(rho, which, order, res.status, res.stable, err, energies[-1])
    assert res.status == "ok", res.message
    # the contact stretches begin and end at the reference's lift-off points (element ends)
    ends = np.unique([[c.s_start, c.s_end] for c in res.contact_loads])
    far = [np.min(np.abs(lift_off - e)) for e in ends]
    assert len(ends) == len(lift_off) and max(far) < 1e-9, (ends, lift_off)
    assert errors[1] < 1e-4 and errors[1] < errors[0] / 3, errors
    assert energies[1] < 1e-2 and energies[1] < energies[0], energies
