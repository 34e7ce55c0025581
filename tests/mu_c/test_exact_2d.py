"""2D mu^c certified in exact arithmetic (hpcwedge.mu_c.exact_2d) against analytic values, the
float pencil polish where it is well conditioned, and its own certificates on wrong brackets."""
from __future__ import annotations

import math

import numpy as np
import pytest
from instances import random_problem

from hpcwedge.contact.build import contact_problem
from hpcwedge.contact.problem import parametrize
from hpcwedge.mu_c.critical import mu_critical
from hpcwedge.mu_c.exact_2d import certified, exact_mu_c_2d, row_labels_2d, tight_rows
from hpcwedge.rays.numerics import NumericsReport
from hpcwedge.scene.constructors import builtin_scene
from hpcwedge.solvers.rows import pattern_rows


def _setup(problem):
    return parametrize(problem), parametrize(problem, exact=True), NumericsReport.of(problem, 10).scale


@pytest.mark.parametrize("taper", [0.001, 0.01, 1.0, 10.0])
def test_plug2d_all_contact_cone_is_tan_taper(taper):
    """The all-contact pattern of plug2d rows 2: mu^c = tan(taper) (to the float geometry's
    rounding), also where the float polish is 2.9e-7 off (0.001 deg)."""
    problem = contact_problem(builtin_scene("plug2d", rows=2, taper_deg=taper))
    param, pq, scale = _setup(problem)
    m, t = problem.m, math.tan(math.radians(taper))
    zu, zr = np.ones(m, bool), np.zeros(m, bool)
    start = mu_critical(param, m, zu, zr, mu_hi=0.65, scale=scale).mu_c
    assert abs(exact_mu_c_2d(pq, param, m, zu, zr, start, scale) - t) <= 1e-11 * t


def test_random_free_bodies_agree_with_the_float_polish():
    """Random 2D free bodies (m = 3, 4), every pattern the float polish certifies at a
    moderate mu^c: the exact value lies within 1e-10 of it (both certified to 1e-9)."""
    rng = np.random.default_rng(3)
    checked = 0
    for m in (3, 4, 3, 4):
        problem = random_problem(rng, m, free=True)
        param, pq, scale = _setup(problem)
        for bits in range(1, 2 ** m):
            zu = np.array([bits >> i & 1 for i in range(m)], bool)
            zr = ~zu
            r = mu_critical(param, m, zu, zr, mu_hi=5.0, mu_max=5.0, scale=scale)
            if r.mu_c is None or not r.polished:
                continue
            exact = exact_mu_c_2d(pq, param, m, zu, zr, r.mu_c, scale)
            assert exact is not None and abs(exact - r.mu_c) <= 1e-10 * r.mu_c, (m, bits, r.mu_c, exact)
            checked += 1
    assert checked >= 8


def test_a_bracket_off_mu_c_has_no_certificate():
    """certified() holds for the bracket exact_mu_c_2d returns and fails for one above or
    below mu^c (feasible at both ends, infeasible at both)."""
    problem = contact_problem(builtin_scene("plug2d", rows=2, taper_deg=10.0))
    param, pq, scale = _setup(problem)
    m, t = problem.m, math.tan(math.radians(10.0))
    zu, zr = np.ones(m, bool), np.zeros(m, bool)
    labels = row_labels_2d(zu, zr)
    eq = labels[:m]
    ineq = tight_rows(param, m, zu, zr, t, scale)
    d = pq.Uq.ncols()
    chosen = next(c for c in _choices(ineq, d - len(eq))
                  if certified(pq, m, zu, zr, eq, c, t * (1 - 1e-12), t * (1 + 1e-12)))
    assert not certified(pq, m, zu, zr, eq, chosen, t * 1.01, t * 1.02)
    assert not certified(pq, m, zu, zr, eq, chosen, t * 0.98, t * 0.99)


def _choices(rows, k):
    import itertools
    return [list(c) for c in itertools.combinations(rows[:k + 2], k)]


def test_row_labels_follow_pattern_rows():
    """row_labels_2d names pattern_rows' rows in its order: the labelled rows of a random
    pattern equal the parametrisation's node rows."""
    rng = np.random.default_rng(0)
    problem = random_problem(rng, 4, free=False)
    param = parametrize(problem)
    m, mu = 4, 0.7
    zu, zr = np.array([1, 0, 0, 1], bool), np.array([0, 0, 1, 0], bool)
    rows = pattern_rows(param, m, zu, zr)
    Un, Rn, Rt = param.U[:m], param.R[:m], param.R[m:2 * m]
    want = {"u": lambda i: Un[i], "rn": lambda i: Rn[i], "rt": lambda i: Rt[i],
            "p": lambda i: mu * Rn[i] + Rt[i], "m": lambda i: mu * Rn[i] - Rt[i]}
    got = rows.a0 + mu * rows.a1
    for row, (kind, i) in zip(got, row_labels_2d(zu, zr)):
        w = want[kind](i)
        assert np.allclose(row / np.linalg.norm(row), w / np.linalg.norm(w), atol=1e-12)
    assert len(got) == len(row_labels_2d(zu, zr))


@pytest.mark.parametrize("exact", [False, True])
def test_the_global_search_alone_is_certified_exactly_where_the_coordinates_are_too_ill_conditioned(exact):
    """plug2d rows 2 at a 0.001 deg taper, the global mu^c without an enumeration: its
    coordinates' cond(T) is 6e9 (a suspect enumeration's), so the least pattern's value is
    certified in exact arithmetic: tan(taper) to 1e-11 (before: 2.3e-8 off). At 1 deg the
    float value stands (no exact work), within 1e-12."""
    from hpcwedge.api import solve
    for taper, tol in ((0.001, 1e-11), (1.0, 1e-12)):
        r = solve(builtin_scene("plug2d", rows=2, taper_deg=taper, mu_c="global", enumerate=False, exact=exact))
        t = math.tan(math.radians(taper))
        assert r.mu_c_status == "found" and abs(r.mu_c - t) <= tol * t, (taper, r.mu_c / t - 1)
