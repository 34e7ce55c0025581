"""Whole pipeline: analytic mu^c of the built-ins, stage skipping, global mu^c
below the listed mu, and float against exact arithmetic on real models."""
import math

import numpy as np
import pytest

from hpcwedge.pipeline import run_scene
from hpcwedge.scene import parse_scene


def scene(model, mu=(0.65,), dim=2, **compute):
    return parse_scene({"name": "t", "dim": dim, "model": model, "friction": {"mu": list(mu)},
                        "compute": compute})


@pytest.mark.parametrize("rows", [2, 3, 4, 5, 6, 7, 8])
@pytest.mark.parametrize("taper", [3.0, 10.0, 25.0])
def test_plug2d_global_mu_c_is_tan_taper(rows, taper):
    want = math.tan(math.radians(taper))
    res = run_scene(scene({"kind": "plug2d", "rows": rows, "taper_deg": taper},
                          mu=(1.0,), enumerate=False, mu_c="global"))
    assert res.mu_c_status == "found"
    assert abs(res.mu_c - want) <= 1e-9 * want


@pytest.mark.parametrize("theta,eps", [(30.0, 0.0), (30.0, 0.1), (15.0, 0.05), (45.0, 0.3), (5.0, 0.0)])
def test_vgroove_formula(theta, eps):
    th = math.radians(theta)
    want = math.tan(th) + eps / (0.5 * math.sin(2 * th))
    res = run_scene(scene({"kind": "vgroove_bar", "theta_deg": theta, "eps": eps}, mu=(want * 1.1,)))
    assert abs(res.mu_c - want) <= 1e-9 * want
    assert res.runs[0].n_cones >= 1 and res.runs[0].cones[0]["mu_c"] is not None


def test_counts_of_the_seed_table():
    """SPEC §7: plug2d at mu = 0.65 has 8, 44, 244, 1148 wedged rays for m = 4..10."""
    for rows, n in [(2, 8), (3, 44), (4, 244), (5, 1148)]:
        res = run_scene(scene({"kind": "plug2d", "rows": rows}, mu_c="none"))
        assert res.runs[0].n_wedged_rays == n and res.runs[0].n_trivial_rays == 4


@pytest.mark.parametrize("rows", [2, 3])
def test_exact_mode_equals_float_on_plug(rows):
    f = run_scene(scene({"kind": "plug2d", "rows": rows}))
    e = run_scene(scene({"kind": "plug2d", "rows": rows}, exact=True))
    rf, re = f.runs[0], e.runs[0]
    assert (rf.n_wedged_rays, rf.n_trivial_rays, rf.n_cones) == (re.n_wedged_rays, re.n_trivial_rays, re.n_cones)
    assert np.array_equal(rf.ray_zero, re.ray_zero)
    assert np.allclose(rf.rays, re.rays, atol=1e-9)
    assert abs(f.mu_c - e.mu_c) <= 1e-12


def test_stages_run_only_when_asked():
    K = {"kind": "stiffness", "K": [[2.0, 0.5], [0.5, 1.0]]}
    r = run_scene(scene(K, mu=(2.5,), enumerate="rays", mu_c="none"))
    assert r.stages == ["enumerate"] and r.runs[0].cones is None and r.mu_c is None
    assert r.timings["condense"] == 0 and r.timings["mu_c"] == 0
    r = run_scene(scene(K, mu=(2.5,), enumerate=False, mu_c="global"))
    assert r.stages == ["mu_c"] and r.runs[0].rays is None and abs(r.mu_c - 2.0) < 1e-12
    r = run_scene(scene({"kind": "plug2d", "rows": 2}, enumerate=False, mu_c="none"))
    assert r.stages == ["condense"]


def test_global_mu_c_when_listed_mu_is_below():
    K = {"kind": "stiffness", "K": [[2.0, 0.5], [0.5, 1.0]]}
    r = run_scene(scene(K, mu=(1.5,)))
    assert r.runs[0].n_wedged_rays == 0 and abs(r.mu_c - 2.0) <= 1e-12
    r = run_scene(scene(K, mu=(1.5,), mu_max=1.8))
    assert r.mu_c is None and r.mu_c_status == "none_up_to_mu_max"


def test_cone_zero_sets_cover_all_nodes():
    r = run_scene(scene({"kind": "plug2d", "rows": 4}))
    for cone in r.runs[0].cones:
        assert set(cone["zero_u"]) | set(cone["zero_r"]) == set(range(8))
        assert cone["mu_c"] >= r.mu_c * (1 - 1e-12)
