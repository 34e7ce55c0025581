"""mu^c of a pattern (cone) and the global mu^c, to 1e-9 relative (SPEC §2).

Route "accurate": bracket mu^c by bisection on LP feasibility to BRACKET_RTOL,
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

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from .conic import FEASIBLE, INFEASIBLE, Rows, lp_feasible, pattern_rows
from .problem import Parametrization

BRACKET_RTOL = 1e-7
POLISH_TOL = 1e-9


@dataclass
class MuC:
    """mu_c: float or None (infeasible up to mu_max); polished: the pencil step
    verified; lps: LP solves; undecided: LP statuses that decided nothing."""

    mu_c: float | None
    polished: bool = False
    lps: int = 0
    undecided: int = 0


def mu_critical(param: Parametrization, m: int, zero_u: np.ndarray, zero_r: np.ndarray,
                mu_hi: float | None = None, mu_max: float = 100.0,
                method: str = "accurate", tol: float = 1e-6) -> MuC:
    """Least mu at which the pattern (zero_u, zero_r) admits a solution with r != 0.

    mu_hi: a mu known feasible (e.g. the run's mu for a cone found there); else
    mu_max is tested first. Returns MuC(None) when infeasible at mu_max.
    """
    rows = pattern_rows(param, m, zero_u, zero_r)
    out = MuC(None)

    def feasible(mu: float):
        out.lps += 1
        status, x = lp_feasible(rows, mu)
        if status not in (FEASIBLE, INFEASIBLE):
            out.undecided += 1       # conservative: treat as feasible (keeps the bracket valid above)
        return status != INFEASIBLE, x

    if mu_hi is None:
        ok, _ = feasible(mu_max)
        if not ok:
            return out
        mu_hi = mu_max
    lo, hi = 0.0, float(mu_hi)
    rtol = BRACKET_RTOL if method == "accurate" else tol
    x_hi = None
    while hi - lo > rtol * hi and hi > 1e-12 * mu_hi:
        mid = 0.5 * (lo + hi)
        ok, x = feasible(mid)
        if ok:
            hi, x_hi = mid, x
        else:
            lo = mid
    out.mu_c = hi
    if method != "accurate":
        return out
    if x_hi is None:
        ok, x_hi = feasible(hi)
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
    for tau in (10 * width, width, 1e-3 * width):
        act = rows.eq | (np.abs(slack) <= tau)
        sc = np.linalg.norm(rows.a0[act], axis=1) + hi * np.linalg.norm(rows.a1[act], axis=1)
        sc[sc == 0] = 1.0
        M0, M1 = rows.a0[act] / sc[:, None], rows.a1[act] / sc[:, None]
        if M0.shape[0] < M0.shape[1] - 1:
            continue
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
