"""The global mu^c: the least mu at which any sign pattern has a solution (2D and 3D),
without enumerating the patterns: a bracket by the pattern tree with an incumbent, or
(2D, large m) by MILPs (milp.wedge_milp), then every pattern near the bracket settled by
its certified mu^c (mu_critical.py)."""
from __future__ import annotations

import math
from functools import partial

import numpy as np

from .feasibility import DEFAULT_OPTIONS, decide
from .milp import WedgeMilp, wedge_milp
from .mu_critical import MuC, add_counts, mu_critical
from .parallel import task_tick
from .patterns import BnBStats, PatternTree, Subtree, sign_patterns
from .problem import Parametrization
from .rows import Status, count, pattern_rows, problem_dim
from .symmetry import Symmetry

#: 2D MILP route (global_bracket_milp): the relative steps below the best mu^c found at
#: which the MILP is asked again; the last is HiGHS's MIP feasibility tolerance
MILP_STEPS = (1e-2, 1e-4, 1e-6)
#: tree route: the next bound is best (1 - TREE_STEP). Every pattern between it and best is
#: settled by the final enumeration at best (1 + 1e-9), so the step sets the work, not the
#: answer; at 1e-7 the tree's problems at the bound lay within Clarabel's tolerance of
#: their boundary (plug3d 4 x 6 without symmetry: 6 undecided, 16 s; 1e-5: none, 6.7 s)
TREE_STEP = 1e-5
#: 2D MILP route: the tree's dive before each MILP gets DIVE_NODES * m + 1 tree nodes
DIVE_NODES = 2
#: route "auto" takes the 2D MILP route from this many contact nodes on; below it the tree,
#: which sees every pattern within 1e-9 of the answer (the MILP route can miss one within
#: ~1e-6 below it, HiGHS's tolerance) and finishes in seconds there (m = 20: ~6 s)
MILP_FROM_M = 25


def global_mu_critical(param: Parametrization, m: int, mu_max: float, method: str = "accurate",
                       tol: float = 1e-6, stats: BnBStats | None = None,
                       symmetry: Symmetry | None = None,
                       scale: float | None = None, route: str = "auto",
                       certify=None) -> tuple[float | None, str]:
    """Least mu with any solution (2D and 3D alike; with a symmetry, over orbit
    representatives). scale: passed to mu_critical (2D balanced coordinates).

    Two stages. The bracket: an upper value `best` (the certified mu^c of a pattern) with no
    pattern feasible below best (1 - TREE_STEP), found by
      route "tree": branch and bound over patterns with an incumbent (LPs in 2D, SOCPs in 3D);
      route "milp" (2D; 3D runs the tree): `global_bracket_milp`, per step a short dive of
        the tree and, where it does not settle the step, one MILP (HiGHS); each pattern
        it returns checked by our LP and its mu^c computed by our certified route; any doubt
        (an undecided MILP, a pattern our LP rejects at every mu, no wedge at all) falls back
        to the tree;
      route "auto": "milp" in 2D from MILP_FROM_M contact nodes on, else "tree".
    The tree route then settles: every pattern (one per orbit) feasible at best (1 + 1e-9)
    gets its certified mu^c; the least is the answer. The MILP route skips that enumeration
    (exponential in m: 635 tree nodes on plug2d m = 16): its answer is the certified mu^c of
    the last pattern it found, the least to the MILP's tolerance (a pattern whose mu^c lies
    within ~1e-6 relative below it can go unseen). stats.extra["route"] says which route
    ran; its MILP counts are stats.extra["milp_solves"] and ["milp_nodes"].

    certify(zero_u, zero_r, mu_c): the least pattern's value certified another way (2D: in
    exact arithmetic, exact_mu_c), or None to keep it.

    Returns (mu_c, status): status "found", "none_at_any_mu" (the relaxation with
    r_t free has no solution) or "none_up_to_mu_max".
    """
    pattern_of: dict = {}           # each value computed -> its pattern (for certify)
    mu_c, status = _search(param, m, mu_max, method, tol, stats, symmetry, scale, route, pattern_of)
    if certify is not None and mu_c in pattern_of:
        exact = certify(*pattern_of[mu_c], mu_c)
        if exact is not None:
            mu_c = exact
    return mu_c, status


def _search(param, m, mu_max, method, tol, stats, symmetry, scale, route, pattern_of: dict):
    """global_mu_critical without its certify step; pattern_of[value] = that value's pattern."""
    if route not in ("auto", "tree", "milp"):
        raise ValueError(f"global mu^c route: 'auto', 'tree' or 'milp', got {route!r}")
    stats = stats if stats is not None else BnBStats()
    # Clarabel's own steps: every tree solve here lies near mu^c (socp module doc)
    search = partial(sign_patterns, param, m, stats=stats, symmetry=symmetry, options=DEFAULT_OPTIONS)
    solve = partial(_recorded, partial(mu_critical, param, m, mu_max=mu_max, method=method, tol=tol, scale=scale),
                    pattern_of)
    best = None
    if (route == "milp" or (route == "auto" and m >= MILP_FROM_M)) and problem_dim(param, m) == 2:
        best = global_bracket_milp(param, m, mu_max, solve, stats, scale)
        if best is not None:
            return best, "found"
    if best is None:
        stats.extra["route"] = "tree"
        if not search(np.inf, friction=False, first_only=True):
            return None, "none_at_any_mu"
        bound = mu_max
        while True:
            leaf = search(bound, first_only=True)
            if not leaf:
                break
            zu, zr = leaf[0]
            r = solve(zu, zr, mu_hi=bound)
            _absorb(stats, r)
            if r.mu_c is None or (best is not None and r.mu_c >= best):
                break
            best = r.mu_c
            bound = best * (1 - TREE_STEP)
        if best is None:
            return None, "none_up_to_mu_max"
    # patterns whose mu^c lies within the last step below `best`: settle them all
    # (one per orbit: mu^c is invariant under the symmetry)
    top = best * (1 + 1e-9)
    for zu, zr in search(top, representatives=True):
        r = solve(zu, zr, mu_hi=top)
        _absorb(stats, r)
        if r.mu_c is not None:
            best = min(best, r.mu_c)
    return best, "found"


def _recorded(solve, pattern_of: dict, zero_u, zero_r, **kw):
    """solve(zero_u, zero_r, **kw), its value's pattern kept in pattern_of[value]."""
    r = solve(zero_u, zero_r, **kw)
    if r.mu_c is not None:
        pattern_of.setdefault(r.mu_c, (zero_u, zero_r))
    return r


def global_bracket_milp(param: Parametrization, m: int, mu_max: float, solve, stats: BnBStats,
                        scale: float | None = None, dive: int = DIVE_NODES) -> float | None:
    """2D global mu^c by MILPs (milp.wedge_milp, valid big-M): the least certified
    pattern mu^c `best` found; None when in doubt (the caller runs the tree instead).
    solve(zero_u, zero_r, mu_hi): the certified mu^c of one pattern (mu_critical).

    The MILP decides feasibility only to HiGHS's tolerance (a pattern infeasible by ~1e-6
    relative in mu can come back feasible, and then hide one feasible with margin), so
    each step asks at best (1 - delta) with delta = MILP_STEPS in turn: a pattern returned
    of lower certified mu^c replaces best (same delta again); none, or one no better
    (blurred), moves to the next delta. The first pattern is the MILP's at mu = inf (r_t
    free), whose mu^c, when finite, saves the MILP at mu_max (the slowest). Before each
    MILP the tree dives for dive * m + 1 nodes (0: no dive), see `milp` below."""
    s = 1.0 if scale is None else float(scale)
    stats.extra["route"] = "milp"

    def milp(mu: float) -> WedgeMilp:
        # a short dive of the tree first: it settles most steps with a few LPs (a relaxed
        # vertex that is complementary descends without a solve; an infeasible root proves
        # none); the MILP only where the dive's budget runs out
        if dive:
            tree = PatternTree(param, m, 0.0 if np.isinf(mu) else mu, friction=not np.isinf(mu))
            out = tree.explore(Subtree(0), budget=dive * m + 1, first_only=True)
            stats.add(out.stats)
            if out.found and not out.undecided:
                count(stats.statuses, "dive_feasible")
                zu, zr = out.found[0].masks(m)
                return WedgeMilp(Status.FEASIBLE, math.nan, 0, zu, zr)
            if not (out.found or out.open or out.stopped or out.stats.undecided):
                count(stats.statuses, "dive_infeasible")
                return WedgeMilp(Status.INFEASIBLE, 0.0, 0)
        ans = wedge_milp(param, m, mu, s)
        stats.extra["milp_solves"] = stats.extra.get("milp_solves", 0) + 1
        stats.extra["milp_nodes"] = stats.extra.get("milp_nodes", 0) + ans.nodes
        count(stats.statuses, "milp_" + ans.status)
        return ans

    seen: dict = {}

    def certified(ans: WedgeMilp, bound: float) -> float | None:
        key = (ans.zero_u.tobytes(), ans.zero_r.tobytes())
        if key in seen:                   # a pattern met again (blurred): its value is known
            count(stats.statuses, "milp_pattern_again")
            return seen[key]
        seen[key] = _certified(ans, bound)
        return seen[key]

    def _certified(ans: WedgeMilp, bound: float) -> float | None:
        rows = pattern_rows(param, m, ans.zero_u, ans.zero_r)
        stats.lps += 1
        ok = np.isfinite(bound) and decide(rows, bound, counts=stats.statuses).status == Status.FEASIBLE
        r = solve(ans.zero_u, ans.zero_r, mu_hi=bound if ok else None)
        _absorb(stats, r)
        return r.mu_c

    best = None
    for mu in (np.inf, mu_max):
        ans = milp(mu)
        if ans.status != Status.FEASIBLE:
            return None                   # no wedge, or undecided: the tree decides
        best = certified(ans, mu)
        if best is not None:
            break
    if best is None:
        return None                       # the MILP's pattern at mu_max is no wedge: doubt
    for delta in MILP_STEPS:
        while True:
            task_tick()
            bound = best * (1 - delta)
            ans = milp(bound)
            if ans.status == Status.UNDECIDED:
                return None
            if ans.status == Status.INFEASIBLE:
                break
            mu = certified(ans, bound)
            if mu is None:
                return None
            if mu >= best:
                break
            best = mu
    return best


def _absorb(stats: BnBStats, r: MuC) -> None:
    """Count a mu^c computation (mu_critical.MuC) into the search statistics."""
    add_counts(stats, r)
    key = "mu_c_polished" if r.polished else "mu_c_unpolished"
    stats.extra[key] = stats.extra.get(key, 0) + 1
