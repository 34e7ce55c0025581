"""The pattern SOCP for Clarabel (socp.py): the ladder of attempts, the two forms, the
Farkas check of what Clarabel returns."""
import numpy as np
from instances import brute_3d, partial_masks, partial_rows, plug3d_param, random_problem_3d

from hpcwedge.contact.problem import parametrize
from hpcwedge.solvers.conic import ATTEMPTS, CLARABEL_STATUS, LEAST_NORM_ATTEMPT
from hpcwedge.solvers.feasibility import decide
from hpcwedge.solvers.rows import Status, pattern_rows
from hpcwedge.solvers.socp import attempts, certificate_ok, pattern_attempts, pattern_socp


def _rows(seed: int, m: int = 3):
    p = parametrize(random_problem_3d(np.random.default_rng(seed), m, bool(seed % 2)))
    return pattern_rows(p, m, np.zeros(m, bool), np.zeros(m, bool))


def test_ladder_skips_the_least_norm_attempt_of_a_problem_with_its_own_objective():
    from dataclasses import replace
    rows = _rows(0)
    plain = pattern_socp(rows, 1.0)
    assert [k for k, _ in attempts(plain, False)] == list(range(ATTEMPTS))
    own = replace(plain, q=np.ones(plain.A.shape[1]))
    assert [k for k, _ in attempts(own, False)] == [k for k in range(ATTEMPTS) if k != LEAST_NORM_ATTEMPT]
    sols = [s for _, s in attempts(plain, False, steered=own)]
    assert len(sols) == ATTEMPTS and all(CLARABEL_STATUS[s.name] == s.status for s in sols)


def test_farkas_certificates_are_checked():
    """An infeasible pattern's certificate passes the check; the same z with the sign of
    b^T z flipped, or moved off the dual cone, does not."""
    found = 0
    for seed in range(30):
        rows = _rows(seed)
        for mu in (0.05, 0.2):
            if decide(rows, mu).status != Status.INFEASIBLE:
                continue
            o = next(pattern_attempts(rows, mu, False))
            if o.status != Status.INFEASIBLE:
                continue
            prob = pattern_socp(rows, mu)
            assert o.certified and certificate_ok(prob.A, prob.b, o.farkas, 1, prob.n_lin)
            assert not certificate_ok(prob.A, prob.b, -o.farkas, 1, prob.n_lin)
            bad = o.farkas.copy()
            bad[prob.n_zero + prob.n_lin:] = 0.0
            bad[prob.n_zero + prob.n_lin + 1] = 1e3            # a cone row with a huge tangential part
            assert not certificate_ok(prob.A, prob.b, bad, 1, prob.n_lin)
            found += 1
    assert found >= 3


def test_first_attempt_settles_the_search_socps_of_a_body_without_symmetry():
    """plug3d 2 x 6 (m = 12) searched without its symmetry at mu = 0.65: Clarabel's first
    attempt settles all but at most 1 % of the tree's SOCPs (feasibility problems:
    settings(0, feasibility=True)); with Clarabel's default regularisation 37 % went down
    the ladder. The 25 feasible patterns either way."""
    from hpcwedge.patterns.tree import BnBStats, sign_patterns
    param, m = plug3d_param(2, 6)
    stats = BnBStats()
    found = sign_patterns(param, m, 0.65, stats=stats)
    retried = sum(v for k, v in stats.statuses.items() if k.startswith("retry1_") and k[7:8].isupper())
    assert len(found) == 25 and stats.solves > 500
    assert retried <= 0.01 * stats.solves, stats.statuses


def test_reaction_form_agrees_with_the_null_space_form():
    """The first attempt (reaction coordinates) and the null-space form decide every
    partial pattern of plug3d 2 x 4 at two mu alike; a reaction point is verified in
    x-space and a reaction certificate, carried into pattern_socp's layout, passes the
    Farkas check there."""
    from hpcwedge.solvers.conic import solve
    from hpcwedge.solvers.socp import VERIFY_TOL, reaction_socp, violation
    p, m = plug3d_param(2, 4)
    rng = np.random.default_rng(5)
    kinds = {Status.FEASIBLE: 0, Status.INFEASIBLE: 0}
    for mu, rows in partial_rows(p, m, rng, (0.4, 0.9), 60):
        first = reaction_socp(rows, mu)
        sol = solve(first.problem, 0, False)
        ref = solve(pattern_socp(rows, mu), 2, False)
        assert sol.status == ref.status in kinds
        kinds[sol.status] += 1
        if sol.status == Status.FEASIBLE:
            assert violation(rows, mu, first.to_x(np.asarray(sol.x))) <= VERIFY_TOL
        else:
            plain = pattern_socp(rows, mu)
            assert certificate_ok(first.problem.A, first.problem.b, sol.z, first.problem.n_zero,
                                  first.problem.n_lin)
            z = first.farkas(sol.z)
            assert z is not None and certificate_ok(plain.A, plain.b, z, 1, plain.n_lin)
    assert min(kinds.values()) >= 10


def test_small_taper_tree_is_decided_by_first_attempts():
    """plug3d 2 x 5 at a 0.1 deg taper (the smallest of SPEC's stress range) and 0.01 deg:
    the reaction form balanced at mu (r_t / mu, the rigid amplitudes' u_n block
    orthonormal) decides every SOCP of the tree on its first attempt, with no pyramid LP,
    at mu = 1.5 tan(taper) and at mu = 0.65; the patterns are brute force's (every one of
    the 1,024 full patterns decided on its own: 1 and 41). Unbalanced, 28 of the 103 SOCPs
    at 0.1 deg and 1.5 tan(taper) went down the ladder and 47 LPs ran."""
    import itertools
    import math

    from hpcwedge.patterns.tree import BnBStats, sign_patterns
    for taper in (0.1, 0.01):
        p, m = plug3d_param(2, 5, taper_deg=taper)
        for mu, n in ((1.5 * math.tan(math.radians(taper)), 1), (0.65, 41)):
            stats = BnBStats()
            tree = {zu.tobytes() for zu, _ in sign_patterns(p, m, mu, stats=stats)}
            first = stats.statuses.get("Solved", 0) + stats.statuses.get("PrimalInfeasible", 0)
            assert first == stats.solves and stats.lps == 0 and not stats.undecided, stats.statuses
            brute = set()
            for bits in itertools.product([False, True], repeat=m):
                zu = np.array(bits)
                d = decide(pattern_rows(p, m, zu, ~zu), mu)
                assert d.status != Status.UNDECIDED
                if d.status == Status.FEASIBLE:
                    brute.add(zu.tobytes())
            assert tree == brute and len(tree) == n


def test_farkas_decisions_prune_only_infeasible_patterns():
    """farkas_decisions of a certified reaction-form certificate (plug3d 2 x 4, random partial
    patterns at mu 0.2 and 0.4, 1.13 and 2.3 mu^c) name a subset of the pattern's fixings
    that no feasible full pattern of brute force keeps, and every random partial pattern
    keeping them is decided infeasible by its own solve. Dropping the gap decisions without
    their dual-cone check does prune feasible patterns: the check can fail."""
    from hpcwedge.solvers.conic import solve
    from hpcwedge.solvers.socp import farkas_decisions, reaction_socp
    p, m = plug3d_param(2, 4)
    rng = np.random.default_rng(3)
    full = (1 << m) - 1
    smaller = unchecked_wrong = certified = 0
    for mu in (0.2, 0.4):
        feasible = brute_3d(p, m, mu)
        for _ in range(60):
            masks = partial_masks(rng, m)
            if masks is None:
                continue
            first = reaction_socp(pattern_rows(p, m, *masks), mu)
            sol = solve(first.problem, 0, False)
            if sol.status != Status.INFEASIBLE or not certificate_ok(
                    first.problem.A, first.problem.b, sol.z, first.problem.n_zero, first.problem.n_lin):
                continue
            certified += 1
            contact, gap = farkas_decisions(first, np.asarray(sol.z))
            assert not (contact & ~masks[0]).any() and not (gap & ~masks[1]).any()
            smaller += int(contact.sum() + gap.sum() < masks[0].sum() + masks[1].sum())
            c_bits = int(sum(1 << int(i) for i in contact.nonzero()[0]))
            g_bits = int(sum(1 << int(i) for i in gap.nonzero()[0]))
            assert not [b for b in feasible if b & c_bits == c_bits and (full & ~b) & g_bits == g_bits]
            # the gap decisions the check kept, dropped unchecked: a feasible pattern is pruned
            unchecked_wrong += bool(gap.any()) and any(b & c_bits == c_bits for b in feasible)
            for _ in range(3):                    # other partial patterns keeping the decisions
                zu, zr = contact.copy(), gap.copy()
                state = rng.integers(0, 3, m)
                zu |= (state == 1) & ~gap
                zr |= (state == 2) & ~zu
                if (~zr).any():
                    assert decide(pattern_rows(p, m, zu, zr), mu).status == Status.INFEASIBLE
    assert certified >= 25 and smaller >= 10 and unchecked_wrong >= 1, (certified, smaller, unchecked_wrong)
