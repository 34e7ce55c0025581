"""Whole pipeline: analytic mu^c of the built-ins, stage skipping, global mu^c
below the listed mu, and float against exact arithmetic on real models."""
import math

import numpy as np
import pytest

from hpcwedge.pipeline import run_scene
from hpcwedge.scene import parse_scene


def scene(model, mu=(0.65,), dim=2, run=None, **compute):
    return parse_scene({"name": "t", "dim": dim, "model": model, "friction": {"mu": list(mu)},
                        "compute": compute, "run": run or {}})


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


# ------------------------------------------------------------------------ 3D
PLUG3D_MU = (0.55, 0.60, 0.65, 0.70, 1.00)


@pytest.fixture(scope="module")
def plug3d_run():
    return run_scene(scene({"kind": "plug3d"}, mu=PLUG3D_MU, dim=3))


def test_plug3d_pattern_counts_monotone_in_mu(plug3d_run):
    """plug3d (m = 10): more feasible patterns at larger mu, each pattern found at
    mu also found at every larger mu, per-pattern mu^c <= mu, global mu^c = tan 10°."""
    res = plug3d_run
    counts = [run.n_patterns for run in res.runs]
    assert counts == [6, 11, 31, 36, 131]
    sets = [{tuple(p["contact"]) for p in run.patterns} for run in res.runs]
    assert all(a <= b for a, b in zip(sets, sets[1:]))
    for run in res.runs:
        keys = [sum(1 << i for i in p["contact"]) for p in run.patterns]
        assert keys == sorted(keys)                              # canonical order: pattern bits
        for p in run.patterns:
            assert p["undecided"] is False
            assert res.mu_c * (1 - 1e-12) <= p["mu_c"] <= run.mu * (1 + 1e-6)
    want = math.tan(math.radians(10.0))
    assert res.mu_c_status == "found" and abs(res.mu_c - want) <= 1e-9 * want
    assert res.stats["mu_c_unpolished"] == 0 and res.stats["patterns_undecided"] == 0
    bnb = res.stats["bnb"]
    assert bnb["partitions"] == 5 * 1024 and bnb["solves"] < 5 * 1024
    assert res.runs[0].rays is None and res.runs[0].cones is None


def test_symmetry_changes_no_answer(plug3d_run):
    """plug3d with run.symmetry = false: the same patterns and the same mu^c (to
    1e-9: there each pattern's own computation; with the symmetry the value of its
    orbit's representative), in more SOCPs and more mu^c computations."""
    off = run_scene(scene({"kind": "plug3d"}, mu=(0.65, 1.0), dim=3, run={"symmetry": False}))
    assert plug3d_run.stats["symmetry"]["order"] == 10 and "symmetry" not in off.stats
    on = {r.mu: r for r in plug3d_run.runs}
    for run in off.runs:
        got = {tuple(p["contact"]): p["mu_c"] for p in on[run.mu].patterns}
        want = {tuple(p["contact"]): p["mu_c"] for p in run.patterns}
        assert list(got) == list(want)
        assert all(abs(got[k] - want[k]) <= 1e-9 * want[k] for k in got)
    assert abs(off.mu_c - plug3d_run.mu_c) <= 1e-12
    per_mu = off.stats["bnb"]["solves"] / 2
    assert plug3d_run.stats["bnb"]["solves"] / 5 < per_mu
    assert plug3d_run.stats["mu_c_polished"] < off.stats["mu_c_polished"]


def test_truss_3d_without_tangents_equals_plug3d(plug3d_run):
    """The plug as a `truss` scene without tangents (t1 chosen from the normal):
    patterns and mu^c do not depend on the tangent frame."""
    from hpcwedge.models import plug3d
    mdl = plug3d()
    model = {"kind": "truss", "nodes": mdl.coords.tolist(), "bars": mdl.cells["line"].tolist(), "EA": 1.0}
    contact = {"nodes": mdl.contact_nodes.tolist(), "normals": mdl.normals.tolist()}
    sc = parse_scene({"name": "t", "dim": 3, "model": model, "contact": contact,
                      "friction": {"mu": [0.65]}})
    res = run_scene(sc)
    ref = {r.mu: r for r in plug3d_run.runs}
    for run in res.runs:
        got = {tuple(p["contact"]): p["mu_c"] for p in run.patterns}
        want = {tuple(p["contact"]): p["mu_c"] for p in ref[run.mu].patterns}
        assert got.keys() == want.keys()
        for k in got:
            assert abs(got[k] - want[k]) <= 1e-9 * want[k]
    assert abs(res.mu_c - plug3d_run.mu_c) <= 1e-12


def test_truss_3d_with_tangents_and_supports():
    """A supported 3D truss (a square pyramid on four contact nodes of a V-shaped
    seat, three non-contact nodes held): tangents given or not, same answers."""
    nodes = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0], [0, 0, 1.5], [0, 0, 3.0], [1, 0, 3.0]]
    bars = [[0, 1], [1, 2], [2, 3], [3, 0], [0, 2], [1, 3], [0, 4], [1, 4], [2, 4], [3, 4],
            [4, 5], [0, 5], [2, 5], [5, 6], [4, 6], [1, 6], [2, 6]]
    s = math.sin(math.radians(20.0))
    c = math.cos(math.radians(20.0))
    normals = [[c, 0, s], [-c, 0, s], [-c, 0, s], [c, 0, s]]
    tangents = [[0, 1, 0], [0, 1, 0], [0, 1, 0], [0, 1, 0]]
    base = {"kind": "truss", "nodes": nodes, "bars": bars, "EA": 1.0,
            "supports": [[4, 0], [4, 1], [4, 2], [5, 0], [5, 1], [5, 2], [6, 0], [6, 1], [6, 2]]}
    sc = parse_scene({"name": "t", "dim": 3, "model": base,
                      "contact": {"nodes": [0, 1, 2, 3], "normals": normals, "tangents": tangents},
                      "friction": {"mu": [0.5, 2.0]}})
    res = run_scene(sc)
    assert res.problem.N.shape[1] == 0                            # supported: no rigid modes
    assert [r.n_patterns for r in res.runs][0] <= res.runs[1].n_patterns
    for run in res.runs:
        for p in run.patterns:
            assert p["mu_c"] <= run.mu * (1 + 1e-6)
    sc2 = parse_scene({"name": "t", "dim": 3, "model": base,
                       "contact": {"nodes": [0, 1, 2, 3], "normals": normals},
                       "friction": {"mu": [0.5, 2.0]}})
    res2 = run_scene(sc2)
    assert [r.n_patterns for r in res2.runs] == [r.n_patterns for r in res.runs]
    assert (res.mu_c is None and res2.mu_c is None) or abs(res.mu_c - res2.mu_c) <= 1e-9 * res.mu_c


def test_3d_stages_and_global_mu_c():
    K3 = {"kind": "stiffness", "K": [[3.0, 0.4, 0.2], [0.4, 2.0, 0.3], [0.2, 0.3, 1.5]]}
    want = 4.784010530585897
    # listed mu below mu^c: no pattern there, the global value all the same
    r = run_scene(scene(K3, mu=(4.0,), dim=3))
    assert r.runs[0].n_patterns == 0 and r.stages == ["enumerate", "mu_c"]
    assert r.mu_c_status == "found" and abs(r.mu_c - want) <= 1e-9 * want
    # enumerate = false: only the global value
    r = run_scene(scene(K3, mu=(5.0,), dim=3, enumerate=False, mu_c="global"))
    assert r.runs[0].patterns is None and r.stages == ["mu_c"] and abs(r.mu_c - want) <= 1e-9 * want
    # mu_c = "global": patterns listed without their own mu^c
    r = run_scene(scene(K3, mu=(5.0,), dim=3, mu_c="global"))
    assert r.runs[0].patterns == [{"contact": [0], "mu_c": None, "undecided": False}]
    assert abs(r.mu_c - want) <= 1e-9 * want
    r = run_scene(scene(K3, mu=(5.0,), dim=3, mu_c="none"))
    assert r.mu_c is None and r.stages == ["enumerate"] and r.runs[0].n_patterns == 1
    r = run_scene(scene(K3, mu=(4.0,), dim=3, mu_max=4.5))
    assert r.mu_c is None and r.mu_c_status == "none_up_to_mu_max"
    r = run_scene(scene({"kind": "stiffness", "K": [[2.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]}, mu=(5.0,), dim=3))
    assert r.mu_c is None and r.mu_c_status == "none_at_any_mu" and r.runs[0].n_patterns == 0
    r = run_scene(scene(K3, mu=(5.0,), dim=3, mu_c_method="bisection", mu_c_tol=1e-4))
    assert want <= r.mu_c <= want * (1 + 2e-4)


@pytest.mark.parametrize("symmetry", [True, False])
def test_plug3d_global_mu_c_below_every_listed_mu(symmetry):
    """plug3d 2 x 4 at mu = 0.1 < tan 10°: no pattern, the global branch and bound
    (over orbit representatives with the symmetry) gives tan 10° to 1e-9."""
    r = run_scene(scene({"kind": "plug3d", "ring": 4}, mu=(0.1,), dim=3, run={"symmetry": symmetry}))
    want = math.tan(math.radians(10.0))
    assert r.runs[0].n_patterns == 0 and r.mu_c_status == "found"
    assert abs(r.mu_c - want) <= 1e-9 * want
    assert r.stats.get("symmetry", {}).get("order", 1) == (8 if symmetry else 1)
