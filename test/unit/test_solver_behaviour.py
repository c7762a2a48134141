"""ShapeSolver's contract (no ROS): warm starts, queries, continuation, statuses, thread safety."""
from __future__ import annotations

import threading

import numpy as np

from dlo_ros.solver import ShapeSolver, SolverOptions
from dlo_ros.solver.update.newton import derivatives
from support.problems import clamped_pair

Q = [0.0, 0.0, 0.0, 1.0]


def solver():
    s = ShapeSolver(clamped_pair(right=(0.6, 0, 0), weight=0.5, twist=0.5), SolverOptions(model="full"), compile="off")
    assert s.solve().ok
    return s


def test_warm_update_takes_newton_steps_and_matches_a_cold_solve():
    s = solver()
    warm = s.solve({"right": ([0.61, 0.0, 0.01], Q)})
    assert warm.ok and warm.warm_started and warm.ipopt_status == "Newton" and warm.iterations <= 5
    cold = ShapeSolver(s.problem, s.options, compile="off").solve(warm=False)
    assert np.max(np.abs(warm.points - cold.points)) < 1e-8


def test_query_does_not_touch_the_warm_start():
    s = solver()
    before = s.solve({"right": ([0.62, 0.0, 0.0], Q)})
    query = s.solve({"right": ([0.3, 0.1, 0.2], Q)}, commit=False)
    assert query.ok and np.allclose(query.points[-1], [0.3, 0.1, 0.2], atol=1e-9)
    again = s.solve({"right": ([0.62, 0.0, 0.0], Q)})
    assert np.allclose(again.points, before.points, atol=1e-9)


def test_new_values_of_the_same_structure_reach_the_next_solve():
    """set_problem with the same structure keeps the NLP (parameters are cached between updates): a
    heavier, stiffer string and a moved obstacle must still give a fresh solver's shape."""
    from dataclasses import replace

    from dlo_ros.model import Obstacle, Profile

    table = Obstacle("halfspace", np.array([0.0, 0.0, -0.5, 0.0, 0.0, 1.0]), "table")
    s = ShapeSolver(clamped_pair(right=(0.85, 0, 0.3), weight=0.5, obstacles=(table,)), SolverOptions(model="full"),
                    compile="off")
    first = s.solve()
    heavier = replace(s.problem, string=replace(s.problem.string, weight_per_length=Profile.constant(2.0),
                                                bend_stiffness=Profile.constant(1.5)),
                      obstacles=(Obstacle("halfspace", np.array([0.0, 0.0, -0.1, 0.0, 0.0, 1.0]), "table"),))
    s.set_problem(heavier)
    warm = s.solve({"right": ([0.85, 0.0, 0.3], Q)})
    cold = ShapeSolver(heavier, s.options, compile="off").solve(warm=False)
    assert first.ok and warm.ok and cold.ok
    assert np.max(np.abs(warm.points - first.points)) > 1e-3  # the new values changed the shape
    mirrored = cold.points * np.array([1.0, -1.0, 1.0])  # the scene is symmetric about y = 0: either branch
    assert min(np.max(np.abs(warm.points - cold.points)), np.max(np.abs(warm.points - mirrored))) < 1e-8


def test_large_jump_converges():
    s = solver()
    r = s.solve({"right": ([0.15, 0.2, 0.3], Q)})
    assert r.ok, r.message
    assert np.allclose(r.points[-1], [0.15, 0.2, 0.3], atol=1e-9)


def test_statuses_for_bad_input_never_raise():
    s = solver()
    r = s.solve({"right": ([5.0, 0.0, 0.0], Q)})
    assert r.status == "unreachable" and "'left' and 'right'" in r.message
    r = s.solve({"right": ([np.nan, 0.0, 0.0], Q)})
    assert r.status == "invalid" and "grips.right.position" in r.message
    r = s.solve({"right": ([0.5, 0.0, 0.0], [0, 0, 0, 3])})
    assert r.status == "invalid" and "grips.right.orientation" in r.message
    r = s.solve({"elbow": ([0.5, 0.0, 0.0], Q)})
    assert r.status == "invalid" and "elbow" in r.message
    # nothing bad was committed: the next good target still warm-starts
    r = s.solve({"right": ([0.6, 0.0, 0.01], Q)})
    assert r.ok and r.warm_started


def test_concurrent_callers_are_serialised():
    """CasADi's IPOPT segfaults when one solver runs in two threads; the lock must serialise them."""
    s = solver()
    results, errors = [], []

    def worker(offset):
        try:
            for i in range(15):
                results.append(s.solve({"right": ([0.55 + 0.002 * i, offset, 0.0], Q)}).status)
        except Exception as exc:  # noqa: BLE001 - any exception fails the test below
            errors.append(exc)

    threads = [threading.Thread(target=worker, args=(o,)) for o in (0.0, 0.01, -0.01)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and results.count("ok") == 45


def test_paper_frame_with_the_chord_on_its_pole_solves_and_gives_finite_torques():
    """The paper's Euler frame has its singular axis (θ = 0) along z; a scene whose chord runs along z sits
    on it.  solve() must not raise there, and the clamp torques (from the internal moment when the
    multipliers cannot give them) must match the same scene solved in the director model.  At the pole the
    Euler model's equilibrium residual overstates its error (1.5 and 4.8 mm here, while the shapes agree to
    1e-4 m), so the tolerance is set aside and the shapes and torques are compared directly."""
    q = [0.0, np.sin(-np.pi / 4), 0.0, np.cos(-np.pi / 4)]  # tangent +x turned to +z
    for chord in (0.7, 0.5):
        problem = clamped_pair(right=(0.0, 0.0, chord), q_left=q, q_right=q)
        paper = ShapeSolver(problem, SolverOptions(frame="paper", model="full", rotation="euler", order=16,
                                                     error_tolerance=1.0),
                            compile="off").solve(warm=False)
        rotated = ShapeSolver(problem, SolverOptions(model="full", order=16), compile="off").solve(warm=False)
        assert paper.ok and rotated.ok
        # without gravity the buckle's plane (a rotation about the chord) is neutral: compare invariants
        radius = [np.linalg.norm(r.points[:, :2], axis=1) for r in (paper, rotated)]
        assert np.max(np.abs(radius[0] - radius[1])) < 1e-4
        for name in ("left", "right"):
            t_paper, t_rot = paper.grips[name].torque, rotated.grips[name].torque
            assert np.all(np.isfinite(t_paper))
            assert abs(np.linalg.norm(t_paper) - np.linalg.norm(t_rot)) < 2e-2 * np.linalg.norm(t_rot), (name, t_paper, t_rot)
            assert abs(t_paper[2]) < 1e-6 * np.linalg.norm(t_rot)  # planar buckle: no torque about the chord


def test_contact_free_derivatives_are_the_full_ones_without_obstacle_rows():
    """The Newton path evaluates a function without the obstacle rows' Jacobian and Hessian while none is
    active: with λ = 0 on those rows it must equal the full KKT function everywhere else."""
    from dlo_ros.model import Obstacle

    table = Obstacle("halfspace", np.array([0.0, 0.0, -0.5, 0.0, 0.0, 1.0]), "table")
    s = ShapeSolver(clamped_pair(right=(0.8, 0.1, 0.2), weight=0.5, obstacles=(table,)), SolverOptions(model="full"),
                    compile="off")
    nlp = s.nlp
    assert nlp.kkt_free_fn is not None and nlp.n_free_rows < nlp.lbg.size
    rng = np.random.default_rng(4)
    z = rng.uniform(-0.5, 0.5, s.model.layout.size)
    p = s.pack_parameters(s.problem, z)
    lam = rng.uniform(-1, 1, nlp.lbg.size)
    lam[nlp.n_free_rows:] = 0.0
    no_contact = np.arange(nlp.lbg.size) < nlp.n_free_rows  # every row but the obstacle rows active
    free, full = derivatives(nlp, s.functions, z, p, lam, no_contact), s.functions.kkt(z, p, lam)
    for k in (0, 1, 3, 4):  # ∇f, g (every row, obstacle values included), ∇²L, energies
        np.testing.assert_allclose(free[k], full[k], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(free[2][: nlp.n_free_rows], full[2][: nlp.n_free_rows], rtol=1e-12, atol=1e-12)
    assert np.all(free[2][nlp.n_free_rows:] == 0.0) and np.any(full[2][nlp.n_free_rows:] != 0.0)


def test_resting_on_a_post_warm_updates_balance_forces_and_match_cold_solves():
    """A heavy string resting on a sphere, its right end moved in small steps: the warm updates (Newton
    steps with the contact rows active) equal cold solves, and forces balance: the grips' forces plus
    the contact force carry the weight D·L (a conservation check independent of the discretisation)."""
    from dlo_ros.model import Obstacle

    weight = 0.8
    post = Obstacle("sphere", np.array([0.25, 0.0, -0.1, 0.08]), "post")  # 5 cm above the free sag
    problem = clamped_pair(left=(0.0, 0.0, 0.3), right=(0.5, 0.0, 0.3), weight=weight, obstacles=(post,))
    s = ShapeSolver(problem, SolverOptions(model="full", order=16), compile="off")
    first = s.solve()
    assert first.ok and np.linalg.norm(first.contact_forces[0]) > 0.05 * weight  # it rests on the post
    newton = 0
    for k in range(1, 6):
        right = (0.5 + 0.01 * k, 0.0, 0.3 - 0.005 * k)
        warm = s.solve({"right": (right, Q)})
        assert warm.ok and warm.warm_started, warm.message
        newton += warm.ipopt_status == "Newton"
        total = sum(w.force for w in warm.grips.values()) + warm.contact_forces[0]
        np.testing.assert_allclose(total, [0.0, 0.0, weight * 1.0], atol=1e-6 * weight)
    cold = ShapeSolver(s.problem, s.options, compile="off").solve(warm=False)
    mirrored = cold.points * np.array([1.0, -1.0, 1.0])  # it rests against one side of the post: either side
    assert cold.ok and min(np.max(np.abs(warm.points - cold.points)), np.max(np.abs(warm.points - mirrored))) < 1e-7
    assert newton >= 3  # the contact stays active: these were Newton updates, not IPOPT fallbacks


def test_fused_and_step_by_step_newton_updates_agree():
    """With interpreted derivatives a warm update takes its first Newton steps in one CasADi call
    (``newton_fn``, LAPACK LU inside); with compiled ones it steps one evaluation at a time (LAPACK gesv
    in numpy).  From the same start to the same targets both must land on the same equilibrium with the
    same multipliers, and match a cold IPOPT solve of the last target in the same NLP."""
    from dlo_ros.model.problem import GripPose

    problem = clamped_pair(right=(0.7, 0.1, 0.05), weight=0.8)
    fused = ShapeSolver(problem, SolverOptions(model="full", order=10), compile="off")
    stepwise = ShapeSolver(problem, SolverOptions(model="full", order=10), compile="off")
    stepwise.fused_newton = False
    assert fused.solve().ok and stepwise.solve().ok
    right = problem.grip("right").pose
    for k in range(1, 8):
        pose = {"right": GripPose(right.position + np.array([-0.01 * k, 0.005 * k, 0.01 * k]), right.orientation)}
        a, b = fused.solve(pose), stepwise.solve(pose)
        assert a.ok and b.ok and a.ipopt_status == b.ipopt_status == "Newton"
        assert a.iterations == b.iterations
        np.testing.assert_allclose(a.points, b.points, atol=1e-12)
        np.testing.assert_allclose(fused.snapshot().lam_g, stepwise.snapshot().lam_g, rtol=1e-8, atol=1e-10)
    cold = fused.solve(pose, warm=False, commit=False)  # same NLP (same frame), IPOPT from the start guess
    assert cold.ok and cold.ipopt_status != "Newton"
    np.testing.assert_allclose(a.points, cold.points, atol=1e-8)
    assert abs(a.energy["total"] - cold.energy["total"]) < 1e-9 * max(1.0, abs(cold.energy["total"]))


def test_a_failing_fused_newton_call_falls_back_to_ipopt():
    """CasADi's LAPACK LU raises on a singular Newton matrix (where gesv would report it): the update must
    then fall back to warm-started IPOPT, not fail."""
    from dlo_ros.model.problem import GripPose

    problem = clamped_pair(right=(0.7, 0.1, 0.05), weight=0.8)
    solver = ShapeSolver(problem, SolverOptions(model="full", order=10), compile="off")
    assert solver.solve().ok and solver.fused_newton

    def singular(*args):
        raise RuntimeError("LapackLu::prepare: 0-th row (zero-based) is exactly zero")

    solver.functions.newton_step = singular
    right = problem.grip("right").pose
    r = solver.solve({"right": GripPose(right.position + np.array([-0.01, 0.0, 0.01]), right.orientation)})
    assert r.ok and r.ipopt_status != "Newton", r.ipopt_status
