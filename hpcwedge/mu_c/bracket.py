"""Bracketing mu^c by bisection on feasibility (2D and 3D), and the 2D route.

Every decision of a mu^c computation goes through a `Probe`: it counts the solves and
takes an undecided status as feasible (conservative: the bracket stays valid above).

2D, route "accurate": bracket mu^c to BRACKET_RTOL (Dinkelbach steps from above, then a
bisection on LP feasibility where they leave a gap), then polish: at mu^c the feasible set
shrinks to a point x*, where the constraints active at the LP vertex found just above mu^c,
as a pencil
M(mu) = M0 + mu M1, lose rank. The generalised eigenvalues of a random square
compression of that pencil that lie in the bracket, whose null vector is
feasible (checked on every row to POLISH_TOL), are candidates; the least one
is mu^c. If no candidate verifies, the bracket's upper end is returned and
the result is flagged (polished = False).

Route "bisection": plain bisection to the scene's mu_c_tol (relative), the
upper end of the bracket returned (benchmarks).
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from hpcwedge.dense import dense_call
from hpcwedge.parallel.cancel import task_tick
from hpcwedge.solvers.feasibility import DEFAULT_OPTIONS, PYRAMID_SIDES, Decision, SolverOptions, decide
from hpcwedge.solvers.pattern_lp import PatternLp, point_holds, ratio
from hpcwedge.solvers.rows import ConeRows, Rows, Status, count

BRACKET_RTOL = 1e-7
#: Dinkelbach steps (dinkelbach_hi) before the bisection, at most
DINKELBACH_STEPS = 30
POLISH_TOL = 1e-9
#: slack thresholds of the active sets tried after those scaled to the bracket width
POLISH_WIDE_TAUS = (1e-5, 1e-3, 1e-2)
#: pencils of more columns than this get their roots near the bracket by shift-invert
#: Arnoldi (`near_roots`) instead of all of them by the QZ algorithm (plug2d m = 640, 1,283
#: columns: 9.7 s for QZ)
POLISH_DENSE_MAX = 400
#: near_roots: eigenvalues asked first, and at most (then QZ)
NEAR_ROOTS_K = (6, 48)
#: bracket_2d: relative steps above a guess proven infeasible (mu_try) asked in turn before
#: mu_max, so that the upper end starts near mu^c (block2d m = 320, all contact: Dinkelbach's 30
#: steps from mu_max = 100 reached 9.6 in 18 s; from 1.01 mu_try the bracket is 1 % wide)
TRY_LADDER = (1e-3, 1e-2, 1e-1, 1.0)


class Probe:
    """The feasibility decisions of one mu^c computation, counted: solves (LP/SOCP solves,
    Dinkelbach's steps included), undecided (decisions taken as feasible), statuses
    (feasibility.decide's counts, and the mu^c routes' own), under `options`."""

    def __init__(self, options: SolverOptions = DEFAULT_OPTIONS):
        self.options = options
        self.solves = 0
        self.undecided = 0
        self.statuses: dict = {}

    def decide(self, rows: Rows | ConeRows, mu: float, sides: tuple[int, ...] = PYRAMID_SIDES,
               warm: PatternLp | None = None) -> Decision:
        """feasibility.decide at mu (sides: its pyramid levels), counted; with `warm` (the
        rows' PatternLp, 0 < mu < inf) its answer first, decide where it proves nothing."""
        self.solves += 1
        if warm is not None and 0.0 < mu < np.inf:
            status, x = warm.solve(mu, self.statuses)
            if status != Status.UNDECIDED:
                return Decision(status, x)
        d = decide(rows, mu, self.options, self.statuses, pyramid_sides=sides)
        if d.status == Status.UNDECIDED:
            self.undecided += 1
        return d

    def feasible(self, rows: Rows | ConeRows, mu: float, warm: PatternLp | None = None) -> bool:
        """Not proven infeasible at mu (undecided counts as feasible): whether a pattern has a
        mu^c below mu_max at all, which nothing but a proof rules out."""
        return self.decide(rows, mu, warm=warm).status != Status.INFEASIBLE


def bisect(ok, lo: float, hi: float, rtol: float) -> tuple[float, float]:
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


def bracket_2d(rows: Rows, probe: Probe, mu_hi: float | None = None, mu_max: float = 100.0,
               method: str = "accurate", tol: float = 1e-6, mu_lo: float | None = None,
               mu_floor: float | None = None, mu_try: float | None = None,
               x_try: np.ndarray | None = None) -> tuple[float | None, bool]:
    """(mu^c, polished) of an LP pattern problem given by its rows (module doc; mu^c None:
    infeasible at mu_max). mu_lo: a guess of an infeasible mu below mu^c; the bisection
    starts from it when an LP confirms it (else from 0). mu_floor: a mu proven infeasible
    another way (a certificate: lower_bound.py), taken as the lower end unchecked. mu_try: a
    guess of a feasible mu just above mu^c, asked first (below mu_hi): feasible, it is the
    upper end; proven infeasible, the lower end, and (without mu_hi) mu_try (1 + TRY_LADDER)
    are asked in turn, up to the first not proven infeasible. x_try: a point believed feasible
    at mu_try (sum r_n = 1): where it holds there (pattern_lp.point_holds, the LPs' own
    acceptance) mu_try is the upper end without an LP (plug2d m = 1,280: the warm LP at
    mu_try took 162 s; floor_pattern's wedge holds). Route
    "accurate" first lowers the upper end by Dinkelbach steps (`dinkelbach_hi`; none when the
    bracket is already within BRACKET_RTOL) and asks just below it: infeasible there, the
    bracket is done. Every LP is first the rows' one warm model (pattern_lp.PatternLp,
    when the equalities do not depend on mu), feasibility.decide where it proves nothing."""
    warm = _OnFirstUse(lambda: PatternLp(rows)) if rows.Z is not None else None
    last = {"x": None}                   # the point of the latest mu taken as feasible
    lo = 0.0
    if mu_try is not None and 0.0 < mu_try < (mu_max if mu_hi is None else mu_hi):
        ladder = [] if mu_hi is not None else [mu_try * (1 + f) for f in TRY_LADDER if mu_try * (1 + f) < mu_max]
        for mu in [mu_try] + ladder:
            d = _witnessed(rows, mu, x_try, probe) if mu == mu_try else None
            d = d or probe.decide(rows, mu, warm=warm)
            if d.status == Status.FEASIBLE:
                mu_hi, last["x"] = mu, d.x
            if d.status != Status.INFEASIBLE:
                break
            lo = mu
    if mu_hi is None:
        if not probe.feasible(rows, mu_max, warm):
            return None, False
        mu_hi = mu_max
    hi = float(mu_hi)
    if mu_floor is not None and lo < mu_floor < hi:
        lo = float(mu_floor)
    if mu_lo is not None and lo < mu_lo < hi and not probe.feasible(rows, mu_lo, warm):
        lo = mu_lo
    if warm is not None and method == "accurate" and hi - lo > BRACKET_RTOL * hi:
        last["x"] = None
        hi = dinkelbach_hi(rows, warm, probe, hi)
        below = hi * (1 - 0.5 * BRACKET_RTOL)
        if lo < below and probe.decide(rows, below, warm=warm).status == Status.INFEASIBLE:
            lo = below

    def ok(mu: float, _spread: float) -> bool:
        d = probe.decide(rows, mu, warm=warm)
        if d.status != Status.FEASIBLE:         # undecided: no step down, so hi stays an upper bound
            return False
        last["x"] = d.x
        return True

    lo, hi = bisect(ok, lo, hi, BRACKET_RTOL if method == "accurate" else tol)
    if method != "accurate":
        return hi, False
    x_hi = last["x"]
    if x_hi is None:
        x_hi = probe.decide(rows, hi, warm=warm).x
    if x_hi is not None:
        mu = polish(rows, x_hi, lo, hi)
        if mu is not None:
            return mu, True
    if warm is not None:
        # the warm model's vertex at hi had no verified root: lp_feasible's (a cold dual
        # simplex) may have one (a random free body, m = 3: the warm one's active set failed)
        x_hi = probe.decide(rows, hi).x
        mu = None if x_hi is None else polish(rows, x_hi, lo, hi)
        if mu is not None:
            return mu, True
    return hi, False


class _OnFirstUse:
    """The object make() returns, made on first use (an attribute asked): a bracket that a
    witness settles builds no PatternLp (plug2d m = 1,280: ~1 s of products)."""

    def __init__(self, make):
        self._make, self._made = make, None

    def __getattr__(self, name):
        if self._made is None:
            self._made = self._make()
        return getattr(self._made, name)


def _witnessed(rows: Rows, mu: float, x: np.ndarray | None, probe: Probe) -> Decision | None:
    """FEASIBLE with x when x holds at mu (point_holds; counted "witness_feasible"), else None
    (counted "witness_failed" when there was one)."""
    if x is None:
        return None
    if point_holds(rows, mu, x):
        count(probe.statuses, "witness_feasible")
        return Decision(Status.FEASIBLE, x)
    count(probe.statuses, "witness_failed")
    return None


def dinkelbach_hi(rows: Rows, warm: PatternLp, probe: Probe, hi: float) -> float:
    """A lower feasible mu than hi (hi itself when none is found), by generalised Dinkelbach
    steps (Crouzeix, Ferland & Schaible's, margins weighted by the last point's a1 . x, which
    converges superlinearly near mu^c): the point of largest margin at hi (PatternLp.margin)
    is feasible at its ratio (pattern_lp.ratio) below hi, checked on every row there
    (pattern_lp.point_holds); that ratio is the next hi, until a step gains less than
    BRACKET_RTOL / 2 or DINKELBACH_STEPS (counted in probe.solves and statuses "dinkelbach";
    plug2d m = 160 from mu = 100: 13 steps to 1e-16, against 32 bisection LPs to 1e-7)."""
    x = None
    for _ in range(DINKELBACH_STEPS):
        task_tick()
        probe.solves += 1
        count(probe.statuses, "dinkelbach")
        got = warm.margin(hi, x)
        if got is None or got[0] <= 0:
            break
        mu = ratio(rows, got[1])
        if not (0.0 < mu < hi) or not point_holds(rows, mu, got[1]):
            break
        gain, hi, x = hi - mu, mu, got[1]
        if gain <= 0.5 * BRACKET_RTOL * hi:
            break
    return hi


def polish(rows: Rows, x: np.ndarray, lo: float, hi: float, seed: int = 0) -> float | None:
    """Exact root of the active-set pencil inside [lo, hi] (see module doc), or None."""
    unit = rows_at(rows, hi)
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
        A, B = dense_call(np.matmul, G, M0), -dense_call(np.matmul, G, M1)
        try:
            lam = None if A.shape[0] <= POLISH_DENSE_MAX else near_roots(A, B, lo - pad, hi + pad, rng)
            lam = sla.eigvals(A, B) if lam is None else lam
        except (np.linalg.LinAlgError, ValueError):
            continue
        lam = lam[np.isfinite(lam)]
        lam = np.sort(lam[np.abs(lam.imag) <= 1e-8 * np.abs(lam.real) + 1e-14].real)
        for mu in lam[(lam >= lo - pad) & (lam <= hi + pad)]:
            if _verified(rows, act, float(mu)):
                return float(mu)
    return None


def near_roots(A: np.ndarray, B: np.ndarray, a: float, b: float, rng: np.random.Generator) -> np.ndarray | None:
    """Eigenvalues lam of the square pencil A v = lam B v, among them every one in the disc
    |lam - c| <= rho, c = (a + b) / 2, rho = (b - a) / 2 (complex ones too; the caller keeps
    the real ones in [a, b]): the largest theta = 1 / (lam - c) of (A - c B)^-1 B by ARPACK
    (one LU of A - c B; the start vector from rng), k = NEAR_ROOTS_K[0] doubled until the
    least |theta| found lies below 1 / rho, so that no eigenvalue of the disc is left out.
    None when that takes more than NEAR_ROOTS_K[1] or ARPACK fails (the caller runs QZ)."""
    from scipy.sparse.linalg import ArpackError, LinearOperator, eigs
    n = A.shape[0]
    c, rho = 0.5 * (a + b), 0.5 * (b - a)
    lu = sla.lu_factor(A - c * B, check_finite=False)
    if not np.all(np.isfinite(lu[0])) or np.any(np.diag(lu[0]) == 0):
        return None
    op = LinearOperator((n, n), matvec=lambda v: sla.lu_solve(lu, B @ v, check_finite=False), dtype=float)
    v0 = rng.standard_normal(n)
    k = NEAR_ROOTS_K[0]
    while k <= NEAR_ROOTS_K[1] and k < n - 1:
        task_tick()
        try:
            theta = eigs(op, k=k, which="LM", v0=v0, return_eigenvectors=False)
        except ArpackError:
            return None
        if np.abs(theta).min() * rho < 1.0:
            theta = theta[theta != 0]
            return c + 1.0 / theta
        k *= 2
    return None


def rows_at(rows: Rows, mu: float) -> np.ndarray:
    """The rows at mu divided by ||a0|| + mu ||a1|| (not by their norm at mu, which
    vanishes for a friction row that is identically tight at mu^c)."""
    A = rows.a0 + mu * rows.a1
    scale = np.linalg.norm(rows.a0, axis=1) + abs(mu) * np.linalg.norm(rows.a1, axis=1)
    scale[scale == 0] = 1.0
    return A / scale[:, None]


def _verified(rows: Rows, act: np.ndarray, mu: float) -> bool:
    """The active rows at mu have a null vector (relative singular value <= POLISH_TOL)
    that, scaled to sum(r_n) = 1, satisfies every row to POLISH_TOL."""
    unit = rows_at(rows, mu)
    _, s, vt = dense_call(np.linalg.svd, unit[act], full_matrices=False)   # act >= d rows (polish): vt (d, d)
    if len(s) >= vt.shape[0] and s[-1] > POLISH_TOL * s[0]:
        return False
    x = vt[-1]
    nr = rows.norm @ x
    if abs(nr) < 1e-12 * np.linalg.norm(rows.norm):
        return False
    x = x / nr
    vals = unit @ x / np.linalg.norm(x)
    return bool(np.all(np.abs(vals[rows.eq]) <= POLISH_TOL) and np.all(vals[~rows.eq] >= -POLISH_TOL))
