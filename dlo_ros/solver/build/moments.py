"""Dead point moments on a director model: the exact equilibrium equations and their Jacobian.

A point moment M at s_k enters the NLP as the pseudo-potential W_M(v_k; q_ref)
(``model/director.py``),
whose gradient is M·δθ only where q_ref is the load's own rotation N(v_k) = v_k/|v_k|.  The exact
equations are therefore the KKT residual evaluated with every centre set to N(v_k) at the current z
(``ProblemParameters.centre_moments``), and their Jacobian is the Hessian of the Lagrangian there
plus, at each load's node values, the small non-symmetric block C(v_k, M) of
``StringNLP.moment_stiffness_fn``. ``ExactMomentKKT`` evaluates both with the NLP's own KKT
function (compiled when it is), so Newton (``newton.newton`` with ``kkt_fn``) solves the exact
equations.
"""

from __future__ import annotations

import numpy as np

from ...model.problem import Problem
from .functions import NlpFunctions
from .nlp import StringNLP
from .parameters import ProblemParameters
from .structure import breakpoint_node


class ExactMomentKKT:
    """The KKT function of the exact equations under the problem's point moments.

    (z, p, λ) → [∇f, g, ∂g/∂z, K, energies] of the exact equations under ``problem``'s point
    moments: ``NlpFunctions.kkt`` with the moments' centres at z, K with the blocks C added (module
    docstring).
    """

    def __init__(
        self, nlp: StringNLP, fns: NlpFunctions, parameters: ProblemParameters, problem: Problem
    ):
        self.fns, self.parameters, self.problem = fns, parameters, problem
        m, lay = nlp.model, nlp.model.layout
        self.stiffness = nlp.moment_stiffness_fn()
        self.loads = []  # (z slice of the load's node values, p slice of its moment)
        for i, ld in enumerate(problem.loads):
            if np.any(np.asarray(ld.moment) != 0.0):
                first = lay.rotation.start + lay.width * breakpoint_node(m.mesh, ld.s)
                self.loads.append(
                    (slice(first, first + lay.width), nlp.params[f"load:{i}:moment"])
                )

    def __call__(self, z: np.ndarray, p: np.ndarray, lam: np.ndarray) -> list[np.ndarray]:
        p = p.copy()
        self.parameters.centre_moments(self.problem, z, p)
        grad, g, jac, hess, energies = self.fns.kkt(z, p, lam)
        for node, moment in self.loads:
            hess[node, node] += np.asarray(self.stiffness(z[node], p[moment]))
        return [grad, g, jac, hess, energies]
