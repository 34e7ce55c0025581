"""kkt.py: the KKT Newton certificate of a 3D pattern's mu^c — the polished point satisfies
every row at mu^c, the pattern is proven infeasible just below, and bisection agrees."""
import numpy as np
import pytest
from instances import random_problem_3d

from hpcwedge.contact.problem import parametrize
from hpcwedge.mu_c.critical import mu_critical
from hpcwedge.mu_c.dinkelbach import max_ratio
from hpcwedge.patterns.tree import sign_patterns
from hpcwedge.solvers.feasibility import decide
from hpcwedge.solvers.rows import Status, pattern_rows
from hpcwedge.solvers.socp import violation


def _cases_3d():
    for seed in range(36):
        yield seed, [2, 3, 4][seed % 3], bool(seed % 2)


@pytest.mark.parametrize("seed,m,free", list(_cases_3d()))
def test_3d_pattern_mu_c_certified_and_against_bisection(seed, m, free):
    """Every feasible pattern at mu = 4: the polished mu^c comes with a point x*
    whose largest friction ratio is mu^c (feasible at mu^c to 1e-12: an upper
    bound), the pattern is infeasible at mu^c (1 - 1e-4) (a verified Farkas
    certificate: a lower bound) and not found feasible at mu^c (1 - 1e-6) (there,
    infeasible or undecided), and the plain bisection (dinkelbach.bracket_3d: its upper
    end only at points' own friction ratios) agrees from above to its own accuracy: on
    these 138 patterns -1.7e-7 .. +1.3e-6 relative (before, taking a point verified to the
    solver's tolerance as feasible at the bisection's mu, down to -1e-5 where a contact
    node carries little load)."""
    rng = np.random.default_rng(7000 + seed)
    p = parametrize(random_problem_3d(rng, m, free))
    for zu, zr in sign_patterns(p, m, 4.0):
        r = mu_critical(p, m, zu, zr, mu_hi=4.0)
        assert r.polished
        rows = pattern_rows(p, m, zu, zr)
        assert violation(rows, r.mu_c, r.x) <= 1e-12
        assert max_ratio(rows, r.x) <= r.mu_c * (1 + 1e-12)
        assert decide(rows, r.mu_c * (1 - 1e-4)).status == Status.INFEASIBLE
        assert decide(rows, r.mu_c * (1 - 1e-6)).status != Status.FEASIBLE      # infeasible or undecided
        assert decide(rows, r.mu_c * (1 + 1e-6)).status != Status.INFEASIBLE
        b = mu_critical(p, m, zu, zr, mu_hi=4.0, method="bisection", tol=1e-8)
        assert r.mu_c * (1 - 1e-6) <= b.mu_c <= r.mu_c * (1 + 1e-5)


def test_newton_trial_steps_plain_then_levenberg_marquardt():
    """The plain Newton step solves J s = -F (LU); on an exactly singular J it is the
    minimum-norm least-squares step; the Levenberg-Marquardt steps after it shrink as
    nu grows tenfold, towards the steepest-descent direction -J^T F."""
    from hpcwedge.mu_c.kkt import _trial_steps
    rng = np.random.default_rng(3)
    J = rng.standard_normal((6, 6))
    F = rng.standard_normal(6)
    steps = list(_trial_steps(J, F, float(np.linalg.norm(F))))
    assert len(steps) == 31 and steps[0][1] == 0.5 and all(r == 1.0 for _, r in steps[1:])
    np.testing.assert_allclose(J @ steps[0][0], -F, atol=1e-12)
    sizes = [np.linalg.norm(s) for s, _ in steps[1:]]
    assert all(a > b for a, b in zip(sizes, sizes[1:]))
    g = -J.T @ F
    last = steps[-1][0]
    assert last @ g / (np.linalg.norm(last) * np.linalg.norm(g)) > 1 - 1e-9
    Js = J.copy()
    Js[:, 5] = 0.0                                     # singular: column 5 unused
    Fs = Js @ rng.standard_normal(6)                   # consistent right-hand side
    plain = next(_trial_steps(Js, Fs, float(np.linalg.norm(Fs))))[0]
    np.testing.assert_allclose(plain, np.linalg.lstsq(Js, -Fs, rcond=None)[0], atol=1e-12)
    assert plain[5] == pytest.approx(0.0, abs=1e-12)


def test_a_degenerate_optimum_certified_by_two_halves():
    """plug3d 3 x 5 at mu = 1, contact nodes 2, 10, 14: at mu^c two cones are active with
    gradients dependent to rounding; Newton on both gives a verified point whose
    multipliers are unsigned (-8e-5 relative), on one alone signed multipliers whose point
    misses the other cone by 5e-11. Together they certify mu^c (kkt._bounds_meet); before,
    the value was left at a bisection bracket, 0.9169281721, below mu^c (undecided
    solves taken as feasible; Clarabel proves the pattern infeasible at 0.9169282 on the
    kernels tried, not on every one). Independent check: the point verifies, and
    Clarabel proves the pattern infeasible 1e-6 below."""
    from instances import plug3d_param

    from hpcwedge.mu_c.critical import mu_critical
    from hpcwedge.solvers.feasibility import SolverOptions, decide
    from hpcwedge.solvers.rows import Status, pattern_rows
    from hpcwedge.solvers.socp import violation
    param, m = plug3d_param(levels=3, ring=5)
    zu = np.zeros(m, bool)
    zu[[2, 10, 14]] = True
    r = mu_critical(param, m, zu, ~zu, mu_hi=1.0)
    assert r.polished and abs(r.mu_c - 0.9169282418842) <= 1e-9 * r.mu_c
    rows = pattern_rows(param, m, zu, ~zu)
    assert violation(rows, r.mu_c, r.x) <= 1e-12
    assert decide(rows, r.mu_c * (1 - 1e-6), SolverOptions()).status == Status.INFEASIBLE


def test_a_large_lift_off_point_polished_without_its_rounding():
    """A random free body (m = 8, seed 1042: the compliance puts the rigid motion at ~1e4 times
    the reactions), its pattern of least mu^c (contact nodes 1, 2, 4, 6, 7): Newton converges
    with signed multipliers, and the point's part off the active rows is rounding alone
    (~6e-12 of a w of norm 7e3), which before put 1.4e-12 .. 2.1e-12 into the cones (above
    POLISH3_TOL): the value was left unpolished, 0.89744527324 from a bisection (7e-9 high)
    in a brute force over the patterns and, in the global search, 0.89744527106 (5e-9 high).
    kkt._least_lift drops it. Independent checks: the point verifies; Clarabel proves the
    pattern infeasible 1e-6 below and finds it feasible 1e-6 above; the least-ratio SOCP (one
    Dinkelbach step, tight tolerances) is infeasible with margin 1e-7 below, not 1e-7 above."""
    from hpcwedge.mu_c.bracket import Probe
    from hpcwedge.mu_c.dinkelbach import _dinkelbach_step
    from hpcwedge.solvers.feasibility import SolverOptions
    rng = np.random.default_rng(1042)
    m = int(rng.integers(5, 9))
    p = parametrize(random_problem_3d(rng, m, free=True))
    zu = np.zeros(m, bool)
    zu[[1, 2, 4, 6, 7]] = True
    r = mu_critical(p, m, zu, ~zu, mu_hi=5.0)
    assert m == 8 and r.polished and abs(r.mu_c - 0.8974452667537) <= 1e-11
    rows = pattern_rows(p, m, zu, ~zu)
    assert violation(rows, r.mu_c, r.x) <= 1e-12 and np.linalg.norm(r.x) > 1e3
    assert decide(rows, r.mu_c * (1 - 1e-6)).status == Status.INFEASIBLE
    assert decide(rows, r.mu_c * (1 + 1e-6)).status == Status.FEASIBLE
    for rel, sign in ((-1e-7, 1), (1e-7, -1)):
        mu = r.mu_c * (1 + rel)
        x = _dinkelbach_step(rows, mu, np.ones(len(rows.nodes)), Probe(SolverOptions(tolerances="tight")))
        worst = (np.linalg.norm(rows.rt @ x, axis=1) - mu * (rows.rn @ x)).max()
        assert sign * worst > 1e-9
