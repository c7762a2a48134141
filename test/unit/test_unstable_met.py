"""The unstable equilibrium a solve meets and leaves is kept with its answer (#39: "record, per pose,
the stable equilibrium and the nearest unstable one the solver meets").

Greenhill's twisted rod past its threshold: the straight rod is an equilibrium whose energy is the
closed form Rt Φ² / 2L, unstable beyond Φ_c; a cold solve from the straight guess meets it first and
leaves it for the buckled, stable shape.  Below Φ_c the straight rod is the stable answer and nothing
unstable is met.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_greenhill_auto import PHI_C, RT, L, deflection, greenhill

from dlo_ros.solver import make_solver
from dlo_ros.solver.options import SolverOptions


@pytest.mark.parametrize("model", ["auto", "full"])
def test_past_the_threshold_the_straight_saddle_is_kept_beside_the_buckle(model):
    phi = 1.3 * PHI_C
    r = make_solver(greenhill(phi), SolverOptions(model=model), compile="off", checks="sync").solve()
    met = r.unstable_met
    assert r.ok and r.stable and deflection(r) > 0.01
    assert met is not None and met.stable is False and met.min_eigenvalue < 0
    assert deflection(met) < 1e-9  # the straight rod
    straight = RT * phi**2 / (2 * L)
    assert met.energy["total"] == pytest.approx(straight, rel=1e-9)
    assert r.energy["total"] < met.energy["total"]
    as_json = json.loads(json.dumps(r.to_dict(), allow_nan=False))["unstable_met"]
    assert as_json["energy_total"] == pytest.approx(straight, rel=1e-9)
    np.testing.assert_allclose(as_json["points"], met.points, atol=1e-12)


def test_below_the_threshold_nothing_unstable_is_met():
    r = make_solver(greenhill(0.8 * PHI_C), SolverOptions(), compile="off", checks="sync").solve()
    assert r.ok and r.stable and deflection(r) < 1e-9 and r.unstable_met is None
    assert r.to_dict()["unstable_met"] is None


def test_a_data_set_stores_the_saddle_each_sample_met(tmp_path):
    """`dlo dataset` rows carry it: two cold samples of the twisted rod, each beside its straight
    saddle (energy and shape as above); load_arrays gives its centreline as (N, K, 3)."""
    from dlo_ros.dataset import build_dataset, load_arrays, plan_from_dict
    from dlo_ros.scene import Scene

    phi = 1.3 * PHI_C
    scene = Scene("greenhill", greenhill(phi), SolverOptions())
    plan = plan_from_dict({"samples": 2, "seed": 0, "start": "cold", "grips": {"b": {"position_box": {
        "min": [L, 0.0, 0.0], "max": [L, 0.0, 0.0]}}}})
    assert build_dataset(scene, plan, tmp_path / "out", workers=1, progress=False).complete
    a = load_arrays(tmp_path / "out")
    assert list(a["status"]) == ["ok", "ok"] and all(a["stable"])
    np.testing.assert_allclose(a["unstable_energy_total"], RT * phi**2 / (2 * L), rtol=1e-9)
    assert np.all(a["unstable_min_eigenvalue"] < 0)
    assert a["unstable_points"].shape == a["points"].shape
    np.testing.assert_allclose(np.hypot(a["unstable_points"][..., 1], a["unstable_points"][..., 2]), 0, atol=1e-9)
