"""Numerical stress (issue 4, deliverable 3): the cases of scripts/stress.py that found
something, kept as regressions. The reference is exact rational arithmetic (the DD on the
same float stiffness), or the analytic mu^c = tan(taper) of a free plug.

Each test failed before its fix: float rays near mu^c on small tapers (balanced
coordinates), ill-conditioned stiffness (run-time detection and the exact fallback;
cancelling DD steps: tests/test_numerics.py, on a constructed cone), mu^c on small
tapers (5e-5 off; balanced coordinates in the LPs), mu^c of an ill-conditioned vertex (1.3e-4 off; polish), 2D patterns at mu^c (1 - 1e-9)
(LP tolerance), a mechanism taken as a supported body (mu^c = -8e-17), a face DD
started from a nearly singular basis (cond 1e11; dd.BASIS_WELL_POSED), the close calls
of a split DD lost between its face tasks and the judgement.
"""
import importlib.util
import io
import math
import os
import sys

import numpy as np
import pytest
from instances import random_problem

from hpcwedge.contact.problem import balanced, friction_rows_2d, parametrize, ray_vectors
from hpcwedge.progress import Progress
from hpcwedge.rays.cones import implied_patterns
from hpcwedge.rays.dd import complementary_rays
from hpcwedge.run.pipeline import run_scene
from hpcwedge.scene.values import SceneError

SCRIPTS = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "scripts")
sys.path.insert(0, SCRIPTS)                    # the script's own imports (harness.py)
_spec = importlib.util.spec_from_file_location("stress_grid", os.path.join(SCRIPTS, "stress.py"))
grid = importlib.util.module_from_spec(_spec)
sys.modules["stress_grid"] = grid              # (dataclasses look their module up)
_spec.loader.exec_module(grid)


def tan(deg):
    return math.tan(math.radians(deg))


def run(spec, mu, progress=None, **compute):
    return run_scene(grid._scene(spec, mu, compute), progress=progress)


def answer(res):
    """Zero sets of the wedged rays and the cones' zero sets (canonical order)."""
    r = res.runs[0]
    return r.ray_zero.tolist(), [(c.zero_u, c.zero_r) for c in r.cones]


@pytest.mark.parametrize("taper,delta", [(1.0, 1e-7), (1.0, -1e-7), (1.0, 1e-9), (0.1, 1e-9)])
def test_float_dd_near_mu_c_on_small_taper(taper, delta):
    """mu = tan(taper) (1 + delta): 1e-7 off mu^c the float DD alone (no fallback) finds the
    exact rays and flags nothing (before the balanced coordinates: 1 ray instead of 8, or 1
    instead of 0); 1e-9 off it flags its run as suspect, and the default (the exact
    fallback) gives the exact rays. What a flagged float run finds depends on the BLAS
    kernels (0.1 deg, 1e-9: 8 rays under OpenBLAS's Haswell kernels, 10 under Sandybridge)."""
    spec = grid.builtin("plug2d", rows=4, taper_deg=taper)
    mu = tan(taper) * (1 + delta)
    raw = run(spec, mu, exact_fallback_max_m=0, mu_c="none")
    exact = run(spec, mu, exact=True, mu_c="none")
    flagged = raw.stats["numerics"]["flagged"]
    assert flagged == (abs(delta) < 1e-8)
    if not flagged:
        assert answer(raw) == answer(exact)
    res = run(spec, mu, mu_c="none")
    assert answer(res) == answer(exact)
    assert res.runs[0].n_wedged_rays == (8 if delta > 0 else 0)


@pytest.mark.parametrize("label,spec,mu", [
    ("stiff diagonals", grid.plug_truss(4, ea_diag=1e6), 0.65),    # cond(K) 8.9e5 (before the
                                                                    # well-posed basis: 500 rays, exact 198)
    ("ill-conditioned K", grid.plug_truss(4, ea_diag=1e-6), 0.65),  # float alone: 192, exact 240
    ("close calls", grid.builtin("plug2d", rows=4, taper_deg=0.1), 1.5 * tan(0.1)),   # 59 vs 56
])
def test_suspect_enumeration_is_detected_and_redone_exactly(label, spec, mu):
    """A float enumeration whose decisions were too close to call is flagged; with
    m <= compute.exact_fallback_max_m it is redone exactly (same answer as exact=true),
    above it the result says so and a warning is printed."""
    exact = run(spec, mu, exact=True, mu_c="none")
    res = run(spec, mu, mu_c="none")
    num = res.stats["numerics"]
    assert num["exact_fallback"] == [mu] and num["runs"][0]["suspect"] and num["flagged"]
    assert answer(res) == answer(exact)
    np.testing.assert_allclose(res.runs[0].rays, exact.runs[0].rays, rtol=0, atol=1e-12)
    log = io.StringIO()
    raw = run(spec, mu, progress=Progress(stream=log), exact_fallback_max_m=0, mu_c="none")
    assert raw.stats["numerics"]["unresolved"] == [mu] and raw.stats["numerics"]["flagged"]
    assert "too close to call" in log.getvalue()


def test_well_posed_runs_are_not_flagged():
    """No false alarm (and no exact rerun) on the reference scene and a refined block."""
    for spec in (grid.builtin("plug2d", rows=5), grid.builtin("block2d", rows=3, refine=8)):
        res = run(spec, 0.65)
        num = res.stats["numerics"]
        assert not num["flagged"] and not num["exact_fallback"], num
        assert abs(res.mu_c - tan(10.0)) <= 1e-9 * tan(10.0)


@pytest.mark.parametrize("taper,mu", [(0.1, 1.5 * tan(0.1)), (0.1, 0.65), (0.3, 1.5 * tan(0.3))])
def test_mu_c_on_small_taper(taper, mu):
    """Global mu^c = tan(taper) to 1e-9 (before: 5e-5 off at 0.1 deg, unpolished)."""
    res = run(grid.builtin("plug2d", rows=4, taper_deg=taper), mu)
    assert abs(res.mu_c - tan(taper)) <= 1e-9 * tan(taper)
    assert res.stats["mu_c_unpolished"] == 0


def _wedged_exact(spec, mu):
    return run(spec, mu, exact=True, mu_c="none").runs[0].n_wedged_rays


def test_global_mu_c_at_an_ill_conditioned_vertex():
    """A random free body whose critical LP vertex is ill-conditioned (active rows with
    slack 3e-4 at a 1e-7 bracket; HiGHS's simplex undecided on 6 LPs): the global mu^c,
    checked by exact arithmetic, to 1e-9 (before: 1.3e-4 low)."""
    spec = grid.raw_stiffness(2, 5, True)
    res = run(spec, 0.8)
    mu_c = res.mu_c
    assert res.runs[0].n_wedged_rays == 0 and res.mu_c_status == "found"
    assert _wedged_exact(spec, mu_c * (1 - 1e-9)) == 0
    assert _wedged_exact(spec, mu_c * (1 + 1e-9)) > 0


@pytest.mark.parametrize("delta,count", [(-1e-9, 0), (1e-9, 1)])
def test_2d_patterns_at_mu_c(delta, count):
    """Sign patterns by the LP branch and bound at mu^c (1 -/+ 1e-9), taper 1 deg: HiGHS
    finds the pattern feasible to its tolerance below mu^c; that is detected and the
    patterns are taken from the exact rays."""
    spec = grid.builtin("plug2d", rows=4, taper_deg=1.0)
    res = run(spec, tan(1.0) * (1 + delta), enumerate="patterns", mu_c="none")
    assert len(res.runs[0].patterns) == count
    if delta < 0:
        assert res.stats["numerics"]["patterns"]["exact"]


def test_implied_patterns_match_an_independent_enumeration():
    from hpcwedge.reference import patterns_of_rays
    for seed in range(6):
        rng = np.random.default_rng(seed)
        prob = random_problem(rng, 4, free=bool(seed % 2))
        p = parametrize(prob)
        dd = complementary_rays(friction_rows_2d(p, 0.9, 4), 4)
        zero = dd.zero[dd.wedged()]
        assert {sum(1 << i for i in c) for c in implied_patterns(zero, 4)} == patterns_of_rays(zero, 4)


def test_balanced_coordinates_are_the_same_cone():
    """balanced: the float DD in the new coordinates has the exact zero sets, and its
    rays map to the same (u, r) as the exact ones."""
    for seed in range(8):
        rng = np.random.default_rng(100 + seed)
        m, free = 4, bool(seed % 2)
        prob = random_problem(rng, m, free)
        mu = float(rng.uniform(0.2, 1.5))
        pb = balanced(parametrize(prob), mu, m, 1.0)[0]
        fl = complementary_rays(friction_rows_2d(pb, mu, m), m)
        pe = parametrize(prob, exact=True)
        ex = complementary_rays(friction_rows_2d(pe, mu, m, exact=True), m, exact=True)
        of, oe = (np.lexsort(z.T[::-1]) for z in (fl.zero, ex.zero))
        assert np.array_equal(fl.zero[of], ex.zero[oe])
        w = fl.wedged()[of]
        _, vf = ray_vectors(pb, fl.X[of], m, w)
        _, ve = ray_vectors(pe, ex.X[oe], m, w)
        np.testing.assert_allclose(vf, ve, rtol=0, atol=1e-9)


def test_answer_does_not_depend_on_frame_or_units():
    """Rotating the global frame or scaling every EA by 1e8 changes nothing."""
    base = run(grid.plug_truss(4), 0.65)
    for spec in (grid.plug_truss(4, angle_deg=137.3), grid.plug_truss(4, angle_deg=291.8),
                 grid.plug_truss(4, ea=1e8)):
        res = run(spec, 0.65)
        assert answer(res) == answer(base)
        assert abs(res.mu_c - base.mu_c) <= 1e-9 * base.mu_c


def test_mechanism_is_an_input_error():
    """Ground bars that leave a rotation free: the condensed K is singular although the
    body has supports (before: taken as supported, global mu^c = -8e-17)."""
    spec = grid.plug_truss(4, ground=1.0)
    spec["model"]["nodes"][-2] = [0.0, 1.5]        # the top ground bar vertical, under the pin
    with pytest.raises(SceneError, match="mechanism"):
        run(spec, 0.65)


def test_exact_fallback_key_is_validated():
    with pytest.raises(SceneError, match="exact_fallback_max_m"):
        grid._scene(grid.builtin("plug2d"), 0.65, {"exact_fallback_max_m": -1})


def test_undecided_simplex_is_retried_by_interior_point(monkeypatch):
    """An LP the dual simplex leaves undecided is solved again by HiGHS's interior point
    method (counted), not taken as feasible."""
    import hpcwedge.solvers.feasibility as feasibility
    from hpcwedge.solvers.lp import lp_feasible
    from hpcwedge.solvers.rows import Status, pattern_rows
    rows = pattern_rows(parametrize(random_problem(np.random.default_rng(3), 3, False)), 3,
                              np.array([True, True, False]), np.array([False, False, True]))
    plain = lp_feasible(rows, 0.8)[0]
    real = lp_feasible
    methods = []

    def flaky(rows, mu, options=None, method="simplex", counts=None):
        methods.append(method)
        return (Status.UNDECIDED, None) if method == "simplex" else real(rows, mu, options, method, counts)
    monkeypatch.setattr(feasibility, "lp_feasible", flaky)
    counts = {}
    status = feasibility.decide(rows, 0.8, counts=counts).status
    assert methods == ["simplex", "ipm"] and status == plain != Status.UNDECIDED
    assert counts == {"lp_undecided": 1, f"lp_retry_ipm_{plain}": 1}


SMALL_TAPER = grid.builtin("plug2d", rows=4, taper_deg=0.1)     # m = 8, close calls at 1.5 tan


def test_face_split_is_judged_like_one_dd():
    """A float DD split over faces (run.face_split) carries the close calls of every
    face into the judgement: redone exactly within the fallback limit, reported above
    it (before: the face tasks dropped them, and the split run passed as exact)."""
    mu = 1.5 * tan(0.1)
    split = {**SMALL_TAPER, "run": {"face_split": 3}}
    exact = run(SMALL_TAPER, mu, exact=True, mu_c="none")
    res = run(split, mu, mu_c="none")
    assert res.stats["numerics"]["exact_fallback"] == [mu] and answer(res) == answer(exact)
    log = io.StringIO()
    raw = run(split, mu, progress=Progress(stream=log), exact_fallback_max_m=0, mu_c="none")
    assert raw.stats["dd"][0]["faces"] == 8 and raw.stats["dd"][0]["close_calls"] > 0
    assert raw.stats["numerics"]["unresolved"] == [mu] and "too close to call" in log.getvalue()


def test_face_dd_starts_from_a_well_conditioned_basis():
    """On the face where the 3 branching nodes are in contact, the first 13 rows in
    order left a row 1e-10 from the span of the others: the initial rays had cond 1e11,
    their combinations zero flags off by up to 0.75, so nearly every ray looked
    degenerate (at m = 16 the face ran > 16 min instead of 0.2 s). Now the basis is
    well conditioned and every ray's zero flags agree with its values up to the close-call
    band (this is the close-call scene: under OpenBLAS's Sandybridge kernels one ray flagged
    nonzero has a.x = -1.6e-11 when recomputed, inside the band)."""
    from hpcwedge.contact.build import build_model, contact_problem
    from hpcwedge.rays.dd import CLOSE_CALL_FACTOR, FLOAT_ZERO_TOL, face_rows, initial_basis
    from hpcwedge.rays.faces import split_faces
    from hpcwedge.rays.numerics import NumericsReport

    mu = 1.5 * tan(0.1)
    scene = grid._scene(SMALL_TAPER, mu, {})
    problem = contact_problem(scene, build_model(scene))
    m = problem.m
    p_mu = balanced(parametrize(problem), mu, m, NumericsReport.of(problem, 10).scale)[0]
    A = friction_rows_2d(p_mu, mu, m)
    for face in split_faces(m, [5, 6, 7]):
        basis, _ = initial_basis(A, m, list(range(m)), False, face_rows(face, m))
        assert np.linalg.cond(A[basis]) < 1e3, face
        dd = complementary_rays(A, m, face=face)
        S = dd.X @ A.T
        band = CLOSE_CALL_FACTOR * FLOAT_ZERO_TOL
        assert np.abs(S[dd.zero]).max(initial=0.0) < 1e-8, face
        assert S[~dd.zero].min(initial=1.0) > -band, face
