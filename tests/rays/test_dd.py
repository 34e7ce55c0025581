"""Complementarity-pruned DD against exact arithmetic, an unpruned brute force, and
an LP per sign pattern, on random supported and free bodies."""

import numpy as np
import pytest
from instances import random_problem

from hpcwedge.contact.problem import friction_rows_2d, parametrize
from hpcwedge.rays.dd import complementary_rays
from hpcwedge.reference import brute_force_rays, pattern_decisions, patterns_of_rays
from hpcwedge.solvers.rows import Status

CASES = [(seed, m, free) for seed in range(40) for m, free in
         [(1, False), (2, False), (2, True), (3, False), (3, True)]]


@pytest.mark.parametrize("seed,m,free", CASES)
def test_float_exact_bruteforce_agree(seed, m, free):
    rng = np.random.default_rng(1000 * seed + 10 * m + free)
    prob = random_problem(rng, m, free)
    mu = float(rng.uniform(0.2, 1.5))
    pf, pe = parametrize(prob), parametrize(prob, exact=True)
    rf = complementary_rays(friction_rows_2d(pf, mu, m), m)
    re = complementary_rays(friction_rows_2d(pe, mu, m, exact=True), m, exact=True)
    zf, ze = set(map(tuple, rf.zero)), set(map(tuple, re.zero))
    assert len(zf) == len(rf.zero) and len(ze) == len(re.zero)      # no duplicates
    assert zf == ze
    assert zf == brute_force_rays(friction_rows_2d(pf, mu, m))
    # the float rays really are rays of the cone with those zero sets
    A = friction_rows_2d(pf, mu, m)
    V = rf.X @ A.T
    assert np.all(V >= -1e-9)
    assert np.array_equal(np.abs(V) <= 1e-9, rf.zero)


@pytest.mark.parametrize("seed", range(20))
@pytest.mark.parametrize("m,free", [(4, False), (4, True), (5, True)])
def test_patterns_lp_per_pattern(seed, m, free):
    """Patterns implied by the rays = patterns with a feasible LP (one per partition)."""
    rng = np.random.default_rng(77 + 1000 * seed + 10 * m + free)
    prob = random_problem(rng, m, free)
    mu = float(rng.uniform(0.3, 1.5))
    p = parametrize(prob)
    dd = complementary_rays(friction_rows_2d(p, mu, m), m)
    lp = set()
    for bits, _, status, _ in pattern_decisions(p, m, mu):
        assert status in (Status.FEASIBLE, Status.INFEASIBLE)
        if status == Status.FEASIBLE:
            lp.add(bits)
    assert patterns_of_rays(dd.zero, m) == lp


@pytest.mark.parametrize("seed", range(6))
def test_exact_m6(seed):
    rng = np.random.default_rng(5 + seed)
    prob = random_problem(rng, 6, free=bool(seed % 2))
    pf, pe = parametrize(prob), parametrize(prob, exact=True)
    rf = complementary_rays(friction_rows_2d(pf, 0.8, 6), 6)
    re = complementary_rays(friction_rows_2d(pe, 0.8, 6, exact=True), 6, exact=True)
    assert set(map(tuple, rf.zero)) == set(map(tuple, re.zero))


def test_pruned_equals_unpruned_filtered():
    """Pruning loses nothing: compare with the full DD of all extreme rays
    (brute force) filtered for complementarity on a free m = 4 body."""
    rng = np.random.default_rng(3)
    prob = random_problem(rng, 4, free=True)
    p = parametrize(prob)
    A = friction_rows_2d(p, 0.9, 4)
    assert set(map(tuple, complementary_rays(A, 4).zero)) == brute_force_rays(A)


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("m,free", [(4, False), (5, True), (6, True)])
def test_row_orders_agree(seed, m, free):
    """The row order changes the work, never the result: greedy (the float default),
    static, and a random node order give the same rays."""
    rng = np.random.default_rng(300 + 1000 * seed + 10 * m + free)
    prob = random_problem(rng, m, free)
    A = friction_rows_2d(parametrize(prob), float(rng.uniform(0.3, 1.5)), m)
    ref = complementary_rays(A, m)
    assert len(ref.X) == len(set(map(tuple, ref.zero)))
    for order in ("static", "greedy", list(rng.permutation(m))):
        r = complementary_rays(A, m, order=order)
        assert set(map(tuple, r.zero)) == set(map(tuple, ref.zero))
        assert len(r.X) == len(ref.X)


def test_greedy_order_is_float_only():
    rng = np.random.default_rng(1)
    p = parametrize(random_problem(rng, 3, False), exact=True)
    A = friction_rows_2d(p, 0.8, 3, exact=True)
    with pytest.raises(ValueError):
        complementary_rays(A, 3, exact=True, order="greedy")
    with pytest.raises(ValueError):
        complementary_rays(A, 3, exact=True, order="fastest")


# --------------------------------------------------------------------- face splitting
