"""Bracketing mu^c by bisection on feasibility (2D and 3D), and the 2D route.

Every decision of a mu^c computation goes through a `Probe`: it counts the solves and
takes an undecided status as feasible (conservative: the bracket stays valid above).

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
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from hpcwedge.parallel.cancel import task_tick
from hpcwedge.solvers.feasibility import DEFAULT_OPTIONS, PYRAMID_SIDES, Decision, SolverOptions, decide
from hpcwedge.solvers.rows import ConeRows, Rows, Status

BRACKET_RTOL = 1e-7
POLISH_TOL = 1e-9
#: slack thresholds of the active sets tried after those scaled to the bracket width
POLISH_WIDE_TAUS = (1e-5, 1e-3, 1e-2)


class Probe:
    """The feasibility decisions of one mu^c computation, counted: solves (LP/SOCP solves,
    Dinkelbach's steps included), undecided (decisions taken as feasible), statuses
    (feasibility.decide's counts, and the mu^c routes' own), under `options`."""

    def __init__(self, options: SolverOptions = DEFAULT_OPTIONS):
        self.options = options
        self.solves = 0
        self.undecided = 0
        self.statuses: dict = {}

    def decide(self, rows: Rows | ConeRows, mu: float, sides: tuple[int, ...] = PYRAMID_SIDES) -> Decision:
        """feasibility.decide at mu (sides: its pyramid levels), counted."""
        self.solves += 1
        d = decide(rows, mu, self.options, self.statuses, pyramid_sides=sides)
        if d.status == Status.UNDECIDED:
            self.undecided += 1
        return d

    def feasible(self, rows: Rows | ConeRows, mu: float) -> bool:
        """Not proven infeasible at mu (undecided counts as feasible): whether a pattern has a
        mu^c below mu_max at all, which nothing but a proof rules out."""
        return self.decide(rows, mu).status != Status.INFEASIBLE


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
               method: str = "accurate", tol: float = 1e-6, mu_lo: float | None = None) -> tuple[float | None, bool]:
    """(mu^c, polished) of an LP pattern problem given by its rows (module doc; mu^c None:
    infeasible at mu_max). mu_lo: a guess of an infeasible mu below mu^c; the bisection
    starts from it when an LP confirms it (else from 0)."""
    if mu_hi is None:
        if not probe.feasible(rows, mu_max):
            return None, False
        mu_hi = mu_max
    lo, hi = 0.0, float(mu_hi)
    if mu_lo is not None and not probe.feasible(rows, mu_lo):
        lo = mu_lo
    last = {"x": None}                   # the point of the latest mid taken as feasible

    def ok(mu: float, _spread: float) -> bool:
        d = probe.decide(rows, mu)
        if d.status != Status.FEASIBLE:         # undecided: no step down, so hi stays an upper bound
            return False
        last["x"] = d.x
        return True

    lo, hi = bisect(ok, lo, hi, BRACKET_RTOL if method == "accurate" else tol)
    if method != "accurate":
        return hi, False
    x_hi = last["x"]
    if x_hi is None:
        x_hi = probe.decide(rows, hi).x
    if x_hi is not None:
        mu = polish(rows, x_hi, lo, hi)
        if mu is not None:
            return mu, True
    return hi, False


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
