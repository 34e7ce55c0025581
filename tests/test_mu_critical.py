"""mu^c: analytic single-node values, the cone route against the pattern
branch and bound, and exact-arithmetic DD on both sides of the value."""
import numpy as np
import pytest

from hpcwedge.cones import maximal_cones
from hpcwedge.dd import complementary_rays
from hpcwedge.mu_critical import mu_critical
from hpcwedge.patterns import global_mu_critical
from hpcwedge.problem import ContactProblem, friction_rows_2d, parametrize
from instances import random_problem


def n_wedged_exact(prob, mu):
    pe = parametrize(prob, exact=True)
    m = prob.m
    return int(complementary_rays(friction_rows_2d(pe, mu, m, exact=True), m, exact=True).wedged().sum())


def cone_route(prob, mu):
    m = prob.m
    p = parametrize(prob)
    dd = complementary_rays(friction_rows_2d(p, mu, m), m)
    gap, load = ~dd.zero_u(), ~dd.zero_r()
    vals = []
    for c in maximal_cones(gap, load, dd.wedged()):
        r = mu_critical(p, m, c.zero_u, c.zero_r, mu_hi=mu)
        assert r.polished
        vals.append(r.mu_c)
    return min(vals) if vals else None


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


@pytest.mark.parametrize("seed", range(16))
@pytest.mark.parametrize("m,free", [(2, False), (2, True), (3, True)])
def test_global_routes_and_exact_bracket(seed, m, free):
    rng = np.random.default_rng(500 + 100 * seed + 10 * m + free)
    prob = random_problem(rng, m, free)
    p = parametrize(prob)
    bnb, status = global_mu_critical(p, m, mu_max=50.0)
    cones = cone_route(prob, 50.0)
    if cones is None:
        assert bnb is None and status != "found"
        return
    assert status == "found"
    assert abs(bnb - cones) <= 1e-9 * cones
    # exact arithmetic: no wedged ray just below mu^c, some just above
    assert n_wedged_exact(prob, cones * (1 - 1e-8)) == 0
    assert n_wedged_exact(prob, cones * (1 + 1e-8)) > 0


def test_bisection_method_tolerance():
    for seed in range(50):
        p = parametrize(random_problem(np.random.default_rng(seed), 2, True))
        exact, _ = global_mu_critical(p, 2, 50.0)
        if exact is not None:
            break
    rough, _ = global_mu_critical(p, 2, 50.0, method="bisection", tol=1e-4)
    assert exact is not None and rough >= exact * (1 - 1e-7) and rough <= exact * (1 + 2e-4)
