"""pattern_lp.py: one pattern's LP kept warm over mu (PatternLp) against the cold LP of
lp.py, and its margin steps (the Dinkelbach route of bracket.dinkelbach_hi) against a cold
bisection."""
import numpy as np
from instances import random_problem, tree_walk

from hpcwedge.contact.problem import parametrize
from hpcwedge.solvers.lp import lp_feasible, lp_violation
from hpcwedge.solvers.pattern_lp import PatternLp, point_holds, ratio
from hpcwedge.solvers.rows import Status, pattern_rows


def test_pattern_lp_agrees_with_the_cold_lp_along_a_bisection():
    """PatternLp (one warm HiGHS model per pattern, mu changed in place) against lp_feasible
    (a new model per mu): on random supported and free bodies' patterns (walked as a tree
    visits them), along a bisection's mu sequence towards the cold LP's switch, every answer
    it decides is the cold one (or infeasible where the cold point meets the rows only to
    HiGHS's tolerance), a feasible point meets the rows at mu (lp_violation, sum
    r_n = 1), and the bisection's last steps, nearest the switch, are decided too (dual rays
    checked there, not left to the cold LP)."""
    decided = {Status.FEASIBLE: 0, Status.INFEASIBLE: 0}
    unsure = near = 0
    for seed in range(6):
        rng = np.random.default_rng(100 + seed)
        m = 5
        p = parametrize(random_problem(rng, m, bool(seed % 2)))
        for zu, zr in tree_walk(rng, m, 12):
            rows = pattern_rows(p, m, zu, zr)
            if not zr.all() and rows.Z is not None:
                warm, counts = PatternLp(rows), {}
                lo, hi = 0.0, 50.0
                for step in range(30):
                    mu = hi if step == 0 else 0.5 * (lo + hi)
                    cold, x_cold = lp_feasible(rows, mu)
                    status, x = warm.solve(mu, counts)
                    if status == Status.UNDECIDED:
                        unsure += 1
                    else:
                        # or a checked dual ray where the cold point meets the rows only to
                        # HiGHS's tolerance (a mu 7e-8 below the pattern's mu^c: 1.1e-8 off)
                        assert status == cold or (status == Status.INFEASIBLE and
                                                  lp_violation(rows, mu, x_cold) > 1e-9), (seed, zu, zr, mu)
                        decided[status] += 1
                        near += step >= 20
                        if status == Status.FEASIBLE:
                            assert abs(rows.norm @ x - 1) <= 1e-9 and lp_violation(rows, mu, x) <= 1e-8
                    if step == 0 and cold != Status.FEASIBLE:
                        break
                    lo, hi = (lo, mu) if cold == Status.FEASIBLE else (mu, hi)
                assert set(counts) <= {"pattern_lp_feasible", "pattern_lp_infeasible", "pattern_lp_unsure"}
    assert min(decided.values()) >= 100 and near >= 50 and unsure <= 0.1 * sum(decided.values()), \
        (decided, near, unsure)


def _cold_feasible(rows, mu: float) -> bool:
    """lp_feasible's point, meeting the rows to 1e-12 (not only to HiGHS's tolerance: a
    random body's pattern 1.4e-6 below its mu^c, 1e-8 off)."""
    status, x = lp_feasible(rows, mu)
    return status == Status.FEASIBLE and lp_violation(rows, mu, x) <= 1e-12


def _random_patterns():
    """(rows, mu^c by _cold_mu_c) of 6 random patterns on each of 8 random bodies of m = 4
    (supported and free in turn), those with a null space and a finite mu^c."""
    for seed in range(8):
        rng = np.random.default_rng(300 + seed)
        m = 4
        p = parametrize(random_problem(rng, m, bool(seed % 2)))
        for _ in range(6):
            zu = rng.random(m) < 0.5
            zr = ~zu & (rng.random(m) < 0.3)
            rows = pattern_rows(p, m, zu, zr)
            if zr.all() or rows.Z is None:
                continue
            want = _cold_mu_c(rows)
            if want is not None:
                yield rows, want


def _cold_mu_c(rows, mu_max: float = 50.0, rtol: float = 1e-10) -> float | None:
    """A pattern's mu^c by bisection on lp_feasible (a new HiGHS model per mu)."""
    if not _cold_feasible(rows, mu_max):
        return None
    lo, hi = 0.0, mu_max
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if _cold_feasible(rows, mid) else (mid, hi)
    return hi


def test_margin_steps_reach_the_cold_bisection_mu_c_from_above():
    """From mu = 50, the weighted margin steps (PatternLp.margin, each point taken at its own
    ratio) only go down, every point meets the rows at its ratio (point_holds, lp_violation),
    and they end at the pattern's mu^c by a cold bisection (lp_feasible, to 1e-10) within
    1e-6 (1e-8 absolute at mu^c = 0) on random supported and free bodies. full patterns; at
    most 30 steps each."""
    checked = 0
    for rows, want in _random_patterns():
        warm, hi, x, steps = PatternLp(rows), 50.0, None, 0
        while steps < 30:
            steps += 1
            got = warm.margin(hi, x)
            if got is None or got[0] <= 0:
                break
            mu = ratio(rows, got[1])
            assert mu <= hi * (1 + 1e-12) and lp_violation(rows, mu, got[1]) <= 1e-9
            if not mu < hi or not point_holds(rows, mu, got[1]):
                break
            hi, x = mu, got[1]
        assert abs(hi - want) <= 1e-6 * want + 1e-8, (hi, want)   # mu^c 0: 1e-8
        checked += 1
    assert checked >= 15


def test_ray_proves_empty_below_the_cold_mu_c_and_never_above():
    """PatternLp.ray_proves_empty (a dual ray checked in x-space after its projection on its
    basis): just below each random pattern's mu^c by a cold bisection (lp_feasible) HiGHS's
    ray of the warm model is accepted, and the same ray is rejected once the model is at a mu
    just above, where lp_feasible's point exists (a wrong proof); so are random vectors and
    the ray with its last entry's sign flipped."""
    accepted = rejected = 0
    rng_y = np.random.default_rng(7)
    for rows, want in _random_patterns():
        if want < 1e-6:
            continue
        warm = PatternLp(rows)
        status, _ = warm.solve(want * (1 - 1e-6))
        _, has, y = warm._h.getDualRay()
        if status == Status.INFEASIBLE and has:
            assert warm.ray_proves_empty(y)
            accepted += 1
        above = want * (1 + 1e-6)
        cold, x = lp_feasible(rows, above)
        assert cold == Status.FEASIBLE and point_holds(rows, above, x)
        warm.solve(above)
        for z in ([y] if has else []) + [rng_y.standard_normal(len(y)) for _ in range(20)]:
            flipped = np.array(z, float)
            flipped[-1] = -flipped[-1]
            assert not warm.ray_proves_empty(z) and not warm.ray_proves_empty(flipped)
            rejected += 2
    assert accepted >= 10 and rejected >= 200, (accepted, rejected)
