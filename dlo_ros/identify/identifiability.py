"""What the data can determine: the null space of the Gauss–Newton normal matrix A = Jᵀ W J / σ².

θ are log-parameters, so A's eigenvectors compare relative changes.  An eigenvalue below
``tolerance · max eigenvalue`` spans a direction the residuals do not see.  A linear combination
cᵀθ is determined iff c is orthogonal to that null space: θ_k alone (c = e_k) gives an absolute
value, θ_a − θ_b (c = e_a − e_b) the ratio a/b.  From shapes alone the equilibrium depends on D/Rf,
Rt/Rf and Re/Rf only (scaling every material by one factor scales the energy, not its minimiser),
so (1, …, 1) is in the null space of every shape-only fit that frees Rf with the others; a grip
force, a grip torque or the total weight removes it (each scales with the materials while the shape
does not).  A parameter that enters no solved model (Rt of a planar shape, which no clamp twists)
has a zero column.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: an eigenvalue of A below this times the largest spans an undetermined direction
RANK_TOLERANCE = 1e-10
#: |V0ᵀ c| / |c| below this: the combination c is determined.  The null space of a nearly
#: degenerate A is
#: known only approximately (a weak direction's eigenvector mixes with its neighbours), so a
#: combination with a 1 % component along it still counts as orthogonal to it
ORTHOGONAL = 1e-2

WHY = {
    "Rt": (
        "no observation twists the string: Rt changes none of the predicted shapes (a shape held "
        "by two "
        "clamps turned relative to each other about the tangent is needed)"
    ),
    "Re": (
        "no observation stretches the string measurably: Re changes none of the predicted shapes"
    ),
    "D": "the weight changes none of the predicted shapes",
    "Rf": "Rf changes none of the predicted shapes",
}


NEITHER = (
    "neither its value nor its ratio to another fitted parameter is determined by these data (an "
    "undetermined direction of the normal matrix involves it)"
)


@dataclass
class Identifiability:
    """Which directions of θ the data determine, and why the others are not.

    names: the fitted θ; eigenvalues (ascending) and eigenvectors (columns) of A; null: the
    columns spanning the undetermined directions; why[name] for each parameter not determined
    alone.
    """

    names: tuple[str, ...]
    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    null: np.ndarray
    why: dict[str, str]

    @property
    def determined(self) -> tuple[str, ...]:
        return tuple(n for n in self.names if n not in self.why)

    @property
    def condition(self) -> float:
        """Return the condition number of A on the determined directions.

        Largest over smallest eigenvalue of A on the determined directions (1 for one
        direction).
        """
        kept = self.eigenvalues[self.eigenvalues > 0][-self.rank :] if self.rank else np.ones(1)
        return float(kept.max() / kept.min())

    @property
    def directions(self) -> tuple[np.ndarray, np.ndarray]:
        """(eigenvectors as columns, eigenvalues) of A on the determined directions."""
        kept = self.null.shape[1]
        return self.eigenvectors[:, kept:], self.eigenvalues[kept:]

    @property
    def rank(self) -> int:
        return len(self.names) - self.null.shape[1]

    def determines(self, c: np.ndarray) -> bool:
        """Whether the combination cᵀθ is determined by the data."""
        c = np.asarray(c, dtype=float)
        return bool(np.linalg.norm(self.null.T @ c) <= ORTHOGONAL * np.linalg.norm(c))

    def ratio_determined(self, a: str, b: str) -> bool:
        c = np.zeros(len(self.names))
        c[self.names.index(a)], c[self.names.index(b)] = 1.0, -1.0
        return self.determines(c)


def analyse(
    names: tuple[str, ...], normal: np.ndarray, tolerance: float = RANK_TOLERANCE
) -> Identifiability:
    """Analyse which of ``names`` the normal matrix ``normal`` determines (see the module)."""
    eig, vec = np.linalg.eigh(0.5 * (normal + normal.T))
    top = max(float(eig.max(initial=0.0)), 0.0)
    null = vec[:, eig <= tolerance * top] if top > 0 else np.eye(len(names))
    why: dict[str, str] = {}
    columns = np.sqrt(np.maximum(np.diag(normal), 0.0))
    for k, name in enumerate(names):
        e = np.zeros(len(names))
        e[k] = 1.0
        if np.linalg.norm(null.T @ e) <= ORTHOGONAL:
            continue
        if top <= 0 or columns[k] <= np.sqrt(
            tolerance * top
        ):  # a zero column: enters no solved model
            why[name] = WHY[name.split("[")[0]]
            continue
        partners = [
            o
            for o in names
            if o != name and np.linalg.norm(null.T @ (e - _unit(names, o))) <= ORTHOGONAL
        ]
        if partners:
            ratios = ", ".join(
                f"{a}/{b}" for a, b in (sorted((name, o), key=_ratio_order) for o in partners)
            )
            why[name] = (
                f"the data determine only ratios ({ratios}): from shapes alone the equilibrium "
                f"depends on "
                "D/Rf, Rt/Rf and Re/Rf; an absolute value needs a measured grip force (force), a "
                "measured "
                "grip torque (torque) or the known total mass (total_mass)"
            )
        else:
            why[name] = NEITHER
    return Identifiability(tuple(names), eig, vec, null, why)


def _ratio_order(name: str) -> int:
    """Ratios are written with Rf (then Rt, Re) in the denominator: D/Rf, Rt/Rf, Re/Rf."""
    return {"D": 0, "Re": 1, "Rt": 2, "Rf": 3}[name.split("[")[0]]


def _unit(names: tuple[str, ...], name: str) -> np.ndarray:
    e = np.zeros(len(names))
    e[names.index(name)] = 1.0
    return e
