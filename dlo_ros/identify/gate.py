"""Does the fitted shape explain the points?  The goodness-of-fit gate of a fit, and why it fails.

A fit that converged is not yet a good fit: the points of a cable 1.3× the scene's length, of a
helix no cable forms, or in millimetres still give a converged estimate, far from the truth, with a
small σ.  The gate compares the reduced χ² (Σ (r/σ)² over the residual rows / degrees of freedom,
``FitResult``) with

    threshold = max(χ²₀.₉₉₉(dof) / dof, MODEL_ERROR_FLOOR)

the 0.999 quantile of the χ² distribution (a correct model with the stated noise exceeds it once in
a thousand fits) with a floor of 4 for model error (discretisation, the chord error of the sampled
centreline, a σ stated a little low: an rms residual up to twice the stated σ passes).  When it
fails only because of a few points far beyond the robust loss's threshold (at most OUTLIER_FRACTION
of them, and the remaining points fit as truncated Gaussian noise: reduced χ² ≤ INNER_MAX), the fit
passes: Huber's loss has down-weighted them.  Otherwise the fit is a ``misfit`` and
:func:`evaluate_gate` names the likely cause from the points and the scene alone: wrong units (the
cloud spans ~1000× the cable), far from the grips (a wrong scene or frame), longer than the cable
(its arc length, estimated from the cloud, exceeds the scene's length), or too many outliers.

:func:`precheck` finds the first two before any equilibrium is solved (a cloud 1000× too big made
the fit stop with "no step decreased the cost" and no hint).  msg_docs/fitting.md, "When the fit
does not fit".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from scipy.sparse.csgraph import minimum_spanning_tree, shortest_path
from scipy.special import chdtri

from ..model.problem import Problem
from .observations import Observation, ObservationSet

#: the quantile of the χ² distribution of the gate
QUANTILE = 0.999
#: the smallest threshold of the reduced χ²: an rms residual up to 2× the stated σ is model error
MODEL_ERROR_FLOOR = 4.0
#: at most this fraction of the points may lie beyond the robust loss (Huber, 2.5 σ) and be
#: forgiven (Gaussian noise alone puts exp(-2.5²/2) = 4.4 % of the points there: the point-to-curve
#: residual has two components)
OUTLIER_FRACTION = 0.20
#: the largest reduced χ² of the points within the robust loss's threshold for the rest to be
#: outliers (Gaussian noise truncated at 2.5 σ gives 0.86: (2 − 2.5² e^(−3.125) / (1 − e^(−3.125)))
#: / 2)
INNER_MAX = 1.5
#: points beyond the robust loss are outliers only if at most this share of their nearest
#: neighbours are beyond it too (:func:`clustering`), and NEIGHBOURS are looked at
CLUSTERED = 0.6
NEIGHBOURS = 6
#: a cloud whose extent is this many times the cable's length (or 1/this) has the wrong units
UNIT_RATIO = 100.0
#: a cloud whose arc length exceeds the scene's length by this factor is of a longer cable
LENGTH_RATIO = 1.08
#: the arc-length estimate measures the polyline through every STRIDE-th centroid of its path
STRIDE = 3
#: the most voxel centroids the arc-length estimate connects (its distance matrix is this squared)
MAX_NODES = 1500


@dataclass(frozen=True)
class Gate:
    """The gate's verdict on a fit's residuals.

    The gate's verdict: ``passed``; the reduced χ² and its threshold; ``cause`` the one-line
    reason when it failed; ``note`` what passed with a remark (outliers down-weighted);
    ``noise_ratio2`` the reduced χ² of the points the fit explains (all, or all but the forgiven
    outliers): (actual noise / stated σ)².
    """

    passed: bool
    chi2_reduced: float
    threshold: float
    cause: str = ""
    note: str = ""
    noise_ratio2: float = float("nan")


def threshold(dof: int) -> float:
    """Return the bound on the reduced χ² for ``dof`` degrees of freedom (see the module)."""
    dof = max(int(dof), 1)
    # chdtri(k, 1 - q): the chi-square quantile q (scipy.stats.chi2.ppf, without importing stats)
    return max(float(chdtri(dof, 1.0 - QUANTILE)) / dof, MODEL_ERROR_FLOOR)


def precheck(problem: Problem, data: ObservationSet) -> str:
    """Say why points cannot be of this scene's string, whatever its stiffness.

    Why these points cannot be of this scene's string whatever its stiffness ('' when they may
    be): wrong units or far from the grips (:func:`geometric_cause`).
    """
    for obs in data.observations:
        cause = geometric_cause(problem, obs, lengths=False)
        if cause:
            return cause
    return ""


def geometric_cause(problem: Problem, obs: Observation, lengths: bool = True) -> str:
    """Return the cause the points of one observation show by themselves, or ''.

    The cause that the points of ``obs`` show by themselves, or ''.  A point on the string is
    within its length L of every grip (the chord is at most the arc), and the cloud spans at most
    about L.
    """
    length = problem.string.length
    pts = obs.points
    extent = float(np.linalg.norm(np.ptp(pts, axis=0)))
    name = f"observation {obs.name!r}"
    if extent > UNIT_RATIO * length:
        return (
            f"wrong units? {name}: the points span {extent:.4g} m, "
            f"{extent / length:.0f}× the string's length "
            f"{length:g} m (points are in metres: millimetres would be 1000×)"
        )
    if len(pts) >= 10 and extent * UNIT_RATIO < length and extent < 0.1 * obs.sigma * UNIT_RATIO:
        return (
            f"wrong units? {name}: the points span only {extent:.3g} m, "
            f"1/{length / max(extent, 1e-12):.0f} of the string's "
            f"length {length:g} m"
        )
    poses = problem.with_grip_poses(obs.poses).grips
    for grip in poses:
        reach = max(grip.s, length - grip.s)  # arc length from the grip to the farther end
        dist = np.linalg.norm(pts - grip.pose.position, axis=1)
        if np.median(dist) > 1.05 * reach + 3.0 * obs.sigma:
            return (
                f"far from the grips: {name}: the points lie a median "
                f"{np.median(dist):.4g} m from grip {grip.name!r}, which holds the string "
                f"{reach:.4g} m from its farther end (wrong scene, "
                "frame or grip poses?)"
            )
    if lengths:
        arc = arc_length(pts, obs.sigma, length)
        if arc > LENGTH_RATIO * length:
            return (
                f"wrong length? {name}: the points follow a curve about {arc:.3g} m long, "
                "the scene's string is "
                f"{length:g} m (string.length)"
            )
    return ""


def arc_length(points: np.ndarray, sigma: float, length: float) -> float:
    """Estimate the length [m] of the curve the points lie along.

    An estimate of the length [m] of the curve the points lie along (a lower bound up to about
    one voxel): the points are averaged in cubic voxels of side max(5σ, L/50) (so noise no longer
    zig-zags), voxels of one point are dropped when most hold several (isolated outliers), and the
    longest path of the minimum spanning tree of the centroids is measured (its diameter, two
    Dijkstra passes).
    """
    side = max(5.0 * sigma, length / 50.0)
    while True:
        keys = np.floor((points - points.min(axis=0)) / side).astype(np.int64)
        _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        if len(counts) <= MAX_NODES:
            break
        side *= 1.5
    inverse = inverse.reshape(-1)
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, inverse, points)
    centroids = sums / counts[:, None]
    if np.median(counts) >= 3:
        centroids = centroids[counts >= 2]
    if len(centroids) < 2:
        return 0.0
    dist = np.linalg.norm(centroids[:, None, :] - centroids[None, :, :], axis=2)
    tree = minimum_spanning_tree(dist)
    first = shortest_path(tree, directed=False, indices=0)
    far = int(np.argmax(np.where(np.isfinite(first), first, -1.0)))
    second, previous = shortest_path(tree, directed=False, indices=far, return_predecessors=True)
    node, path = int(np.argmax(np.where(np.isfinite(second), second, -1.0))), []
    while node >= 0:
        path.append(node)
        node = int(previous[node])
    # every STRIDE-th centroid of the path: the voxels a curve crosses at a corner zig-zag it
    keep = path[::STRIDE] if (len(path) - 1) % STRIDE == 0 else path[::STRIDE] + [path[-1]]
    return float(np.sum(np.linalg.norm(np.diff(centroids[keep], axis=0), axis=1)))


def longest_arc(problem: Problem, data: ObservationSet) -> float:
    """Return the longest :func:`arc_length` of the observations' clouds [m]."""
    return max(arc_length(o.points, o.sigma, problem.string.length) for o in data.observations)


def clustering(data: ObservationSet, u: list[np.ndarray], huber: float) -> float:
    """Measure how much the points beyond the loss's threshold cluster together.

    The mean fraction of the NEIGHBOURS nearest points (in space) of each point beyond ``huber``
    σ that are beyond it too: about the fraction of such points or less for scattered outliers,
    near 1 for a systematic misfit (whole stretches of the cloud off the fitted shape).
    """
    shares = []
    for obs, x in zip(data.observations, u):
        outside = x > huber
        if not outside.any() or len(x) <= NEIGHBOURS:
            continue
        _, idx = cKDTree(obs.points).query(obs.points[outside], k=NEIGHBOURS + 1)
        shares.append(outside[idx[:, 1:]].mean(axis=1))
    return float(np.mean(np.concatenate(shares))) if shares else 0.0


def evaluate_gate(
    problem: Problem,
    data: ObservationSet,
    chi2_total: float,
    dof: int,
    distances: list[np.ndarray],
    huber: float,
) -> Gate:
    """Judge whether a fit's residuals are explained by the stated noise.

    The gate on a fit's residuals: ``chi2_total`` = Σ (r/σ)² over all rows, ``dof`` its degrees
    of freedom, ``distances`` each observation's |r| per point [m] (module docstring).
    """
    bound = threshold(dof)
    reduced = chi2_total / max(dof, 1)
    if reduced <= bound:
        return Gate(True, reduced, bound, noise_ratio2=reduced)
    u = [d / o.sigma for d, o in zip(distances, data.observations)]
    points = sum(len(x) for x in u)
    outside = sum(int(np.sum(x > huber)) for x in u)
    fraction = outside / max(points, 1)
    inner = chi2_total - sum(float(np.sum(x[x > huber] ** 2)) for x in u)
    inner_reduced = inner / max(dof - 2 * outside, 1)
    # the points within the robust loss's threshold fit as Gaussian noise would (truncated at huber
    # σ)
    inner_fits = dof > 2 * outside and inner_reduced <= INNER_MAX
    if inner_fits and fraction <= OUTLIER_FRACTION:
        note = (
            f"{outside} of {points} points lie beyond {huber:g} σ: outliers, down-weighted by "
            "the robust loss"
        )
        return Gate(True, reduced, bound, note=note, noise_ratio2=inner_reduced)
    causes = (geometric_cause(problem, obs, lengths=False) for obs in data.observations)
    cause = next((c for c in causes if c), "")
    if not cause and inner_fits and fraction <= 0.5 and clustering(data, u, huber) <= CLUSTERED:
        cause = (
            f"outliers: {outside} of {points} points ({100 * fraction:.0f} %) lie beyond "
            f"{huber:g} σ of the fitted shape, more than the robust loss forgives "
            f"({100 * OUTLIER_FRACTION:.0f} %)"
        )
    causes = (geometric_cause(problem, obs) for obs in data.observations)
    cause = (
        cause
        or next((c for c in causes if c), "")
        or (
            "the fitted shape does not explain the points (a shape the scene's string cannot "
            "take: "
            "wrong scene, grip poses, length or model, or σ stated too small; the points follow "
            "at "
            f"least about {longest_arc(problem, data):.3g} m of "
            f"curve, the string is {problem.string.length:g} m)"
        )
    )
    rms = np.sqrt(np.mean(np.concatenate(distances) ** 2))
    sigma = min(o.sigma for o in data.observations)
    return Gate(
        False,
        reduced,
        bound,
        f"misfit: reduced chi2 {reduced:.4g} > {bound:.3g} (rms "
        "residual "
        f"{rms * 1e3:.3g} mm, sigma {sigma * 1e3:.3g} mm): {cause}",
    )
