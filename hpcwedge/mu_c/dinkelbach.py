"""mu^c of a 3D pattern (SPEC §2): min over the pattern's x of max_i ||r_t,i|| / r_n,i,
a generalised fractional program.

Route "accurate":
  1. a feasible x at mu_hi (one SOCP);
  2. Dinkelbach iterations in the scaled form of Crouzeix, Ferland and
     Schaible: mu_k = max_i ||r_t,i(x_{k-1})|| / r_n,i(x_{k-1}); x_k solves the SOCP
         min s  s.t.  ||r_t,i|| <= mu_k r_n,i + s r_n,i(x_{k-1}),  pattern rows,
     (s_k <= 0 since x_{k-1} is feasible with s = 0), until mu_k stalls
     (DINKELBACH_RTOL) — each mu_k is the max ratio of a verified point, an
     upper bound of mu^c to the verification tolerance (cones at rounding level are
     out of the ratio: plug3d 2 x 8, a stall 1.9e-7 below mu^c);
  3. polish: the KKT Newton certificate (kkt.py);
  4. if it fails: the polish from a sub-pattern's point (_polish_from_apex), steps 1-3
     under Clarabel's tight tolerances, then the default ones again from a start sought
     by bisection. A value no polish verifies is flagged (polished = False): the upper
     end of a bisection bracket, or the value of a verified point at which a cone sits
     at its apex with multipliers that cannot be signed, when the sub-pattern without
     that cone has the same certified value and Newton from the sub-pattern's point
     does not sign them either. That was once taken as certified; on
     plug3d 4 x 6 (mu = 1) all 36 such patterns, and one orbit of plug3d 2 x 8 (mu =
     2; 4 of its 5 agreed), have points lower (3.9e-7 .. 2.4e-9), which the tight
     route certifies.
Route "bisection": bisection on SOCP feasibility (mu_bracket.Probe: undecided counted
and taken as feasible) to mu_c_tol.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from hpcwedge.contact.problem import Parametrization
from hpcwedge.mu_c.bracket import BRACKET_RTOL, Probe, bisect
from hpcwedge.mu_c.kkt import APEX_RTOL, kkt_polish
from hpcwedge.parallel.cancel import task_tick
from hpcwedge.solvers.conic import ConicProblem
from hpcwedge.solvers.feasibility import Decision, pyramid_sides_for
from hpcwedge.solvers.rows import ConeRows, Status, count, pattern_rows
from hpcwedge.solvers.socp import attempts, pattern_socp

#: Dinkelbach stops when a step lowers mu by less than this (relative)
DINKELBACH_RTOL = 1e-7
DINKELBACH_MAX = 60
DINKELBACH_WEIGHT_FLOOR = 1e-2
#: where the polish from Dinkelbach's point fails, cones this small there (relative to
#: the largest) are taken as unloaded at mu^c, and the polish starts again from the
#: certified point of the sub-pattern without them (_polish_from_apex)
NEAR_APEX_RTOL = 1e-6


def mu_critical_3d(param: Parametrization, m: int, zero_u: np.ndarray, zero_r: np.ndarray, rows: ConeRows,
                   probe: Probe, mu_hi: float | None, mu_max: float, method: str,
                   tol: float) -> tuple[float | None, bool, np.ndarray | None]:
    """(mu^c, polished, x*) of the 3D pattern (zero_u, zero_r) whose rows are `rows` (module
    doc; mu^c None: infeasible at mu_max; x*: the polished point, else None)."""
    hi = float(mu_max if mu_hi is None else mu_hi)
    first = probe.decide(rows, hi)
    if first.status != Status.FEASIBLE and hi < mu_max:
        # mu_hi was not confirmed (a pattern taken as feasible there on a tolerance
        # or an undecided status): start from mu_max instead
        alt = probe.decide(rows, mu_max)
        if alt.status == Status.INFEASIBLE:
            return None, False, None
        if first.status == Status.INFEASIBLE or alt.status == Status.FEASIBLE:
            first, hi = alt, float(mu_max)
    if first.status == Status.INFEASIBLE:
        return None, False, None
    if method != "accurate":
        return bracket_3d(rows, hi, probe, tol, first), False, None
    zu, zr = np.asarray(zero_u, bool), np.asarray(zero_r, bool)
    if probe.options.tight:
        return _accurate_3d(param, m, zu, zr, rows, hi, first, probe, depth=0)
    out = _accurate_3d(param, m, zu, zr, rows, hi, first, probe, depth=0, seek=False)
    if out is not None and out[1]:
        return out
    retry, doubt = _tight_retry(param, m, zu, zr, rows, hi, probe)
    if retry is not None:
        return retry
    out = out or _accurate_3d(param, m, zu, zr, rows, hi, first, probe, depth=0)
    if not out[1]:
        probe.undecided += doubt
    return out


def _tight_retry(param, m, zu, zr, rows, hi, probe: Probe):
    """The accurate route under Clarabel's tight tolerances, tried when the default
    polish fails (an apex point settled by its sub-pattern included: module doc),
    before the default route seeks another start by bisection:
    ((mu^c, True, x*), 0) when its polish verifies, else (None, its undecided solves).
    Near a mu^c where many cones are active at once the default solves leave Dinkelbach
    ~1e-6 above mu^c, too far for Newton to find the active set, and the bisection took
    undecided solves as feasible: plug3d 3 x 10 at mu = 0.65, two orbits of patterns
    were left at 0.5960095 and 0.5336348 (30 of 601 patterns), whose certified values
    are 0.5960110 and 0.5336361 (points verified at mu^c (1 + 1e-7), infeasibility
    certificates below); on a third orbit the bisection's start polished, but took
    2.3 s where this route takes 0.05 s. Counted into `probe`: solves added, the
    retry's statuses as tight_*, mu_c_tight_retry and mu_c_tight_polished; a certified
    value's undecided solves are the retry's alone."""
    count(probe.statuses, "mu_c_tight_retry")
    tight = Probe(replace(probe.options, tolerances="tight"))
    first = tight.decide(rows, hi)
    out = None
    if first.status == Status.FEASIBLE:
        out = _accurate_3d(param, m, zu, zr, rows, hi, first, tight, depth=0)
    probe.solves += tight.solves
    for k, v in tight.statuses.items():
        count(probe.statuses, "tight_" + k, v)
    if out is None or not out[1]:
        return None, tight.undecided
    # the certified value owes nothing to the first attempt's undecided solves (its bracket
    # is dropped): only the retry's are the value's
    probe.undecided = tight.undecided
    count(probe.statuses, "mu_c_tight_polished")
    return out, 0


def _accurate_3d(param, m, zu, zr, rows, hi, first, probe: Probe, depth, seek=True):
    """(mu^c, polished, x*) of the pattern given a decision `first` that is not
    infeasible at hi: Dinkelbach + KKT polish; if the polish does not verify, None
    unless `seek`, else bisection to BRACKET_RTOL and again from the bracket's upper point (that
    bisection only seeks a start for Dinkelbach, whose result is then checked: its
    undecided points skip the pyramid levels too coarse to decide a point so near
    mu^c, feasibility.pyramid_sides_for; on plug3d 3 x 6 the full ladder there cost
    2 s of a 2.3 s task and decided nothing). A polished
    mu* proves that every point below it leaves the cones carrying the KKT
    multipliers unloaded: that sub-pattern (those nodes also gap) is then checked
    at mu*, and its own mu^c taken when it is feasible there."""
    pol = None
    x = first.x
    if x is not None:
        mu, x = dinkelbach(rows, x, hi, probe)
        if mu == 0.0:
            return 0.0, True, x
        pol = kkt_polish(rows, x, mu, options=probe.options) or _polish_from_apex(
            param, m, zu, zr, rows, x, hi, probe, depth)
    if pol is None and not seek:
        return None
    if pol is None:
        state = {"x": x}

        def ok(mu, spread):
            d = probe.decide(rows, mu, pyramid_sides_for(spread))
            if d.status != Status.INFEASIBLE:
                state["x"] = d.x if d.x is not None else state["x"]
                return True
            return False

        before, top = probe.undecided, hi
        lo, hi = bisect(ok, 0.0, hi, BRACKET_RTOL)
        x = state["x"]
        if x is not None:
            mu, x = dinkelbach(rows, x, hi, probe)
            pol = kkt_polish(rows, x, mu, options=probe.options) or _polish_from_apex(
                param, m, zu, zr, rows, x, hi, probe, depth)
        if pol is None:
            # that bisection took undecided and tolerance-feasible points as feasible to seek
            # a start: its upper end is no bound (random trusses: up to 9e-5 below mu^c)
            return _fallback_3d(rows, top, probe)
        # the polish certifies mu* whatever the start: the bisection's undecided solves,
        # taken as feasible to seek that start, decide nothing the value rests on
        if probe.undecided > before:
            count(probe.statuses, "mu_c_start_undecided", probe.undecided - before)
            probe.undecided = before
    return _settle(param, m, zu, zr, rows, hi, pol, probe, depth)


def _settle(param, m, zu, zr, rows, hi, pol, probe: Probe, depth):
    """(mu^c, polished, x*) from a polish `pol` (kkt_polish's answer) of the pattern: the
    sub-pattern with the multipliers' support unloaded is checked at mu* (below mu* no
    point loads those cones) and, if feasible there, solved recursively (_accurate_3d)."""
    mu_s, support, x_s, signed = pol
    if depth >= m:
        return mu_s, signed, x_s
    zr_sub = zr.copy()
    zr_sub[rows.nodes[support]] = True
    sub = pattern_rows(param, m, zu, zr_sub)
    d = probe.decide(sub, mu_s * (1 + 1e-12))
    if d.status == Status.INFEASIBLE:
        if signed:
            return mu_s, True, x_s
        return _fallback_3d(rows, hi, probe)
    mu_sub, polished_sub, x_sub = _accurate_3d(param, m, zu, zr_sub, sub, mu_s * (1 + 1e-12), d,
                                               probe, depth + 1)
    count(probe.statuses, "polish_support_recursions")
    if signed:
        return (mu_sub, polished_sub, x_sub) if mu_sub < mu_s else (mu_s, True, x_s)
    # unsigned apex point whose sub-pattern (apex cones unloaded) has the same value,
    # polished: a verified point, but no proof that none lies lower (one that loads an
    # apex cone did on every such pattern the tight route could settle: module doc), so
    # an upper bound, not polished, unless the polish from the sub-pattern's point signs
    count(probe.statuses, "polish_apex_by_subpattern")
    if polished_sub and abs(mu_sub - mu_s) <= 1e-10 * mu_s:
        # Newton from the sub-pattern's own point may still sign the multipliers
        again = kkt_polish(rows, x_sub, mu_sub, options=probe.options) if x_sub is not None else None
        if again is not None and again[3]:
            count(probe.statuses, "polish_apex_from_subpattern_point")
            return _settle(param, m, zu, zr, rows, hi, again, probe, depth + 1)
        return min(mu_s, mu_sub), False, x_s
    if mu_sub < mu_s:
        return mu_sub, False, x_sub
    return _fallback_3d(rows, hi, probe)


def _polish_from_apex(param, m, zu, zr, rows, x, hi, probe: Probe, depth):
    """kkt_polish of the pattern from its sub-pattern's polished point, where the polish
    from Dinkelbach's point x failed and x leaves some cones nearly unloaded (below
    NEAR_APEX_RTOL, not all): the mu^c of such a pattern is often reached only with those
    cones at their apex, where Dinkelbach's iterates stall (a cone whose r_n falls to
    rounding level is out of its ratio) and Newton from them finds no root. The sub-
    pattern (those nodes also gap) is solved without a start search; its point is only a
    start, so its undecided solves are counted as statuses, not against the value; the
    certificate is this pattern's own. plug3d 2 x 8 at mu = 2: 8 of 9,161 patterns were
    left at bisection brackets 1.82121-1.82123 (undecided solves taken as feasible),
    their certified mu^c is 1.8212335219. None when there is nothing to try or it fails."""
    if depth >= m:
        return None
    size = np.hypot(rows.rn @ x, np.linalg.norm(rows.rt @ x, axis=1))
    near = size <= NEAR_APEX_RTOL * size.max()
    if not near.any() or near.all():
        return None
    count(probe.statuses, "polish_from_apex")
    zr_sub = zr.copy()
    zr_sub[rows.nodes[near]] = True
    sub = pattern_rows(param, m, zu, zr_sub)
    child = Probe(probe.options)
    d = child.decide(sub, hi)
    out = None
    if d.status == Status.FEASIBLE:
        out = _accurate_3d(param, m, zu, zr_sub, sub, hi, d, child, depth + 1, seek=False)
    probe.solves += child.solves
    for k, v in child.statuses.items():
        count(probe.statuses, k, v)
    if child.undecided:
        count(probe.statuses, "polish_from_apex_undecided", child.undecided)
    if out is None or not out[1] or out[2] is None:
        return None
    pol = kkt_polish(rows, out[2], out[0], options=probe.options)
    if pol is not None:
        count(probe.statuses, "polish_from_apex_verified")
    return pol


def _fallback_3d(rows, hi, probe: Probe):
    """Bisection to BRACKET_RTOL: (upper end, False, None)."""
    count(probe.statuses, "mu_c_unpolished")
    return bracket_3d(rows, hi, probe, BRACKET_RTOL), False, None


def bracket_3d(rows: ConeRows, hi: float, probe: Probe, rtol: float, first: Decision | None = None) -> float:
    """An upper bound of the pattern's mu^c below hi (a mu known feasible), by bisection to
    rtol: the upper end moves only to the friction ratio max ||r_t|| / r_n (max_ratio) of a
    point shown feasible (Probe.below), at which that point is feasible, never to a mu merely
    not proven infeasible nor to a point's mu when its ratio lies above it (the point
    verifies to socp.VERIFY_TOL relative to all the reactions, which at a node carrying a
    small share of them allows a ratio well above mu: random trusses' brackets ended up to
    9e-5 below mu^c); it starts at the ratio of hi's own point (`first`: the decision at hi,
    if made already), which can lie above hi when hi was feasible only to that tolerance.
    The lower end is where no such point was found."""
    d = first if first is not None else probe.decide(rows, hi)
    if d.status == Status.FEASIBLE and d.x is not None and math.isfinite(ratio := max_ratio(rows, d.x)):
        hi = ratio               # hi itself may hold to the solver's tolerance only
    lo, top = 0.0, hi
    while hi - lo > rtol * hi and hi > 1e-12 * top:
        task_tick()
        mid = 0.5 * (lo + hi)
        d = probe.decide(rows, mid, pyramid_sides_for(0.5 * (hi - lo) / mid))
        ratio = max_ratio(rows, d.x) if d.status == Status.FEASIBLE and d.x is not None else math.inf
        if ratio < hi:
            hi, lo = ratio, min(lo, ratio)
        else:
            lo = mid
    return hi


def max_ratio(rows: ConeRows, x: np.ndarray) -> float:
    """max_i ||r_t,i|| / r_n,i over the cone nodes of x, cones at their apex
    (||r_i|| <= APEX_RTOL relative) left out; inf if some r_n,i <= 0 < ||r_t,i||."""
    rn = rows.rn @ x
    rt = np.linalg.norm(rows.rt @ x, axis=1)
    size = np.sqrt(rn ** 2 + rt ** 2)
    live = size > APEX_RTOL * max(size.max(), 1e-300)
    if not live.any():
        return 0.0
    rn, rt = rn[live], rt[live]
    if np.any(rn <= 0):
        return math.inf
    return float((rt / rn).max())


def dinkelbach(rows: ConeRows, x: np.ndarray, mu_hi: float, probe: Probe) -> tuple[float, np.ndarray]:
    """Scaled Dinkelbach iterations (module doc) from a feasible x: (mu, x) with
    mu = max_ratio(x) the least upper bound reached."""
    mu = max_ratio(rows, x)
    if not math.isfinite(mu):
        return mu_hi, x
    for _ in range(DINKELBACH_MAX):
        task_tick()
        if mu <= 0.0:
            return 0.0, x
        weights = np.maximum(rows.rn @ x, 0.0)
        weights /= max(weights.max(), 1e-300)
        # a floor: a cone nearly unloaded at x would otherwise barely move (its
        # ratio converges as slowly as its weight); a cone that must unload
        # completely to go lower is caught by the support recursion of the polish
        weights = np.maximum(weights, DINKELBACH_WEIGHT_FLOOR)
        y = _dinkelbach_step(rows, mu, weights, probe)
        if y is None:
            break
        mu_y = max_ratio(rows, y)
        if not mu_y < mu:
            break
        step = mu - mu_y
        mu, x = mu_y, y
        if step <= DINKELBACH_RTOL * mu:
            break
    return mu, x


def _dinkelbach_step(rows: ConeRows, mu: float, weights: np.ndarray, probe: Probe) -> np.ndarray | None:
    """argmin of min s s.t. (mu rn_i x + weights_i s, rt_i x) in SOC, pattern rows;
    None unless Clarabel solves it and x verifies on the non-friction rows."""
    base = pattern_socp(rows, mu)
    p = rows.Z.shape[1]
    col = np.zeros((base.A.shape[0], 1))
    first_cone = 1 + base.n_lin
    col[first_cone::3, 0] = -weights
    q = np.zeros(p + 1)
    q[-1] = 1.0
    problem = ConicProblem(np.hstack([base.A, col]), base.b, base.n_zero, base.n_lin, base.n_soc, q)
    for attempt, sol in attempts(problem, probe.options.tight):
        probe.solves += 1
        count(probe.statuses, ("dinkelbach_" if not attempt else f"dinkelbach_retry{attempt}_") + sol.name)
        if sol.status == Status.FEASIBLE:
            x = rows.Z @ sol.x[:p]
            nr = rows.norm @ x
            if nr > 0:
                x = x / nr
                lin_ok = rows.lin.shape[0] == 0 or (rows.lin @ x).min() >= -1e-9 * np.linalg.norm(x)
                if lin_ok:
                    return x
    return None
