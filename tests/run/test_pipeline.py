"""Whole pipeline: analytic mu^c of the built-ins, stage skipping, global mu^c
below the listed mu, and float against exact arithmetic on real models."""
import math
import re

import numpy as np
import pytest

from hpcwedge.results.record import NOT_COMPUTED, Cone, Pattern, Run
from hpcwedge.run.pipeline import condense, mu_c_keys, orbit_key, run_scene
from hpcwedge.scene.parse import parse_scene


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
    assert res.runs[0].n_cones >= 1 and res.runs[0].cones[0].mu_c is not None


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
        assert set(cone.zero_u) | set(cone.zero_r) == set(range(8))
        assert cone.mu_c >= r.mu_c * (1 - 1e-12)


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
    sets = [{tuple(p.contact) for p in run.patterns} for run in res.runs]
    assert all(a <= b for a, b in zip(sets, sets[1:]))
    for run in res.runs:
        keys = [sum(1 << i for i in p.contact) for p in run.patterns]
        assert keys == sorted(keys)                              # canonical order: pattern bits
        for p in run.patterns:
            assert p.undecided is False
            assert res.mu_c * (1 - 1e-12) <= p.mu_c <= run.mu * (1 + 1e-6)
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
        got = {tuple(p.contact): p.mu_c for p in on[run.mu].patterns}
        want = {tuple(p.contact): p.mu_c for p in run.patterns}
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
        got = {tuple(p.contact): p.mu_c for p in run.patterns}
        want = {tuple(p.contact): p.mu_c for p in ref[run.mu].patterns}
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
            assert p.mu_c <= run.mu * (1 + 1e-6)
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
    assert r.runs[0].patterns == [Pattern(contact=[0], mu_c=None, undecided=False)]
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


# ------------------------------------------------------------------ scale-free numerics (issue 11)

def _cli_result(tmp_path, name: str, text: str, files: dict | None = None):
    """(exit status, stderr, show --json or None) of `hpcwedge run` on a scene text, in a
    subprocess (a crash of the old code must not take the test process with it)."""
    import json
    import subprocess
    import sys
    for fname, arrays in (files or {}).items():
        np.savez(tmp_path / fname, **arrays)
    (tmp_path / f"{name}.toml").write_text(text)
    out = tmp_path / f"{name}.h5"
    p = subprocess.run([sys.executable, "-m", "hpcwedge", "run", str(tmp_path / f"{name}.toml"), "-o", str(out),
                        "-q"], capture_output=True, text=True, timeout=300)
    if p.returncode:
        return p.returncode, p.stderr, None
    s = subprocess.run([sys.executable, "-m", "hpcwedge", "show", str(out), "--json"], capture_output=True,
                       text=True, timeout=120)
    return 0, p.stderr, json.loads(s.stdout)


BLOCK = 'name = "b"\ndim = 2\n[model]\nkind = "block2d"\nrows = 3\nE = {E}\n[friction]\nmu = [0.65]\n' \
        '[compute]\nenumerate = true\nmu_c = "cones"\n'


def _rays(d):
    X = np.array(d["runs"][0]["rays"])
    n = X.shape[1] // 2
    return X[:, :n], X[:, n:]


@pytest.mark.parametrize("E", [1e308, 1e200, 1e-200])
def test_block2d_extreme_modulus_same_answers(tmp_path, E):
    """block2d with E = 1e308, 1e200, 1e-200: the moduli are rescaled before assembly,
    so the answers are those of E = 1 (mu^c to 1e-12, counts, cones), r equal to 1e-12,
    u = u(E = 1) / E to 1e-9 relative (before: a PETSc SEGV or a traceback)."""
    rc, _, ref = _cli_result(tmp_path, "ref", BLOCK.format(E=1.0))
    assert rc == 0
    rc, err, got = _cli_result(tmp_path, "big", BLOCK.format(E=E))
    assert rc == 0, err
    assert abs(got["mu_c"] - ref["mu_c"]) <= 1e-12 * ref["mu_c"]
    assert got["runs"][0]["n_wedged_rays"] == ref["runs"][0]["n_wedged_rays"] == 244
    assert [c["zero_u"] for c in got["runs"][0]["cones"]] == [c["zero_u"] for c in ref["runs"][0]["cones"]]
    (u0, r0), (u, r) = _rays(ref), _rays(got)
    assert np.abs(r - r0).max() <= 1e-12
    big = np.abs(u0) > 1e-9 * np.abs(u0).max()
    assert np.abs(u[big] * E / u0[big] - 1).max() <= 1e-9


def test_raw_K_scaled_by_powers_of_two_and_1e_minus_300(tmp_path):
    """A valid raw K (plug2d m = 8) times 2^-1000 gives the unscaled run's answers bit
    for bit, u times 2^1000 exactly; times 1e-300 the same mu^c to 1e-12 (before: exit 0
    with mu^c = 2e-24)."""
    from hpcwedge.contact.build import contact_problem
    prob = contact_problem(scene({"kind": "plug2d", "rows": 4}))
    text = 'name = "k"\ndim = 2\n[model]\nkind = "stiffness"\nfile = "{f}"\n[friction]\nmu = [0.65]\n' \
           '[compute]\nenumerate = true\nmu_c = "cones"\n'
    runs = {}
    for name, K in (("one", prob.K), ("pow2", np.ldexp(prob.K, -1000)), ("tiny", prob.K * 1e-300)):
        rc, err, runs[name] = _cli_result(tmp_path, name, text.format(f=f"{name}.npz"),
                                          {f"{name}.npz": {"K": K, "null_space": prob.N}})
        assert rc == 0, err
    one, pow2, tiny = runs["one"], runs["pow2"], runs["tiny"]
    assert pow2["mu_c"] == one["mu_c"] and pow2["runs"][0]["cones"] == one["runs"][0]["cones"]
    (u0, r0), (u, r) = _rays(one), _rays(pow2)
    assert np.array_equal(r, r0) and np.array_equal(u, np.ldexp(u0, 1000))
    assert abs(tiny["mu_c"] - one["mu_c"]) <= 1e-12 * one["mu_c"]
    assert tiny["runs"][0]["n_wedged_rays"] == one["runs"][0]["n_wedged_rays"]


def test_stiffness_too_small_for_the_displacements_is_one_line(tmp_path):
    """E = 5e-324 (the least subnormal): the rays' u would overflow a double: exit 2,
    one line naming model, no result."""
    rc, err, got = _cli_result(tmp_path, "sub", BLOCK.format(E=5e-324))
    assert rc == 2 and got is None
    assert err.startswith("hpcwedge: error: model:") and "overflow" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "sub.h5").exists()


def test_unit_moduli_are_not_rescaled():
    """Ordinary scenes keep their bits: the built-in plugs and unit moduli get exponent 0."""
    from hpcwedge.contact.build import stiffness_exponent
    for model in ({"kind": "plug2d"}, {"kind": "block2d", "E": 1.0}, {"kind": "vgroove_bar", "eps": 0.1}):
        assert stiffness_exponent(scene(model)) == 0
    assert stiffness_exponent(scene({"kind": "block2d", "E": 2.0 ** 40})) == 40
    assert stiffness_exponent(scene({"kind": "vgroove_bar", "EA": 3e-7, "eps": 1e-9})) == -22


@pytest.mark.parametrize("eps", [1.0, 10.0, 3e5, 2.0 ** -30])
def test_moduli_left_at_their_defaults_are_scaled_with_the_given_ones(eps):
    """vgroove_bar with eps given and EA at its default 1: mu^c = tan(theta) + eps / (k
    sin 2 theta) (SPEC §6; k = EA / L = 1/2 here) = 1 + 2 eps at theta = 45 deg, whatever
    the exponent eps gives the scene (before: the default EA was left unscaled, eps = 10
    gave 3.5 instead of 21)."""
    from hpcwedge.contact.build import stiffness_exponent
    sc = scene({"kind": "vgroove_bar", "theta_deg": 45.0, "eps": eps}, mu=[2.0 + 2 * eps], mu_max=1e6)
    want = 1.0 + 2 * eps
    assert (stiffness_exponent(sc) != 0) == (eps > 1.5)
    got = run_scene(sc).mu_c
    assert abs(got - want) <= 1e-9 * want


@pytest.mark.parametrize("mu_max", [1e5, 3e5, 1e6])
def test_global_mu_c_with_every_listed_mu_below_it_and_a_large_mu_max(mu_max):
    """plug2d with mu = 0.1 < mu^c: the global search starts at mu_max, the LPs balanced
    there; the value is still tan(taper) to 1e-9, certified (before: 2.5e-5 to 2.8e-4
    below it from mu_max = 3e5 on, an unpolished value under a note claiming 1e-7)."""
    res = run_scene(scene({"kind": "plug2d", "rows": 2}, mu=[0.1], mu_max=mu_max, mu_c="cones"))
    want = math.tan(math.radians(10.0))
    assert abs(res.mu_c - want) <= 1e-9 * want
    assert res.stats["mu_c_unpolished"] == 0 and not res.stats["numerics"]["flagged"]


@pytest.mark.parametrize("mu_max,want", [(0.1, None), (0.2, math.tan(math.radians(10.0)))])
def test_global_mu_c_does_not_depend_on_the_listed_mu_or_on_enumerate(mu_max, want):
    """SPEC §2: the global mu^c is the scene's, searched up to mu_max. plug2d (mu^c = tan 10
    deg) with a listed mu above or below it, enumerating or not: the same answer (before:
    with mu_max = 0.1 the listed mu = 0.65's cones gave 0.1763 "found", the three other
    runs null)."""
    got = set()
    for mu in (0.65, 0.05):
        for enumerate_ in (True, False):
            res = run_scene(scene({"kind": "plug2d", "rows": 2}, mu=[mu], mu_max=mu_max, enumerate=enumerate_))
            got.add((None if res.mu_c is None else round(res.mu_c, 12), res.mu_c_status))
    assert got == {(None if want is None else round(want, 12), "none_up_to_mu_max" if want is None else "found")}


# ------------------------------------------------------------------------ stages and records

def test_condense_stage_record():
    raw = condense(scene({"kind": "stiffness", "K": [[2.0, 0.5], [0.5, 1.0]]}))
    assert raw.model is None and raw.seconds == 0.0 and raw.problem.m == 1
    built = condense(scene({"kind": "plug2d", "rows": 2}))
    assert built.model is not None and built.problem.m == 4 and built.seconds > 0


def test_a_large_models_condensation_is_announced_and_a_small_ones_is_not(monkeypatch):
    """From NOTE_CONDENSE_MIN_DOFS DOFs on, one line when the condensation starts (DOFs,
    contact nodes) and one when it ends (seconds); below, none (the same condensation)."""
    import io

    from hpcwedge.progress import Progress
    from hpcwedge.run import pipeline
    body = scene({"kind": "block2d", "rows": 3, "cols": 2, "refine": 2})
    quiet = io.StringIO()
    small = pipeline.condense(body, Progress(stream=quiet))
    assert quiet.getvalue() == ""
    monkeypatch.setattr(pipeline, "NOTE_CONDENSE_MIN_DOFS", small.model.n_dofs)
    said = io.StringIO()
    large = pipeline.condense(body, Progress(stream=said))
    lines = said.getvalue().splitlines()
    assert lines[0] == f"[hpcwedge] condense: {small.model.n_dofs:,} DOFs onto {small.problem.m} contact nodes", lines
    assert re.fullmatch(r"\[hpcwedge\] condense: done \(\d+\.\d s\)", lines[1]) and len(lines) == 2, lines
    assert np.array_equal(large.problem.K, small.problem.K)


def test_stats_keys_of_a_patterns_run():
    r = run_scene(scene({"kind": "plug2d", "rows": 2}, enumerate="patterns"))
    assert list(r.stats) == ["dd", "lp_solves", "mu_c_polished", "mu_c_unpolished", "lp_undecided", "symmetry",
                             "patterns_undecided", "bnb", "numerics", "parallel", "environment"]
    assert r.stats["bnb"]["partitions"] == 2 ** 4 and r.stages == ["condense", "enumerate", "mu_c"]


@pytest.mark.parametrize("enumerate_,ring,taper,mu", [(True, 4, 1.0, math.tan(math.radians(1.0)) * (1 + 1e-6)),
                                                      (False, 4, 0.01, 0.65)])
def test_stats_bnb_counts_the_pyramid_lps(enumerate_, ring, taper, mu, monkeypatch):
    """stats.bnb.lps: the pyramid LPs that the tree (enumeration) or the global search ran for
    SOCPs no Clarabel attempt decided, counted as the solver statuses count their calls, the
    same in tasks of 1 tree node as in the default's. Such SOCPs lie near a mu^c: plug3d 2 x 4
    at a 1 deg taper enumerated 1e-6 above its global mu^c tan(taper) (6 LPs in the tree), the
    global search on 2 x 4 at a 0.01 deg taper (13; 2 x 5 there ran 30-50, by the BLAS kernel,
    before the tree's first attempt was balanced, and runs none since). The global search
    runs with its certified lower bound off: at this taper the bound meets the bracket's
    value and ends the search before the settling tree, whose pyramid LPs are counted here."""
    if not enumerate_:
        import functools

        import hpcwedge.run.pipeline as pipeline
        monkeypatch.setattr(pipeline, "global_mu_critical", functools.partial(pipeline.global_mu_critical,
                                                                              bound=False))
    data = {"name": "p", "dim": 3, "friction": {"mu": [mu]},
            "model": {"kind": "plug3d", "levels": 2, "ring": ring, "taper_deg": taper},
            "compute": {"enumerate": enumerate_, "mu_c": "none" if enumerate_ else "global"}}
    runs = [run_scene(parse_scene({**data, "run": {"task_budget": b}})) for b in (1, 64)]
    bnb = runs[0].stats["bnb"]
    assert bnb["lps"] > 0 and all(r.stats["bnb"] == bnb for r in runs)
    if enumerate_:
        assert bnb["lps"] == runs[0].stats["socp_statuses"]["lp_calls"]


def test_orbit_keys_give_one_mu_c_task_per_orbit():
    """orbit_key: bit words of (zero_u, zero_r), canonical under the symmetry; mu_c_keys: a
    run's cones then patterns (a pattern's zero_r: the nodes not in contact)."""

    class Swap:                    # nodes 0 and 1 exchanged: the least pair of the orbit
        def canonical(self, c, g):
            def swap(b):
                return (b & ~3) | ((b & 1) << 1) | ((b >> 1) & 1)
            return min((c, g), (swap(c), swap(g)))
    assert orbit_key([0, 2], [1], None) == (0b101, 0b010)
    run = Run(mu=1.0, cones=[Cone(rays=[], trivial_rays=[], zero_u=[0], zero_r=[1, 2])],
              patterns=[Pattern([1]), Pattern([0, 2])])
    keys = mu_c_keys(run, 3, None)
    assert keys == [((1, 6), [0], [1, 2]), ((2, 5), [1], [0, 2]), ((5, 2), [0, 2], [1])]
    sym = [k for k, *_ in mu_c_keys(run, 3, Swap())]
    assert sym[0] == sym[1] == (1, 6) and sym[2] == (5, 2)


@pytest.mark.parametrize("method", ["accurate", "bisection"])
def test_each_mu_c_says_whether_it_is_polished(method):
    """Every cone's and pattern's mu^c carries mu_c_polished: True where the pencil / KKT polish
    certified it, False where it was left at a bisection bracket's end (every value of the
    "bisection" route); as many False as stats.mu_c_unpolished (no symmetry: one task per
    item); None where there is no value."""
    r2 = run_scene(scene({"kind": "plug2d", "rows": 3}, mu=(0.1, 0.65), mu_c_method=method))
    r3 = run_scene(scene({"kind": "plug3d", "ring": 4}, dim=3, run={"symmetry": False}, mu_c_method=method))
    for res, items in ((r2, [c for run in r2.runs for c in run.cones]), (r3, r3.runs[0].patterns)):
        assert items and all(i.mu_c is not None for i in items)
        assert {i.mu_c_polished for i in items} == {method == "accurate"}
    assert sum(not p.mu_c_polished for p in r3.runs[0].patterns) == r3.stats["mu_c_unpolished"]
    none = run_scene(scene({"kind": "plug2d", "rows": 2}, mu_c="none"))
    assert all(c.mu_c is None and c.mu_c_polished is NOT_COMPUTED for c in none.runs[0].cones)
    assert all("mu_c_polished" not in c for c in none.to_dict()["runs"][0]["cones"])


def test_a_condensed_problem_too_large_for_memory_is_refused_before_condensing():
    """plug2d rows 1000 (m = 2,000): the dense condensed stiffness and its parametrisation need
    about 1 GB (about 8 dense 4,000 x 4,000 copies, measured); with 0.5 GB allowed the run
    stops with one line before condensing (before: it condensed, and at rows 5,000 grew to
    16 GB). A model of a tenth the size runs under the same limit."""
    from hpcwedge.progress import MemoryLimit
    from hpcwedge.scene.constructors import builtin_scene
    scene = builtin_scene("plug2d", rows=1000, enumerate=False, mu_c="none", max_memory_gb=0.5)
    with pytest.raises(MemoryLimit, match=r"^run\.max_memory_gb: the condensed stiffness of 2,000 contact "
                                          r"nodes \(4,000 x 4,000 dense\)"):
        condense(scene)
    small = builtin_scene("plug2d", rows=100, enumerate=False, mu_c="none", max_memory_gb=4)
    assert condense(small).problem.m == 200
