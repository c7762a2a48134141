"""Closed-form clamped--clamped planar inextensible elastica (Euler buckling, post-buckled).

This module is the *exact* reference solution used as ground truth for the numerical
(Ritz) solvers.  It is pure numpy/scipy and has no ROS dependency.

Problem
-------
An inextensible, unshearable planar rod of length ``L`` and bending stiffness ``Rf``
(``Rf = E I``) is clamped at both ends with the tangent along ``+x``::

    r(0) = (0, 0),   r(L) = (a, 0),   theta(0) = theta(L) = 0,   0 < a < L,

where ``s`` is arc length, ``r(s) = (x(s), y(s))``, ``r'(s) = (cos theta, sin theta)``
and ``kappa = theta'`` is the curvature.  The bending energy is
``U = int_0^L 1/2 Rf kappa^2 ds``.  The internal force (exerted by the part beyond ``s``
on the part before ``s``) is constant, ``n = (-P, 0)`` for the symmetric mode, i.e. a
compressive axial force ``P > 0``.  Moment balance ``m' + r' x n = 0`` with
``m = Rf theta'`` gives the elastica (pendulum) equation::

    Rf theta'' + P sin(theta) = 0.                                            (1)

Solution (first symmetric mode, buckled towards +y)
---------------------------------------------------
With ``lambda^2 = P / Rf``, the first integral of (1) is
``theta'^2 = 4 lambda^2 (k^2 - sin^2(theta/2))``, ``k = sin(theta_max/2)``.  Substituting
``sin(theta/2) = k sin(phi)`` gives ``phi' = lambda dn``, i.e. ``phi = am(u, k)`` with
``u = lambda s`` (the phase is fixed by ``theta(0) = 0``, ``theta'(0) > 0``)::

    sin(theta/2) = k sn(u),   cos(theta/2) = dn(u),   theta' = 2 k lambda cn(u).  (2)

The first symmetric clamped--clamped mode spans one full period of ``sn`` (four
quarter-waves): ``lambda L = 4 K(k)``, hence::

    lambda = 4K/L,   P = Rf (4K/L)^2,   M = |Rf theta'(0)| = 2 k Rf (4K/L).   (3)

Integrating ``cos theta = 2 dn^2 - 1`` and ``sin theta = 2 k sn dn = -2 k d(cn)/du``::

    x(s) = (2 E(am(u), k) - u) / lambda,                                    (4)
    y(s) = 2 k (1 - cn(u)) / lambda          (>= 0),                         (5)

where ``E(phi, k)`` is the incomplete elliptic integral of the second kind
(``E(am u, k)`` is Jacobi's epsilon function, evaluated via Carlson's ``R_F``/``R_D``).  At
``s = L`` (``u = 4K``, ``E(am 4K) = 4E``) this yields the chord condition::

    a / L = 2 E(k) / K(k) - 1,                                               (6)

which is strictly decreasing in ``k`` (``a/L -> 1`` as ``k -> 0``; ``a = 0``, the
ends touching, at ``k ~= 0.9089``), and fixes ``k``.  The mid-span deflection is
``y(L/2) = 4k/lambda = k L / K``.  Using ``k^2 cn^2 = dn^2 - (1 - k^2)`` the bending
energy is::

    U = 2 Rf k^2 lambda int_0^{4K} cn^2 du = 32 Rf K (E - (1 - k^2) K) / L.    (7)

(Small-amplitude check: ``U -> 4 pi^2 Rf k^2 / L``, ``a/L -> 1 - k^2``, ``P -> 4 pi^2 Rf / L^2``.)

Note: scipy's elliptic functions take the *parameter* ``m = k^2``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq
from scipy.special import ellipe, ellipj, ellipk, elliprd, elliprf

__all__ = ["ClampedElastica", "clamped_clamped_elastica"]


@dataclass(frozen=True)
class ClampedElastica:
    """Exact first symmetric buckled mode of the clamped--clamped planar elastica.

    All ``s`` arguments are arc lengths in ``[0, L]`` (scalar or array); outside that
    interval the formulas continue the periodic elastica and are not physical.
    """

    length: float  #: L [m]
    bend_stiffness: float  #: Rf [N m^2]
    chord: float  #: a [m], 0 < a < L, distance between the ends
    k: float  #: elliptic modulus k = sin(theta_max / 2), from a/L = 2E(k)/K(k) - 1
    K: float  #: complete elliptic integral of the first kind K(k)

    # ------------------------------------------------------------------ helpers
    @property
    def m(self) -> float:
        """Elliptic parameter ``m = k^2`` (scipy convention)."""
        return self.k * self.k

    @property
    def E(self) -> float:
        """Return the complete elliptic integral of the second kind at modulus k."""
        return float(ellipe(self.m))

    @property
    def wavenumber(self) -> float:
        """``lambda = 4 K(k) / L = sqrt(P / Rf)`` [1/m]."""
        return 4.0 * self.K / self.length

    def _phase(self, s: ArrayLike) -> NDArray[np.float64]:
        return self.wavenumber * np.asarray(s, dtype=float)

    def _epsilon(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """Jacobi epsilon function ``E(am(u, k), k) = int_0^u dn^2(t) dt``.

        Reduced to ``u = 2K n + r`` with ``|r| <= K`` (``E(am u) = 2 n E + E(am r)``) and
        evaluated with Carlson's symmetric integrals (DLMF 19.25.9)::

            E(am r) = sn R_F(cn^2, dn^2, 1) - (m/3) sn^3 R_D(cn^2, dn^2, 1).

        ``scipy.special.ellipeinc`` is deliberately not used: it has isolated wrong
        values (scipy issue #19498, still present in scipy 1.15; e.g. a jump of ~0.38 at
        ``phi ~= 1.18724``, ``m ~= 0.0987``), which would corrupt ``x(s)``.
        """
        n = np.round(u / (2.0 * self.K))
        r = u - 2.0 * self.K * n
        sn, cn, _, _ = ellipj(r, self.m)
        cn2 = cn * cn
        dn2 = 1.0 - self.m * sn * sn
        return (
            2.0 * n * self.E
            + sn * elliprf(cn2, dn2, 1.0)
            - (self.m / 3.0) * sn**3 * elliprd(cn2, dn2, 1.0)
        )

    # --------------------------------------------------------------- kinematics
    def positions(self, s: ArrayLike) -> NDArray[np.float64]:
        """Centre-line points ``(x, y)`` at arc lengths ``s``; shape ``np.shape(s) + (2,)``.

        ``x = (2 E(am u) - u)/lambda``, ``y = 2k (1 - cn u)/lambda``, ``u = lambda s``
        (eqs. 4, 5): ``x`` runs along the chord from 0 to ``a``, ``y >= 0``.
        """
        u = self._phase(s)
        lam = self.wavenumber
        _, cn, _, _ = ellipj(u, self.m)
        x = (2.0 * self._epsilon(u) - u) / lam
        y = 2.0 * self.k * (1.0 - cn) / lam
        return np.stack([x, y], axis=-1)

    def tangent_angle(self, s: ArrayLike) -> NDArray[np.float64]:
        """Angle of ``dr/ds`` from the x axis [rad]: ``theta = 2 arcsin(k sn(lambda s))``.

        Zero at both ends, positive on ``(0, L/2)``, negative on ``(L/2, L)``.
        """
        sn, _, _, _ = ellipj(self._phase(s), self.m)
        return 2.0 * np.arcsin(np.clip(self.k * sn, -1.0, 1.0))

    def curvature(self, s: ArrayLike) -> NDArray[np.float64]:
        """Curvature ``kappa = dtheta/ds = 2 k lambda cn(lambda s)`` [1/m]."""
        _, cn, _, _ = ellipj(self._phase(s), self.m)
        return 2.0 * self.k * self.wavenumber * cn

    # ------------------------------------------------------------------ statics
    @property
    def end_force(self) -> float:
        """Compressive axial end force magnitude ``P = Rf (4K/L)^2`` [N]."""
        return self.bend_stiffness * self.wavenumber**2

    @property
    def end_moment(self) -> float:
        """Clamp moment magnitude ``M = |Rf theta'(0)| = 2 k Rf (4K/L)`` [N m].

        The same magnitude acts at both clamps (``theta'(L) = theta'(0)``).
        """
        return 2.0 * self.k * self.bend_stiffness * self.wavenumber

    @property
    def energy(self) -> float:
        """Bending energy ``U = int 1/2 Rf kappa^2 ds = 32 Rf K (E - (1-k^2) K) / L`` [J]."""
        K = self.K
        return 32.0 * self.bend_stiffness * K * (self.E - (1.0 - self.m) * K) / self.length

    @property
    def max_deflection(self) -> float:
        """Mid-span deflection ``y(L/2) = k L / K`` [m]."""
        return self.k * self.length / self.K


def _chord_ratio(m: float) -> float:
    """``a/L = 2 E(m)/K(m) - 1`` as a function of the parameter ``m = k^2``."""
    return 2.0 * float(ellipe(m)) / float(ellipk(m)) - 1.0


def clamped_clamped_elastica(
    length: float, bend_stiffness: float, chord: float
) -> ClampedElastica:
    """Exact first symmetric buckled shape of a rod clamped horizontally at (0,0) and (a,0).

    Solves the chord condition ``a/L = 2E(k)/K(k) - 1`` (eq. 6) for ``m = k^2`` with
    Brent's method on ``[0, 0.95]`` (the ratio is strictly decreasing there, from 1 to
    about -0.27; ``a = 0`` corresponds to ``k ~= 0.9089``).

    Raises ``ValueError`` unless ``length > 0``, ``bend_stiffness > 0`` and ``0 < chord < length``.
    """
    L = float(length)
    Rf = float(bend_stiffness)
    a = float(chord)
    if not (np.isfinite(L) and L > 0.0):
        raise ValueError(f"length must be positive, got {length!r}")
    if not (np.isfinite(Rf) and Rf > 0.0):
        raise ValueError(f"bend_stiffness must be positive, got {bend_stiffness!r}")
    if not (0.0 < a < L):
        raise ValueError(
            f"chord must satisfy 0 < chord < length, got chord={chord!r}, length={length!r}"
        )

    ratio = a / L
    m = brentq(
        lambda mm: _chord_ratio(mm) - ratio,
        0.0,
        0.95,
        xtol=1e-300,
        rtol=4.0 * np.finfo(float).eps,
        maxiter=500,
    )
    m = float(m)
    return ClampedElastica(
        length=L, bend_stiffness=Rf, chord=a, k=float(np.sqrt(m)), K=float(ellipk(m))
    )
