"""mu^c of a pattern (cone) and the global mu^c, to 1e-9 relative (SPEC §2).

2D, route "accurate": bracket mu^c by bisection on LP feasibility to BRACKET_RTOL,
then polish: at mu^c the feasible set shrinks to a point x*, where the
constraints active at the LP vertex found just above mu^c, as a pencil
M(mu) = M0 + mu M1, lose rank. The generalised eigenvalues of a random square
compression of that pencil that lie in the bracket, whose null vector is
feasible (checked on every row to POLISH_TOL), are candidates; the least one
is mu^c. If no candidate verifies, the bracket's upper end is returned and
the result is flagged (polished = False).

Route "bisection": plain bisection to the scene's mu_c_tol (relative), the
upper end of the bracket returned (benchmarks).

3D, route "accurate" (mu^c = min over the pattern's x of max_i ||r_t,i|| / r_n,i,
a generalised fractional program):
  1. a feasible x at mu_hi (one SOCP);
  2. Dinkelbach iterations in the scaled form of Crouzeix, Ferland and
     Schaible: mu_k = max_i ||r_t,i(x_{k-1})|| / r_n,i(x_{k-1}); x_k solves the SOCP
         min s  s.t.  ||r_t,i|| <= mu_k r_n,i + s r_n,i(x_{k-1}),  pattern rows,
     (s_k <= 0 since x_{k-1} is feasible with s = 0), until mu_k stalls
     (DINKELBACH_RTOL) — each mu_k is the max ratio of a verified point, an
     upper bound of mu^c;
  3. polish: Newton's method on the KKT system of min mu over the active set
     read off x_k (smooth cones ||r_t,i|| = mu r_n,i, cones at their apex r_i = 0,
     active u_n >= 0 rows, sum r_n = 1), with the multipliers started by least
     squares. The result is accepted when the point satisfies every row of the
     pattern to POLISH3_TOL and the multipliers have the right signs (λ >= 0 on
     the cones, >= 0 on the u_n rows, apex multipliers in the dual cone): then
     it is a certificate that no point exists below mu* (convexity at fixed mu),
     and mu* is exact to rounding. Otherwise the Dinkelbach bound is returned,
     flagged (polished = False).
3D, route "bisection": bisection on SOCP feasibility (conic.decide, undecided
counted and taken as feasible) to mu_c_tol.

Every iteration calls parallel.task_tick(): inside an engine task a SIGTERM (or the
master's stop) cancels the computation within one solve; the task is redone on resume.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import math

import numpy as np
import scipy.linalg as sla

from .feasibility import DEFAULT_OPTIONS, PYRAMID_SIDES, SolverOptions, count, decide, pyramid_sides_for
from .rows import ConeRows, Rows, Status, pattern_rows, problem_dim
from .socp import ConicProblem, attempts, pattern_socp, solve, violation
from .parallel import task_tick
from .problem import Parametrization, balanced_2d

BRACKET_RTOL = 1e-7
POLISH_TOL = 1e-9
#: 2D with a scale: mu^c is recomputed in coordinates balanced at it when it lies below
#: mu_hi / REBALANCE (the first coordinates were balanced at mu_hi)
REBALANCE = 10.0
#: ... starting from the bracket mu^c (1 -/+ this) around the first value
REBALANCE_BRACKET = 1e-6
#: slack thresholds of the active sets tried after those scaled to the bracket width
POLISH_WIDE_TAUS = (1e-5, 1e-3, 1e-2)
#: 3D: Dinkelbach stops when a step lowers mu by less than this (relative)
DINKELBACH_RTOL = 1e-7
DINKELBACH_MAX = 60
DINKELBACH_WEIGHT_FLOOR = 1e-2
#: 3D: the polished point must satisfy every row to this (relative to ||x||)
POLISH3_TOL = 1e-12
#: 3D: a cone whose ||r_i|| is below this (relative) is at its apex in the ratio
APEX_RTOL = 1e-8
#: 3D: a multiplier above -SIGN_RTOL * (largest) counts as signed. At a degenerate
#: optimum (a cone active with a zero multiplier) the multipliers are ill-determined;
#: measured down to -4e-7 relative on plug3d 3x4 where the active set was right
SIGN_RTOL = 1e-6


@dataclass
class MuC:
    """mu_c: float or None (infeasible up to mu_max); polished: the pencil (2D) or
    KKT (3D) step verified; lps: LP/SOCP solves; undecided: statuses that decided
    nothing; statuses: how each solve was decided (conic counts)."""

    mu_c: float | None
    polished: bool = False
    lps: int = 0
    undecided: int = 0
    statuses: dict = field(default_factory=dict)
    x: np.ndarray | None = None          # 3D polished: the point at mu^c (x-space, sum r_n = 1)


def mu_critical(param: Parametrization, m: int, zero_u: np.ndarray, zero_r: np.ndarray,
                mu_hi: float | None = None, mu_max: float = 100.0,
                method: str = "accurate", tol: float = 1e-6, scale: float | None = None,
                options: SolverOptions = DEFAULT_OPTIONS) -> MuC:
    """Least mu at which the pattern (zero_u, zero_r) admits a solution with r != 0.

    mu_hi: a mu known feasible (e.g. the run's mu for a cone found there); else
    mu_max is tested first. Returns MuC(None) when infeasible at mu_max.
    scale (2D): the stiffness that weighs u_n against r (numerics.Numerics.scale). The
    LPs then run in the balanced coordinates of problem.balanced_2d at mu_hi, and once
    more at the mu^c found when it lies below mu_hi / REBALANCE (scripts/stress.py: plug2d
    at 0.1 deg, mu^c to 3e-13 instead of 8e-9 relative).
    """
    if problem_dim(param, m) == 3 or scale is None:
        rows = pattern_rows(param, m, zero_u, zero_r)
        if isinstance(rows, ConeRows):
            return _mu_critical_3d(param, m, zero_u, zero_r, mu_hi, mu_max, method, tol, MuC(None), options)
        return mu_critical_rows(rows, mu_hi, mu_max, method, tol, options=options)

    def solve(ref: float, hi: float | None, lo: float | None = None) -> MuC:
        return mu_critical_rows(pattern_rows(balanced_2d(param, ref, m, scale)[0], m, zero_u, zero_r),
                                hi, mu_max, method, tol, mu_lo=lo, options=options)

    ref = mu_max if mu_hi is None else mu_hi
    out = solve(ref, mu_hi)
    if out.mu_c is None or method != "accurate" or out.mu_c * REBALANCE > ref:
        return out
    again = solve(out.mu_c, out.mu_c * (1 + REBALANCE_BRACKET), out.mu_c * (1 - REBALANCE_BRACKET))
    again.lps += out.lps
    again.undecided += out.undecided
    for k, v in out.statuses.items():
        again.statuses[k] = again.statuses.get(k, 0) + v
    return again if again.mu_c is not None and (again.polished or not out.polished) else out


def mu_critical_rows(rows: Rows, mu_hi: float | None = None, mu_max: float = 100.0,
                     method: str = "accurate", tol: float = 1e-6, out: MuC | None = None,
                     mu_lo: float | None = None, options: SolverOptions = DEFAULT_OPTIONS) -> MuC:
    """mu^c of an LP pattern problem given by its rows (2D patterns; also any
    polyhedral problem of the same form, e.g. a 3D pattern with pyramids).
    mu_lo: a guess of an infeasible mu below mu^c; the bisection starts from it when an
    LP confirms it (else from 0)."""
    out = MuC(None) if out is None else out

    def feasible_at(mu: float):
        out.lps += 1
        d = decide(rows, mu, options, out.statuses)
        status, x = d.status, d.x
        if status not in (Status.FEASIBLE, Status.INFEASIBLE):
            out.undecided += 1       # conservative: treat as feasible (keeps the bracket valid above)
        return status != Status.INFEASIBLE, x

    if mu_hi is None:
        ok, _ = feasible_at(mu_max)
        if not ok:
            return out
        mu_hi = mu_max
    lo, hi = 0.0, float(mu_hi)
    if mu_lo is not None and not feasible_at(mu_lo)[0]:
        lo = mu_lo
    rtol = BRACKET_RTOL if method == "accurate" else tol
    x_hi = None
    while hi - lo > rtol * hi and hi > 1e-12 * mu_hi:
        task_tick()
        mid = 0.5 * (lo + hi)
        ok, x = feasible_at(mid)
        if ok:
            hi, x_hi = mid, x
        else:
            lo = mid
    out.mu_c = hi
    if method != "accurate":
        return out
    if x_hi is None:
        ok, x_hi = feasible_at(hi)
    if x_hi is not None:
        mu = polish(rows, x_hi, lo, hi)
        if mu is not None:
            out.mu_c, out.polished = mu, True
    return out


def polish(rows: Rows, x: np.ndarray, lo: float, hi: float, seed: int = 0) -> float | None:
    """Exact root of the active-set pencil inside [lo, hi] (see module doc), or None."""
    unit = _unit_rows(rows, hi)
    slack = (unit @ x) / max(np.linalg.norm(x), 1e-300)
    width = max(hi - lo, 1e-300) / max(hi, 1e-300)
    rng = np.random.default_rng(seed)
    pad = 2 * (hi - lo) + 1e-5 * hi    # the LP feasibility tolerance can put the bracket ~1e-7 low
    # active sets by slack; the wide ones catch an ill-conditioned vertex whose active
    # rows at x_hi have slacks far above the bracket width (random free bodies: 3e-4 at
    # width 1e-7); a wrong active set has no verified root
    wide = tuple(t for t in POLISH_WIDE_TAUS if t > 10 * width)
    for tau in (10 * width, width, 1e-3 * width) + wide:
        task_tick()
        act = rows.eq | (np.abs(slack) <= tau)
        sc = np.linalg.norm(rows.a0[act], axis=1) + hi * np.linalg.norm(rows.a1[act], axis=1)
        sc[sc == 0] = 1.0
        M0, M1 = rows.a0[act] / sc[:, None], rows.a1[act] / sc[:, None]
        if M0.shape[0] < M0.shape[1]:
            continue             # fewer than d rows always have a null vector: no root to find
        G = rng.standard_normal((M0.shape[1], M0.shape[0]))
        try:
            lam = sla.eigvals(G @ M0, -(G @ M1))
        except (np.linalg.LinAlgError, ValueError):
            continue
        lam = lam[np.isfinite(lam)]
        lam = np.sort(lam[np.abs(lam.imag) <= 1e-8 * np.abs(lam.real) + 1e-14].real)
        for mu in lam[(lam >= lo - pad) & (lam <= hi + pad)]:
            if _verified(rows, act, float(mu)):
                return float(mu)
    return None


def _unit_rows(rows: Rows, mu: float) -> np.ndarray:
    """Rows at mu divided by ||a0|| + mu ||a1|| (not by their norm at mu, which
    vanishes for a friction row that is identically tight at mu^c)."""
    A = rows.a0 + mu * rows.a1
    scale = np.linalg.norm(rows.a0, axis=1) + abs(mu) * np.linalg.norm(rows.a1, axis=1)
    scale[scale == 0] = 1.0
    return A / scale[:, None]


def _verified(rows: Rows, act: np.ndarray, mu: float) -> bool:
    """The active rows at mu have a null vector (relative singular value <= POLISH_TOL)
    that, scaled to sum(r_n) = 1, satisfies every row to POLISH_TOL."""
    unit = _unit_rows(rows, mu)
    _, s, vt = np.linalg.svd(unit[act])
    if len(s) >= vt.shape[0] and s[-1] > POLISH_TOL * s[0]:
        return False
    x = vt[-1]
    nr = rows.norm @ x
    if abs(nr) < 1e-12 * np.linalg.norm(rows.norm):
        return False
    x = x / nr
    vals = unit @ x / np.linalg.norm(x)
    return bool(np.all(np.abs(vals[rows.eq]) <= POLISH_TOL) and np.all(vals[~rows.eq] >= -POLISH_TOL))


# ------------------------------------------------------------------------ 3D
def _mu_critical_3d(param: Parametrization, m: int, zero_u: np.ndarray, zero_r: np.ndarray,
                    mu_hi: float | None, mu_max: float, method: str, tol: float, out: MuC,
                    options: SolverOptions) -> MuC:
    """mu^c of a 3D pattern (module doc, 3D routes)."""
    rows = pattern_rows(param, m, zero_u, zero_r)

    def feasible_at(rows, mu: float, sides: tuple[int, ...] = PYRAMID_SIDES):
        out.lps += 1
        d = decide(rows, mu, options, out.statuses, pyramid_sides=sides)
        if d.status == Status.UNDECIDED:
            out.undecided += 1       # conservative: taken as feasible
        return d

    hi = float(mu_max if mu_hi is None else mu_hi)
    first = feasible_at(rows, hi)
    if first.status != Status.FEASIBLE and hi < mu_max:
        # mu_hi was not confirmed (a pattern taken as feasible there on a tolerance
        # or an undecided status): start from mu_max instead
        alt = feasible_at(rows, mu_max)
        if alt.status == Status.INFEASIBLE:
            return out
        if first.status == Status.INFEASIBLE or alt.status == Status.FEASIBLE:
            first, hi = alt, float(mu_max)
    if first.status == Status.INFEASIBLE:
        return out
    if method != "accurate":
        out.mu_c = _bisect(lambda mu, _: feasible_at(rows, mu).status != Status.INFEASIBLE, 0.0, hi, tol)[1]
        return out
    mu, polished, x = _accurate_3d(param, m, np.asarray(zero_u, bool), np.asarray(zero_r, bool), rows,
                                   hi, first, feasible_at, out, depth=0, options=options)
    out.mu_c, out.polished, out.x = mu, polished, x
    return out


def _bisect(ok, lo: float, hi: float, rtol: float) -> tuple[float, float]:
    """Shrink [lo, hi] (ok(hi) true) until hi - lo <= rtol * hi; (lo, hi).
    ok(mid, spread): spread = (hi - lo) / (2 mid), how near mid lies to the bracket's ends."""
    top = hi
    while hi - lo > rtol * hi and hi > 1e-12 * top:
        task_tick()
        mid = 0.5 * (lo + hi)
        if ok(mid, 0.5 * (hi - lo) / mid):
            hi = mid
        else:
            lo = mid
    return lo, hi


def _accurate_3d(param, m, zu, zr, rows, hi, first, feasible_at, out, depth, options):
    """(mu^c, polished) of the pattern given a decision `first` that is not
    infeasible at hi: Dinkelbach + KKT polish; if the polish does not verify,
    bisection to BRACKET_RTOL and again from the bracket's upper point (that
    bisection only seeks a start for Dinkelbach, whose result is then checked: its
    undecided points skip the pyramid levels too coarse to decide a point so near
    mu^c, conic.pyramid_sides_for; on plug3d 3 x 6 the full ladder there cost
    2 s of a 2.3 s task and decided nothing). A polished
    mu* proves that every point below it leaves the cones carrying the KKT
    multipliers unloaded: that sub-pattern (those nodes also gap) is then checked
    at mu*, and its own mu^c taken when it is feasible there."""
    pol = None
    x = first.x
    if x is not None:
        mu, x = dinkelbach(rows, x, hi, out, options)
        if mu == 0.0:
            return 0.0, True, x
        pol = kkt_polish(rows, x, mu, options=options)
    if pol is None:
        state = {"x": x}

        def ok(mu, spread):
            d = feasible_at(rows, mu, pyramid_sides_for(spread))
            if d.status != Status.INFEASIBLE:
                state["x"] = d.x if d.x is not None else state["x"]
                return True
            return False

        lo, hi = _bisect(ok, 0.0, hi, BRACKET_RTOL)
        x = state["x"]
        if x is None:
            return hi, False, None
        mu, x = dinkelbach(rows, x, hi, out, options)
        pol = kkt_polish(rows, x, mu, options=options)
        if pol is None:
            return hi, False, None
    mu_s, support, x_s, signed = pol
    if depth >= m:
        return mu_s, signed, x_s
    zr_sub = zr.copy()
    zr_sub[rows.nodes[support]] = True
    sub = pattern_rows(param, m, zu, zr_sub)
    d = feasible_at(sub, mu_s * (1 + 1e-12))
    if d.status == Status.INFEASIBLE:
        if signed:
            return mu_s, True, x_s
        return _fallback_3d(rows, hi, feasible_at, out)
    mu_sub, polished_sub, x_sub = _accurate_3d(param, m, zu, zr_sub, sub, mu_s * (1 + 1e-12), d,
                                               feasible_at, out, depth + 1, options)
    count(out.statuses, "polish_support_recursions")
    if signed:
        return (mu_sub, polished_sub, x_sub) if mu_sub < mu_s else (mu_s, True, x_s)
    # unsigned apex point: accepted when the sub-pattern (apex cones unloaded) has
    # the same value, polished
    count(out.statuses, "polish_apex_by_subpattern")
    if polished_sub and abs(mu_sub - mu_s) <= 1e-10 * mu_s:
        return min(mu_s, mu_sub), True, x_s
    if mu_sub < mu_s:
        return mu_sub, False, x_sub
    return _fallback_3d(rows, hi, feasible_at, out)


def _fallback_3d(rows, hi, feasible_at, out):
    """Bisection to BRACKET_RTOL: (upper end, False, None)."""
    count(out.statuses, "mu_c_unpolished")
    lo, hi = _bisect(lambda mu, _: feasible_at(rows, mu).status != Status.INFEASIBLE, 0.0, hi, BRACKET_RTOL)
    return hi, False, None


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


def dinkelbach(rows: ConeRows, x: np.ndarray, mu_hi: float, out: MuC,
               options: SolverOptions = DEFAULT_OPTIONS) -> tuple[float, np.ndarray]:
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
        y = _dinkelbach_step(rows, mu, weights, out, options)
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


def _dinkelbach_step(rows: ConeRows, mu: float, weights: np.ndarray, out: MuC,
                     options: SolverOptions) -> np.ndarray | None:
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
    for attempt, sol in attempts(problem, options.tight):
        out.lps += 1
        count(out.statuses, ("dinkelbach_" if not attempt else f"dinkelbach_retry{attempt}_") + sol.status)
        if sol.status == "Solved":
            x = rows.Z @ sol.x[:p]
            nr = rows.norm @ x
            if nr > 0:
                x = x / nr
                lin_ok = rows.lin.shape[0] == 0 or (rows.lin @ x).min() >= -1e-9 * np.linalg.norm(x)
                if lin_ok:
                    return x
    return None


def kkt_polish(rows: ConeRows, x: np.ndarray, mu: float,
               taus: tuple[float, ...] = (1e-6, 1e-4, 1e-8, 1e-3, 1e-2),
               options: SolverOptions = DEFAULT_OPTIONS) -> tuple | None:
    """Newton's method on the KKT system of min mu over the active set at x (module
    doc): (mu*, support, x*, True) verified, or None. support: the cone nodes (indices
    into rows.nodes) with a positive multiplier — below mu* no point loads any of them.
    (mu*, apex nodes, x*, False): a converged point with cones at their apex whose
    multipliers could not be signed (at an apex the constraint qualification can
    fail, and KKT multipliers need not exist at a minimum); the caller settles it
    through the sub-pattern with those nodes unloaded."""
    Z = rows.Z
    w0 = Z.T @ x
    a = rows.rn @ Z                     # (c, p)
    T = rows.rt @ Z                     # (c, 2, p)
    L = rows.lin @ Z                    # (l, p)
    nrm = rows.norm @ Z                 # (p,)
    size = np.linalg.norm(w0)
    rn, rtv = a @ w0, T @ w0
    rt = np.linalg.norm(rtv, axis=1)
    rsize = np.sqrt(rn ** 2 + rt ** 2)
    tried = set()
    unsigned = None
    for tau, apex_tau in [(t, at) for t in taus for at in (APEX_RTOL, t)]:
        task_tick()
        apex = rsize <= apex_tau * max(rsize.max(), 1e-300)
        smooth = ~apex & (rt - mu * rn >= -tau * (mu * np.abs(rn) + rt))
        lin = (L @ w0 <= tau * size) if L.shape[0] else np.zeros(0, bool)
        S, Ap, Lin = np.flatnonzero(smooth), np.flatnonzero(apex), np.flatnonzero(lin)
        # active-set steps: rows whose multiplier came out with the wrong sign (weakly
        # active, degenerate) are dropped and the system solved again; the primal
        # check of every row then tells whether dropping them was right
        for _ in range(len(S) + len(Lin)):
            key = (tuple(S), tuple(Ap), tuple(Lin))
            if key in tried or not len(S):
                break
            tried.add(key)
            # only the span V of the active rows matters to the active system: solve in
            # w = w_perp + V c (elsewhere the Jacobian is singular along every direction
            # that moves only inactive rows)
            act = np.vstack([a[S], T[S].reshape(-1, a.shape[1]), a[Ap], T[Ap].reshape(-1, a.shape[1]),
                             L[Lin], nrm[None, :]])
            _, sv, vt = np.linalg.svd(act, full_matrices=False)
            V = vt[:int((sv > 1e-12 * sv[0]).sum())].T
            w_perp = w0 - V @ (V.T @ w0)
            res = _kkt_newton(a @ V, T @ V, L @ V, nrm @ V, V.T @ w0, mu, S, Ap, Lin, options)
            if res is None:
                break
            c, mu_s, support, signed, drop_s, drop_l = res
            w = w_perp + V @ c
            ok = violation(rows, mu_s, Z @ w) <= POLISH3_TOL
            if ok and signed:
                return mu_s, support, Z @ w, True
            if ok and len(Ap) and unsigned is None:
                unsigned = (mu_s, support, Z @ w, False)
            if not (len(drop_s) or len(drop_l)):
                break
            S, Lin = np.setdiff1d(S, drop_s), np.setdiff1d(Lin, drop_l)
    return unsigned


def _kkt_newton(a, T, L, nrm, w0, mu0, S, Ap, Lin, options, iters: int = 40):
    """Newton on F(w, mu, lam, gam, eta) = 0 (see kkt_polish); (w, mu) when it
    converges with multipliers of the right signs, else None."""
    p = len(w0)
    E = np.vstack([a[Ap], T[Ap, 0], T[Ap, 1], L[Lin]]) if (len(Ap) or len(Lin)) else np.zeros((0, p))
    nS, nE = len(S), E.shape[0]
    nA = len(Ap)

    def parts(w, mu):
        Tw = np.einsum("ckp,p->ck", T[S], w)
        nt = np.linalg.norm(Tw, axis=1)
        t = Tw / nt[:, None]
        G = np.einsum("ckp,ck->cp", T[S], t) - mu * a[S]          # gradients of g_i (nS, p)
        return Tw, nt, t, G

    def residual(w, mu, lam, gam, eta):
        Tw, nt, t, G = parts(w, mu)
        F1 = G.T @ lam + E.T @ gam + eta * nrm
        F2 = 1.0 - lam @ (a[S] @ w)
        F3 = nt - mu * (a[S] @ w)
        F4 = E @ w
        F5 = nrm @ w - 1.0
        return np.concatenate([F1, [F2], F3, F4, [F5]])

    w, mu = w0 / (nrm @ w0), mu0
    Tw, nt, t, G = parts(w, mu)
    if np.any(nt <= 0):
        return None
    # multipliers by least squares from stationarity
    M = np.zeros((p + 1, nS + nE + 1))
    M[:p, :nS] = G.T
    M[:p, nS:nS + nE] = E.T
    M[:p, -1] = nrm
    M[p, :nS] = a[S] @ w
    rhs = np.zeros(p + 1)
    rhs[p] = 1.0
    # sum lam_i r_n,i = 1 as a (heavily weighted) hard row: at a degenerate optimum
    # the cone gradients nearly vanish and plain least squares would shrink lam to 0
    M[p] *= 1e8
    rhs[p] *= 1e8
    y = np.linalg.lstsq(M, rhs, rcond=None)[0]
    lam, gam, eta = y[:nS], y[nS:nS + nE], y[-1]
    n = p + 1 + nS + nE + 1
    F = residual(w, mu, lam, gam, eta)
    for _ in range(iters):
        Tw, nt, t, G = parts(w, mu)
        if np.any(nt <= 0):
            return None
        J = np.zeros((n, n))
        iw, imu, il, ig, ie = slice(0, p), p, slice(p + 1, p + 1 + nS), slice(p + 1 + nS, p + 1 + nS + nE), n - 1
        H = np.zeros((p, p))
        for k, i in enumerate(S):
            P = np.eye(2) - np.outer(t[k], t[k])
            H += lam[k] * (T[i].T @ P @ T[i]) / nt[k]
        J[iw, iw] = H
        J[iw, imu] = -(a[S].T @ lam)
        J[iw, il] = G.T
        J[iw, ig] = E.T
        J[iw, ie] = nrm
        r2 = p                                   # row of F2
        J[r2, iw] = -(a[S].T @ lam)
        J[r2, il] = -(a[S] @ w)
        r3 = slice(p + 1, p + 1 + nS)
        J[r3, iw] = G
        J[r3, imu] = -(a[S] @ w)
        r4 = slice(p + 1 + nS, p + 1 + nS + nE)
        J[r4, iw] = E
        J[n - 1, iw] = nrm
        # Levenberg-Marquardt with nu = ||F|| (Yamashita & Fukushima): a descent step
        # even where the system is singular (minimisers of the ratio not isolated),
        # quadratic convergence under a local error bound
        f0 = np.linalg.norm(F)
        JtJ, JtF = J.T @ J, J.T @ F
        nu = min(f0, 1.0)
        for trial in range(31):
            if trial == 0:            # the plain Newton (least-squares) step first
                step = np.linalg.lstsq(J, -F, rcond=None)[0]
            else:
                try:
                    step = np.linalg.solve(JtJ + nu * np.eye(n), -JtF)
                except np.linalg.LinAlgError:
                    break
                nu *= 10.0
            w1, mu1 = w + step[iw], mu + step[imu]
            lam1, gam1, eta1 = lam + step[il], gam + step[ig], eta + step[ie]
            if np.all(np.linalg.norm(np.einsum("ckp,p->ck", T[S], w1), axis=1) > 0):
                F_new = residual(w1, mu1, lam1, gam1, eta1)
                if np.linalg.norm(F_new) < (0.5 if trial == 0 else 1.0) * f0:
                    break
        else:
            break
        w, mu, lam, gam, eta = w1, mu1, lam1, gam1, eta1
        done = np.abs(F_new).max() <= 1e-14 * max(1.0, np.abs(lam).max(), abs(mu))
        small = np.abs(step).max() <= 1e-15 * max(1.0, np.abs(w).max(), abs(mu))
        F = F_new
        if done or small:
            break
    if np.abs(F).max() > 1e-11 * max(1.0, np.abs(lam).max(), abs(mu)) or not np.isfinite(mu) or mu <= 0:
        return None
    # signs: cones lam >= 0; u_n rows: constraint L w >= 0 enters as E^T gam with gam <= 0;
    # apex: (gam_a, gam_t) = -(mu zeta_0, zeta_t) with zeta in the second-order cone
    support = _signed_support(lam, gam, S, Ap, nA, len(Lin), mu)
    if support is None:
        # multipliers are not unique where the active rows are dependent: look for
        # signed ones at the converged point (a small conic feasibility problem)
        Tw, nt, t, G = parts(w, mu)
        y = _signed_multipliers(G, a[S] @ w, E, nrm, nA, len(Lin), mu, options)
        if y is not None:
            support = _signed_support(y[0], y[1], S, Ap, nA, len(Lin), mu)
        if support is None:
            return w, float(mu), np.asarray(Ap, dtype=int), False, S[lam < 0], Lin[gam[3 * nA:] > 0]
    return w, float(mu), support, True, S[:0], Lin[:0]


def _signed_support(lam, gam, S, Ap, nA, nL, mu, rtol: float = SIGN_RTOL):
    """The support of the multipliers (cone nodes with lam > 0, apex nodes with
    zeta_0 > 0) when all signs are right (to rtol of their size), else None."""
    scale = max(np.abs(lam).max() if len(lam) else 0.0, np.abs(gam).max() if len(gam) else 0.0, 1e-300)
    tol = rtol * scale
    if len(lam) and lam.min() < -tol:
        return None
    if nL and gam[3 * nA:].max() > tol:
        return None
    support = list(S[lam > tol])
    if nA:
        z0 = -gam[:nA] / mu
        zt = -np.stack([gam[nA:2 * nA], gam[2 * nA:3 * nA]], axis=1)
        if np.any(np.linalg.norm(zt, axis=1) - z0 > tol):
            return None
        support += list(Ap[z0 > tol])
    return np.array(sorted(support), dtype=int)


def _signed_multipliers(G, rn, E, nrm, nA, nL, mu, options):
    """Multipliers (lam >= 0, gam) with G^T lam + E^T gam + eta nrm = 0 and
    lam . rn = 1, gam's u_n part <= 0, apex parts -(mu zeta_0, zeta_t), zeta in the
    second-order cone; found by Clarabel, accepted when the equations hold to
    1e-10 relative. None if there are none."""
    nS, p = G.shape
    nE = E.shape[0]
    # variables v = [lam (nS), nu (nL) >= 0, zeta (3 nA), eta]; gam = [-mu z0, -z1, -z2, -nu]
    nv = nS + nL + 3 * nA + 1
    Mg = np.zeros((p, nv))
    Mg[:, :nS] = G.T
    Ea, E1, E2, EL = E[:nA], E[nA:2 * nA], E[2 * nA:3 * nA], E[3 * nA:]
    Mg[:, nS:nS + nL] = -EL.T
    for k in range(nA):
        c = nS + nL + 3 * k
        Mg[:, c] = -mu * Ea[k]
        Mg[:, c + 1] = -E1[k]
        Mg[:, c + 2] = -E2[k]
    Mg[:, -1] = nrm
    row = np.zeros(nv)
    row[:nS] = rn
    Aeq = np.vstack([Mg, row[None, :]])
    beq = np.zeros(p + 1)
    beq[-1] = 1.0
    # cones: zero (p + 1) | lam, nu >= 0 | zeta in SOC(3)
    sel = np.zeros((nS + nL + 3 * nA, nv))
    sel[:nS + nL, :nS + nL] = -np.eye(nS + nL)
    for k in range(nA):
        c = nS + nL + 3 * k
        sel[nS + nL + 3 * k:nS + nL + 3 * k + 3, c:c + 3] = -np.eye(3)
    A = np.vstack([Aeq, sel])
    b = np.concatenate([beq, np.zeros(sel.shape[0])])
    sol = solve(ConicProblem(A, b, p + 1, nS + nL, nA), 0, options.tight)
    if sol.status != "Solved":
        return None
    v = sol.x
    if np.abs(Aeq @ v - beq).max() > 1e-10 * max(1.0, np.abs(v).max()):
        return None
    lam = v[:nS]
    nu = v[nS:nS + nL]
    z = v[nS + nL:nS + nL + 3 * nA].reshape(nA, 3)
    gam = np.concatenate([-mu * z[:, 0], -z[:, 1], -z[:, 2], -nu])
    return lam, gam
