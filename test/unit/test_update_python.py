"""The Python around one warm update (#38) changes no answer.

* ``certainly_apart`` (its per-geometry plan, its arithmetic rearranged) decides as the algorithm it
  replaced, kept here as ``reference_apart``, and never says "apart" where ``candidate_pairs``
  finds a pair;
* ``DirectorModel.quad_tangents`` remembers the last z's: the same numbers as ``frame_columns``;
* ``quat_to_frame`` of a few quaternions in Python floats: the numpy path's numbers, bit for bit;
* ``ProblemParameters.place_slots`` reuses the last placement only for the same shape, slots kept,
  obstacles and radius: the parameter vector and placements as worked out afresh;
* ``ProblemParameters.pack`` of a director model: each grip's rows of p looked up once, its frame
  entries remembered per GripPose object (as the Euler angles are);
* ``quadrature._chebvander`` of a few points in Python floats: numpy's ``chebvander``, bit for bit,
  in its layout (and the matrix products after it); ``ElementMesh``'s matrices with the
  elements' columns as slices: the entries ``np.ix_`` wrote;
* ``ShapeResult.contact_loads`` worked out on first read: ``contacts.contact_loads`` of the
  state, through ``replace``, deep copies and pickling;
* streamed updates (the closed 3D path of test_director_stream.py, both models of
  bench/perf/update_python.py, hanging and on the table) give the same results, field by field,
  as a solver whose remembered values are dropped before every update.
"""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np
import pytest

import copy
import pickle

from numpy.polynomial import chebyshev as C

from dlo_ros.model import director as D
from dlo_ros.model import quadrature as Q
from dlo_ros.model.elements import ElementMesh
from dlo_ros.model import quaternion_frames as QF
from dlo_ros.model.problem import GripPose
from dlo_ros.scene import load_scene
from dlo_ros.solver.contact import obstacle_slots as OSL
from dlo_ros.solver.contact import self_contact as SC
from dlo_ros.solver.results.result import ShapeResult
from dlo_ros.solver.shape_solver import ShapeSolver

from test_director_stream import path
from test_self_contact import random_curve, small_loop

L = 1.0


def reference_apart(points: np.ndarray, geometry: SC.ContactGeometry) -> bool:
    """``certainly_apart`` as it was before #38's rewrite (the algorithm, step by step)."""
    n = len(points)
    h, reach = geometry.spacing, geometry.reach
    near = geometry.exclusion - 1e-12
    m = int(np.ceil(near / h))
    while m > 1 and (m - 1) * h >= near:
        m -= 1
    while m * h < near:
        m += 1
    big = max(m + 1, int(np.ceil(1.25 * reach / h)) + 1)
    if n < 3 or n > 401 or m >= n:
        return n < 2 or m >= n
    if geometry.held.size:
        grips = [
            np.flatnonzero(geometry.held == g)
            for g in np.unique(geometry.held[geometry.held >= 0])
        ]
        for i, gi in enumerate(grips):
            for gj in grips[i + 1 :]:
                if np.abs(gi[:, None] - gj[None, :]).min() < big:
                    return False
    steps = np.diff(points, axis=0)
    lengths = np.sqrt(np.einsum("ij,ij->i", steps, steps))
    if not lengths.min() > 0.1 * h:
        return False
    unit = steps / lengths[:, None]
    turns = np.arccos(np.clip(np.einsum("ij,ij->i", unit[:-1], unit[1:]), -1.0, 1.0))
    total = np.concatenate(([0.0], np.cumsum(turns)))

    def most_turning(segments: int) -> float:
        segments = min(segments, n - 1)
        return float(np.max(total[segments - 1 :] - total[: n - segments]))

    if not most_turning(big - 1) < np.pi / 2 - 1e-9:
        return False
    windows = np.concatenate(([0.0], np.cumsum(lengths)))
    shortest = float(np.min(windows[m:] - windows[: n - m]))
    if not np.cos(most_turning(m) / 2) * shortest > geometry.distance * (1 + 1e-9):
        return False

    def min_squared(pts: np.ndarray, band: np.ndarray) -> float:
        centred = pts - pts.mean(axis=0)
        sq = np.einsum("ij,ij->i", centred, centred)
        return float((sq[:, None] + sq[None, :] - 2.0 * (centred @ centred.T) + band).min())

    wide = big + 2 * 4
    if wide <= n - 1 and most_turning(wide - 1) < np.pi / 2 - 1e-9:
        idx = np.unique(np.append(np.arange(0, n, 4), n - 1))
        band = np.where(idx[None, :] - idx[:, None] >= wide - 4, 0.0, np.inf)
        longest = float(lengths.max())
        if min_squared(points[idx], band) > (reach + 4 * longest) ** 2 * (1 + 1e-9) + 1e-15:
            return True
    if big > n - 1:
        return True
    full = np.full((n, n), np.inf)
    full[np.triu_indices(n, big)] = 0.0
    return min_squared(points, full) > reach**2 * (1 + 1e-9) + 1e-15


def shapes(s: np.ndarray):
    """Arcs, small loops, gentle and folded random curves, a stream-like wobble of each."""
    for radius in (1.0, 0.4, 0.25, 0.16):
        yield np.stack([radius * np.sin(s / radius), radius * (1 - np.cos(s / radius)), 0 * s], 1)
    yield small_loop(s, 10 * (s[1] - s[0]))
    for seed in range(6):
        rng = np.random.default_rng(seed)
        gentle = sum(
            np.outer(np.sin(np.pi * k * s / L + rng.uniform(0, 6)), rng.normal(size=3)) / k**2
            for k in (1, 2)
        ) * 0.3 * L + np.outer(s, rng.normal(size=3))
        yield gentle
        yield gentle + 1e-3 * rng.normal(size=gentle.shape)
        for scale in (3.0, 1.0, 0.3):
            yield random_curve(seed, len(s)) * scale


@pytest.mark.parametrize("radius", [0.005, 0.0, 0.02])
@pytest.mark.parametrize("grips", [(), (0.0, L), (0.0, 0.03 * L), (0.2, 0.7)])
def test_certainly_apart_decides_as_before_and_is_exact(radius, grips):
    geometry = SC.contact_geometry(L, radius, grip_s=grips)
    answers = []
    for pts in shapes(geometry.s):
        apart = SC.certainly_apart(pts, geometry)
        assert apart == reference_apart(pts, geometry)
        assert not (apart and SC.candidate_pairs(pts, geometry))
        answers.append(apart)
    assert grips == (0.0, 0.03 * L) or any(answers)  # the shortcut is exercised
    for n in (1, 2, 3, 402):  # the sample counts it declines or answers at once
        pts = np.outer(np.linspace(0, L, n), [1.0, 0.0, 0.0])
        assert SC.certainly_apart(pts, geometry) == reference_apart(pts, geometry)


def test_quad_tangents_remembered_are_frame_columns():
    sc = load_scene("default_cable")
    solver = ShapeSolver(sc.problem, replace(sc.options, model="full", order=12), compile="off")
    assert solver.solve().ok
    model, z = solver.nlp.model, solver.snapshot().z
    fresh = np.array(D.frame_columns((model.B @ model.node_values(z)).T, np)[0])
    got = model.quad_tangents(z)
    assert np.array_equal(got, fresh) and not got.flags.writeable
    assert model.quad_tangents(z.copy()) is got  # the same z: remembered
    other = z.copy()
    other[3] += 1e-3
    moved = model.quad_tangents(other)
    assert np.array_equal(
        moved, np.array(D.frame_columns((model.B @ model.node_values(other)).T, np)[0])
    )
    assert np.array_equal(model.quad_tangents(z), fresh)


def test_few_quaternions_to_frames_bit_for_bit():
    rng = np.random.default_rng(3)
    for k in range(1, QF.FEW_QUATERNIONS + 1):
        q = rng.normal(size=(k, 4)) * rng.uniform(0.1, 3.0)
        # the numpy path: the same quaternions among more than FEW_QUATERNIONS
        many = D.quat_to_frame(np.concatenate([q] * (QF.FEW_QUATERNIONS + 1)))
        assert np.array_equal(D.quat_to_frame(q), many[:k])
    with np.errstate(invalid="ignore"):
        assert np.isnan(D.quat_to_frame(np.zeros((1, 4)))).all()  # numpy's answer, as before


def test_few_point_chebvander_bit_for_bit():
    rng = np.random.default_rng(5)
    with np.errstate(all="ignore"):
        for n in range(0, Q.FEW_POINTS + 3):
            for deg in (0, 1, 2, 19, 20, 48):
                x = rng.uniform(-1.0, 1.0, n)
                x[:3] = [-1.0, 1.0, np.nan][: min(n, 3)]
                want, got = C.chebvander(x, deg), Q._chebvander(x, deg)
                assert got.shape == want.shape and got.strides == want.strides
                assert np.array_equal(got, want, equal_nan=True), (n, deg)
                m = rng.normal(size=(deg + 1, 7))
                assert np.array_equal(got @ m, want @ m, equal_nan=True)


def reference_mesh_matrices(mesh: ElementMesh, s: np.ndarray):
    """``ElementMesh``'s interpolation, quad_interpolation and integration_matrix with np.ix_."""
    B, dB = np.zeros((s.size, mesh.count)), np.zeros((s.size, mesh.count))
    P, dP = np.zeros((s.size, mesh.quad_count)), np.zeros((s.size, mesh.quad_count))
    W = np.zeros((s.size, mesh.quad_count))
    which = mesh.element_of(s, "left")
    for e in np.unique(which):
        rows = np.flatnonzero(which == e)
        b, db = mesh.elements[e].matrices(s[rows] - mesh.breakpoints[e])
        cols = np.arange(mesh.first[e], mesh.first[e] + mesh.elements[e].count)
        B[np.ix_(rows, cols)], dB[np.ix_(rows, cols)] = b, db
        qcols = np.arange(mesh.quad_first[e], mesh.quad_first[e + 1])
        local = s[rows] - mesh.breakpoints[e]
        if mesh.quads is None:
            pb, pdb = mesh.elements[e].matrices(local)
        else:
            pb = mesh.quads[e].interpolation_matrix(local)
            pdb = mesh.quads[e].derivative_matrix(local)
        P[np.ix_(rows, qcols)], dP[np.ix_(rows, qcols)] = pb, pdb
    for e, el in enumerate(mesh.elements):
        lo, hi = mesh.breakpoints[e], mesh.breakpoints[e + 1]
        cols = np.arange(mesh.quad_first[e], mesh.quad_first[e + 1])
        full, part = s >= hi, (s > lo) & (s < hi)
        W[np.ix_(full, cols)] = el.weights if mesh.quads is None else mesh.quads[e].weights
        if np.any(part):
            W[np.ix_(part, cols)] = (
                el.integral(s[part] - lo)
                if mesh.quads is None
                else mesh.quads[e].integration_matrix(s[part] - lo)
            )
    return (B, dB), (P, dP), W


@pytest.mark.parametrize("order", [12, 24])
def test_mesh_matrices_with_slices_as_with_ix(order):
    sc = load_scene("default_cable")
    for opts in (replace(sc.options, model="full", order=order), slots_options(sc.options)):
        mesh = ShapeSolver(sc.problem, opts, compile="off").nlp.model.mesh
        rng = np.random.default_rng(order)
        length = float(mesh.breakpoints[-1])
        for n in (1, 3, 9, 40):
            s = np.sort(rng.uniform(0.0, length, n))
            s[0] = mesh.breakpoints[min(1, len(mesh.breakpoints) - 1)]  # a breakpoint
            (B, dB), (P, dP), W = reference_mesh_matrices(mesh, s)
            got_b, got_db = mesh.interpolation(s)
            got_p, got_dp = mesh.quad_interpolation(s)
            assert np.array_equal(got_b, B) and np.array_equal(got_db, dB)
            assert np.array_equal(got_p, P) and np.array_equal(got_dp, dP)
            assert np.array_equal(mesh.integration_matrix(s), W)


def test_contact_loads_worked_out_on_first_read():
    sc = load_scene("default_cable")
    problem = lowered(sc.problem)
    solver = ShapeSolver(problem, replace(sc.options, model="full", order=12), compile="off")
    assert solver.solve().ok
    grip = problem.grip("right").pose
    result = solver.solve({"right": GripPose(grip.position + [0.01, 0.0, 0.0], grip.orientation)})
    assert result.ok and result.ipopt_status.startswith("Newton")
    given = result.__dict__["_contact_loads_given"]
    assert not isinstance(given, list)  # deferred
    state = solver._state
    nlp = solver.nlp
    lam_si = state.lam_g / (nlp.row_scale * nlp.sigma)
    from dlo_ros.solver.results.contacts import contact_loads

    want = contact_loads(nlp, problem, state.z, state.p, lam_si)
    assert want and same(flat(pickle.loads(pickle.dumps(result)).contact_loads), flat(want))
    assert isinstance(pickle.loads(pickle.dumps(result)).__dict__["_contact_loads_given"], list)
    for other in (copy.deepcopy(result), replace(result), result):
        assert same(flat(other.contact_loads), flat(want))
    assert result.__dict__["_contact_loads_given"] is result.contact_loads  # read once
    assert ShapeResult("ok", "").contact_loads == []


def slots_options(options):
    """bench/perf/update_python.py's 'slots 12': the model auto streams default_cable on."""
    return replace(
        options,
        model="full",
        order=12,
        obstacle_slots=2,
        slotted_obstacles="flat",
        obstacle_points="nodes",
    )


def lowered(problem):
    down = np.array([0.0, 0.0, 0.32])
    return problem.with_grip_poses(
        {g.name: GripPose(g.pose.position - down, g.pose.orientation) for g in problem.grips}
    )


def test_slot_placement_reused_only_for_the_same_inputs():
    sc = load_scene("default_cable")
    problem = lowered(sc.problem)
    solver = ShapeSolver(problem, slots_options(sc.options), compile="off")
    assert solver.solve().ok
    parameters, start = solver.parameters, problem.grip("right").pose.position
    filled = 0
    for k in range(1, 120, 7):
        r = solver.solve({"right": GripPose(*path(k, start))})
        assert r.ok, r.message
        state = solver.snapshot()
        reused = parameters.pack(solver.problem, state.z, keep=state.p)
        placements = parameters.placements
        parameters._placed = None
        fresh = parameters.pack(solver.problem, state.z, keep=state.p)
        assert np.array_equal(reused, fresh)
        for a, b in zip(placements, parameters.placements):
            assert all(np.array_equal(getattr(a, f.name), getattr(b, f.name)) for f in fields(a))
        filled += int(sum(np.sum(p.on) for p in placements))
        # another shape, or no slots kept: worked out, not reused
        moved = state.z.copy()
        moved[0] += 1e-3
        parameters.pack(solver.problem, moved, keep=state.p)
        assert parameters._placed is not None and parameters._placed[0][0] == moved.tobytes()
    assert filled > 0  # on the table: slots were filled and placed


def flat(value) -> list:
    """Every number and string of a result, recursively (the solve time left out)."""
    out: list = []
    if hasattr(value, "__dataclass_fields__"):
        for f in fields(value):
            if "time" not in f.name:
                out += [f.name, *flat(getattr(value, f.name))]
    elif isinstance(value, dict):
        for key in sorted(value, key=str):
            out += [str(key), *flat(value[key])]
    elif isinstance(value, (list, tuple)):
        out += [len(value), *(x for item in value for x in flat(item))]
    elif isinstance(value, np.ndarray):
        out += [value.shape, *np.asarray(value, dtype=float).ravel().tolist()]
    else:
        out.append(value)
    return out


def same(a: list, b: list) -> bool:
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):
        if isinstance(x, float) and isinstance(y, float):
            if not (x == y or (np.isnan(x) and np.isnan(y)) or abs(x - y) <= 1e-12):
                return False
        elif x != y:
            return False
    return True


@pytest.mark.parametrize("model", ["full 12", "slots 12"])
@pytest.mark.parametrize("on_table", [False, True], ids=["hanging", "on_table"])
def test_streamed_results_as_without_remembered_values(model, on_table):
    sc = load_scene("default_cable")
    problem = lowered(sc.problem) if on_table else sc.problem
    options = (
        replace(sc.options, model="full", order=12)
        if model == "full 12"
        else slots_options(sc.options)
    )
    new, forgetful = (ShapeSolver(problem, options, compile="off") for _ in range(2))
    assert new.solve().ok and forgetful.solve().ok
    worked_out = []
    place = new.parameters._place_slots
    new.parameters._place_slots = lambda *args: worked_out.append(1) or place(*args)
    start = problem.grip("right").pose.position
    for k in range(1, 201):
        target = {"right": GripPose(*path(4 * k, start))}  # 200 updates, 2.5 times the step
        forgetful.nlp.model._tangents = None
        forgetful.parameters._placed = None
        forgetful.parameters._frame_cache.clear()
        forgetful.parameters._grip_layout.clear()
        a, b = new.solve(target), forgetful.solve(target)
        assert a.ok and b.ok, (k, a.message, b.message)
        assert same(flat(a), flat(b)), k
    if model == "slots 12":  # placed on the answer, and again at the next update's start
        assert 0 < len(worked_out) <= 200 + 8 * 20
