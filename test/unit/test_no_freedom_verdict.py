"""An ok result always carries a stability verdict (#37: one random scene was ok with stable null).

When the active constraints leave the shape no freedom, the reduced Hessian is empty: there is no
admissible perturbation, so nothing can lower the energy and the equilibrium is stable (trivially,
Lagrange-Dirichlet).  The result then says stable true, min_eigenvalue null, and why.  Such scenes
are rare (a mesh with as many independent constraint rows as unknowns); the empty null space is
injected here at ``results.stability.stability_verdict``'s return, the seam it comes through.
"""

from __future__ import annotations

import numpy as np
from support.problems import clamped_pair

from dlo_ros.solver.options import SolverOptions
from dlo_ros.solver.results import outputs
from dlo_ros.solver.results.stability import NO_FREEDOM
from dlo_ros.solver.shape_solver import ShapeSolver


def test_no_freedom_is_stable_and_says_why(monkeypatch):
    real = outputs.stability_verdict

    def no_freedom(nlp, fns, state):
        real(nlp, fns, state)  # it also fills the derivatives the result needs
        return True, None

    monkeypatch.setattr(outputs, "stability_verdict", no_freedom)
    r = ShapeSolver(clamped_pair(), SolverOptions(model="full"), compile="off").solve()
    assert r.ok and r.stable is True and r.min_eigenvalue is None
    assert NO_FREEDOM in r.message
    assert r.to_dict()["stable"] is True and np.isfinite(r.equilibrium_residual_m)
