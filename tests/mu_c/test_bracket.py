"""mu_bracket.py: the 2D route of a pattern's mu^c (bisection on LP feasibility, then the
pencil polish), through mu_critical's dispatch: analytic single-node values, polished; the
pencil's roots near the bracket by shift-invert against QZ; a floor and a guess against the
plain route."""
import math

import numpy as np
import pytest
import scipy.linalg as sla
from instances import global_run

from hpcwedge.contact.problem import ContactProblem, parametrize
from hpcwedge.mu_c.bracket import BRACKET_RTOL, Probe, bracket_2d, near_roots
from hpcwedge.mu_c.critical import mu_critical
from hpcwedge.mu_c.lower_bound import rigid_bound
from hpcwedge.solvers.rows import pattern_rows


@pytest.mark.parametrize("seed", range(12))
def test_single_node_formula(seed):
    rng = np.random.default_rng(seed)
    G = rng.standard_normal((2, 2))
    K = G @ G.T + 0.1 * np.eye(2)
    p = parametrize(ContactProblem(2, K, np.zeros((2, 0))))
    r = mu_critical(p, 1, np.array([True]), np.array([False]), mu_max=1e4)
    want = K[1, 1] / abs(K[0, 1])
    if want > 1e4:
        assert r.mu_c is None
    else:
        assert r.polished and abs(r.mu_c - want) <= 1e-10 * want


@pytest.mark.parametrize("seed", range(6))
def test_near_roots_are_the_qz_roots_in_the_disc(seed):
    """bracket.near_roots (shift-invert Arnoldi) against QZ (scipy.linalg.eigvals) on random
    pencils with a cluster of real roots planted near the disc: every QZ root inside the disc
    is among near_roots' to 1e-9, and near_roots grows k until the disc is covered (the
    planted cluster is larger than its first k)."""
    rng = np.random.default_rng(seed)
    n = 60
    lam = np.concatenate([0.5 + 1e-6 * rng.standard_normal(9), 3.0 * rng.standard_normal(n - 9)])
    V = rng.standard_normal((n, n))
    B = rng.standard_normal((n, n))
    A = B @ V @ np.diag(lam) @ np.linalg.inv(V)              # A v = lam B v, v the columns of V
    a, b = 0.5 - 1e-4, 0.5 + 1e-4
    got = near_roots(A, B, a, b, np.random.default_rng(0))
    qz = sla.eigvals(A, B)
    inside = qz[np.abs(qz - 0.5 * (a + b)) <= 0.5 * (b - a)]
    assert got is not None and inside.size == 9
    for z in inside:
        assert np.abs(got - z).min() <= 1e-9 * abs(z)


def test_floor_and_guess_give_the_plain_bracket_value():
    """bracket_2d with a certified floor and a guess just above it (the global search's
    shortcut) against the plain route (Dinkelbach steps from mu_max, bisection) on the
    all-contact pattern of plug2d (m = 40), whose mu^c is tan 10 deg: both polished, equal
    to 1e-12; the shortcut with one LP, a wrong guess (below mu^c: proven infeasible) only
    raises the lower end."""
    res = global_run({"kind": "plug2d", "rows": 20, "taper_deg": 10.0}, mu_c="none")
    p, m = parametrize(res.problem), res.m
    rows = pattern_rows(p, m, np.ones(m, bool), np.zeros(m, bool))
    want = math.tan(math.radians(10.0))
    floor, _ = rigid_bound(p, m, 100.0)
    plain, short, wrong = Probe(), Probe(), Probe()
    mu0, pol0 = bracket_2d(rows, plain)
    mu1, pol1 = bracket_2d(rows, short, mu_floor=floor, mu_try=floor * (1 + 0.5 * BRACKET_RTOL))
    mu2, pol2 = bracket_2d(rows, wrong, mu_try=0.9 * want)
    assert pol0 and pol1 and pol2
    assert abs(mu0 - want) <= 1e-12 and abs(mu1 - mu0) <= 1e-12 and abs(mu2 - mu0) <= 1e-12
    assert short.solves == 1 < plain.solves


def test_ladder_above_a_guess_below_mu_c(monkeypatch):
    """A guess proven infeasible (mu_try 0.5 % below mu^c of plug2d's all-contact pattern,
    m = 40): the ladder above it (TRY_LADDER) finds an upper end 1 % above mu^c, so the value
    is the one without the ladder (Dinkelbach from mu_max) to 1e-12, in fewer solves and fewer
    Dinkelbach steps."""
    from hpcwedge.mu_c import bracket
    res = global_run({"kind": "plug2d", "rows": 20, "taper_deg": 10.0}, mu_c="none")
    p, m = parametrize(res.problem), res.m
    rows = pattern_rows(p, m, np.ones(m, bool), np.zeros(m, bool))
    want = math.tan(math.radians(10.0))
    ladder, plain = Probe(), Probe()
    mu1, pol1 = bracket_2d(rows, ladder, mu_try=0.995 * want)
    monkeypatch.setattr(bracket, "TRY_LADDER", ())
    mu0, pol0 = bracket_2d(rows, plain, mu_try=0.995 * want)
    assert pol0 and pol1 and abs(mu1 - want) <= 1e-12 and abs(mu0 - want) <= 1e-12
    assert ladder.solves < plain.solves
    assert ladder.statuses["dinkelbach"] < plain.statuses["dinkelbach"]


def test_polish_by_near_roots_equals_polish_by_qz(monkeypatch):
    """The polish of plug2d's all-contact pattern (m = 40) with every pencil through
    near_roots (POLISH_DENSE_MAX = 0) gives QZ's value to 1e-13."""
    from hpcwedge.mu_c import bracket
    res = global_run({"kind": "plug2d", "rows": 20, "taper_deg": 10.0}, mu_c="none")
    p, m = parametrize(res.problem), res.m
    rows = pattern_rows(p, m, np.ones(m, bool), np.zeros(m, bool))
    qz, pol = bracket_2d(rows, Probe())
    monkeypatch.setattr(bracket, "POLISH_DENSE_MAX", 0)
    arnoldi, pol2 = bracket_2d(rows, Probe())
    assert pol and pol2 and abs(arnoldi - qz) <= 1e-13 * qz
