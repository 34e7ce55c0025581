"""lp.py: LP feasibility by HiGHS — the pyramids sandwich the cone (inscribed feasible =>
SOCP feasible => circumscribed feasible) — and the violation of a point (lp_violation)."""
import numpy as np

from hpcwedge.feasibility import decide
from hpcwedge.lp import lp_feasible, lp_violation
from hpcwedge.problem import parametrize
from hpcwedge.rows import Status, pattern_rows, pyramid_rows
from instances import random_partial_rows, random_problem


def test_pyramids_sandwich_the_cone():
    """inner feasible => SOCP feasible => outer feasible, on random partial patterns."""
    rng = np.random.default_rng(7)
    n_checked = 0
    for _ in range(40):
        rows = random_partial_rows(rng)
        for mu in (0.5, 1.5):
            s = decide(rows, mu).status
            si = lp_feasible(pyramid_rows(rows, 8, inner=True), mu)[0]
            so = lp_feasible(pyramid_rows(rows, 8, inner=False), mu)[0]
            if si == Status.FEASIBLE:
                assert s == Status.FEASIBLE
            if s == Status.FEASIBLE:
                assert so == Status.FEASIBLE
            n_checked += 1
    assert n_checked == 80


def test_lp_point_meets_its_rows_and_violation_measures_a_wrong_one():
    """A HiGHS point of a feasible 2D pattern meets every row to its tolerance (lp_violation
    ~ 1e-10); infeasible patterns return no point; a point that breaks a row is measured
    by the largest violation relative to ||x||."""
    n_feasible = n_infeasible = 0
    for seed in range(20):
        p = parametrize(random_problem(np.random.default_rng(seed), 3, bool(seed % 2)))
        zu = np.array([bool(seed & 1), bool(seed & 2), True])
        rows = pattern_rows(p, 3, zu, ~zu)
        for mu in (0.3, 3.0):
            status, x = lp_feasible(rows, mu)
            if status == Status.INFEASIBLE:
                assert x is None
                n_infeasible += 1
                continue
            assert status == Status.FEASIBLE and abs(rows.norm @ x - 1) <= 1e-9
            assert lp_violation(rows, mu, x) <= 1e-8
            assert lp_violation(rows, mu, -x) > 1e-3            # sum r_n = -1: some row broken
            n_feasible += 1
    assert n_feasible >= 5 and n_infeasible >= 5
