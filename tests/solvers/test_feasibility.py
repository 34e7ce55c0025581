"""The one decision policy (feasibility.decide): 3D feasible sign patterns by the branch
and bound == brute force over all 2^m partitions by the SOCP == an independent
route (a different formulation, in (u, r) with K u = r, and a different solver:
HiGHS on inscribed / circumscribed pyramids of the friction cones); the policy's
answers are verified; the pyramid fallback; the 2D dispatch is the LP; options."""
import math
import time

import numpy as np
import pytest
from instances import random_partial_rows, random_problem, random_problem_3d

from hpcwedge.contact.problem import parametrize
from hpcwedge.mu_c.critical import mu_critical, mu_critical_rows
from hpcwedge.patterns.tree import PatternTree
from hpcwedge.reference import pattern_decisions, ur_sandwich
from hpcwedge.solvers.feasibility import PYRAMID_SIDES, SolverOptions, decide, pyramid_sides_for
from hpcwedge.solvers.lp import lp_feasible
from hpcwedge.solvers.rows import Rows, Status, pattern_rows, pyramid_rows
from hpcwedge.solvers.socp import VERIFY_TOL, violation

CASES = [(seed, [2, 3, 4, 3, 2, 4][seed % 6], bool(seed % 2)) for seed in range(110)] + \
        [(1000 + k, m, free) for k, (m, free) in enumerate([(5, False), (5, True), (6, True), (7, False)])]


@pytest.mark.parametrize("seed,m,free", CASES)
def test_3d_patterns_bnb_equals_brute_force_and_independent_route(seed, m, free):
    rng = np.random.default_rng(seed)
    prob = random_problem_3d(rng, m, free)
    mu = float(np.exp(rng.uniform(np.log(0.3), np.log(3.0))))
    p = parametrize(prob)
    brute, undecided_indep = set(), 0
    for bits, zu, status, x in pattern_decisions(p, m, mu, {}):
        assert status != Status.UNDECIDED
        if status == Status.FEASIBLE:
            brute.add(bits)
            assert violation(pattern_rows(p, m, zu, ~zu), mu, x) <= VERIFY_TOL
        indep = ur_sandwich(prob, zu, mu)
        if indep is None:
            undecided_indep += 1
        else:
            assert (indep == Status.FEASIBLE) == (status == Status.FEASIBLE), (bits, status, indep)
    assert undecided_indep <= 1
    tree = PatternTree(p, m, mu)
    out = tree.explore(tree.root())
    assert {s.contact for s in out.found} == brute
    assert out.undecided == []
    assert all(s.depth == m and s.contact | s.gap == (1 << m) - 1 for s in out.found)


def test_pyramid_critical_mu_within_its_gap_of_mu_c():
    """What pyramid_sides_for relies on: the critical mu of the inscribed k-pyramids
    (an LP mu^c, mu_critical_rows) lies in [mu^c, mu^c / cos(pi/k)], that of the
    circumscribed ones in [mu^c cos(pi/k), mu^c] (the polished SOCP mu^c): so a
    level decides nothing at a mu whose relative distance from mu^c is well below
    its gap 1 - cos(pi/k), unless its facets touch the optimum."""
    rng = np.random.default_rng(11)
    n_checked = 0
    for _ in range(12):
        m = 3
        p = parametrize(random_problem_3d(rng, m, bool(rng.integers(2))))
        zu = np.zeros(m, bool)
        zu[rng.integers(m)] = True
        r = mu_critical(p, m, zu, ~zu, mu_max=50.0)
        if r.mu_c is None or not r.polished:
            continue
        rows = pattern_rows(p, m, zu, ~zu)
        for k in (8, 16):
            c = np.cos(np.pi / k)
            mu_in = mu_critical_rows(pyramid_rows(rows, k, inner=True), mu_max=100.0).mu_c
            mu_out = mu_critical_rows(pyramid_rows(rows, k, inner=False), mu_max=100.0).mu_c
            assert r.mu_c * (1 - 1e-6) <= mu_in <= r.mu_c / c * (1 + 1e-6)
            assert r.mu_c * c * (1 - 1e-6) <= mu_out <= r.mu_c * (1 + 1e-6)
            n_checked += 1
    assert n_checked >= 12


def test_pyramid_sides_for_keeps_the_levels_finer_than_the_spread():
    assert pyramid_sides_for(1.0) == PYRAMID_SIDES
    assert pyramid_sides_for(1e-7) == ()
    for spread in (1e-5, 1e-4, 1e-3, 1e-2, 0.1):
        kept = pyramid_sides_for(spread)
        assert kept == tuple(k for k in PYRAMID_SIDES if 2 * np.sin(np.pi / (2 * k)) ** 2 <= spread)


def test_decide_without_pyramids_decides_what_clarabel_decides():
    """pyramid_sides=() only drops the LP fallback: the decisions Clarabel makes
    are the same (random partial patterns)."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        rows = random_partial_rows(rng)
        for mu in (0.5, 1.5):
            full, bare = decide(rows, mu), decide(rows, mu, pyramid_sides=())
            assert bare.status == full.status or bare.status == Status.UNDECIDED


def test_decide_objective_proves_the_contact_child():
    """The branch and bound's steered solve: min u_n,i over a node's problem; a
    verified positive optimum means the contact child is infeasible."""
    agree = 0
    for seed in range(30):
        m = 3
        p = parametrize(random_problem_3d(np.random.default_rng(seed), m, free=bool(seed % 2)))
        zu, zr = np.zeros(m, bool), np.zeros(m, bool)
        obj = p.U[0] / np.linalg.norm(p.U[0])
        d = decide(pattern_rows(p, m, zu, zr), 2.0, objective=obj)
        if d.status != Status.FEASIBLE:
            continue
        child = decide(pattern_rows(p, m, np.array([True, False, False]), zr), 2.0).status
        if d.positive:
            assert child == Status.INFEASIBLE
        agree += 1
    assert agree > 10


def test_2d_dispatch_is_the_lp():
    p = parametrize(random_problem(np.random.default_rng(1), 3, False))
    zu = np.array([True, True, False])
    rows = pattern_rows(p, 3, zu, ~zu)
    assert isinstance(rows, Rows)
    for mu in (0.3, 3.0, 30.0):
        assert decide(rows, mu).status == lp_feasible(rows, mu)[0]


def test_solver_options_are_values():
    """Tolerances are a value handed to decide (no module state): "tight" decides as
    "default" does on clear cases; an unknown mode is refused."""
    with pytest.raises(ValueError, match="solver tolerances"):
        SolverOptions("loose")
    rng = np.random.default_rng(9)
    for _ in range(10):
        rows = random_partial_rows(rng)
        plain, tight = decide(rows, 1.5), decide(rows, 1.5, SolverOptions("tight"))
        assert Status.UNDECIDED in (plain.status, tight.status) or plain.status == tight.status
        if tight.status == Status.FEASIBLE:
            assert violation(rows, 1.5, tight.x) <= VERIFY_TOL
    assert decide(rows, 1.5).status == plain.status       # nothing left behind by the tight calls


def _pyramid_node():
    """rows and mu of a plug3d 2 x 4 tree node (1 deg taper, 1e-6 above its mu^c) that every
    Clarabel attempt leaves undecided and the 16-facet inscribed pyramid decides feasible."""
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.patterns.tree import Subtree
    from hpcwedge.scene.parse import parse_scene
    mu = math.tan(math.radians(1.0)) * (1 + 1e-6)
    prob = contact_problem(parse_scene({"name": "p", "dim": 3, "friction": {"mu": [mu]},
                                        "model": {"kind": "plug3d", "levels": 2, "ring": 4, "taper_deg": 1.0}}))
    zu, zr = Subtree(6, 214, 8).masks(prob.m)
    return pattern_rows(parametrize(prob), prob.m, zu, zr), mu


def test_the_pyramid_lps_stop_at_their_budget(monkeypatch):
    """PYRAMID_BUDGET_S bounds the fallback (at m = 64 one 256-facet pyramid LP ran for minutes):
    with the budget spent the decision is UNDECIDED (the caller keeps the subtree) without an
    LP, counted; within it the pyramid decides. lp_feasible past its deadline runs no HiGHS."""
    import hpcwedge.solvers.feasibility as feasibility
    rows, mu = _pyramid_node()
    counts = {}
    assert decide(rows, mu, counts=counts).status == Status.FEASIBLE
    assert counts["pyramid_inner_feasible"] == 1
    monkeypatch.setattr(feasibility, "PYRAMID_BUDGET_S", 0.0)
    counts = {}
    assert decide(rows, mu, counts=counts).status == Status.UNDECIDED
    assert counts["pyramid_budget_spent"] == 1 and "lp_calls" not in counts
    inner = pyramid_rows(rows, 16, inner=True)
    assert lp_feasible(inner, mu, deadline=time.monotonic() - 1.0) == (Status.UNDECIDED, None)
    assert lp_feasible(inner, mu, deadline=time.monotonic() + 60.0)[0] == Status.FEASIBLE
