"""Sign-pattern branch and bound (2D: LP relaxations) and the global mu^c route
that needs no enumeration.

A node of the tree fixes some nodes to contact (u_n = 0) or gap (r = 0); the
relaxation keeps u_n >= 0, r_n >= 0 (and friction) for the others. A child
whose condition the parent's solution already meets is feasible without a
solve. Undecided LP statuses keep the subtree (never pruned on doubt).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .conic import INFEASIBLE, lp_feasible, pattern_rows
from .mu_critical import mu_critical
from .problem import Parametrization

MEETS_TOL = 1e-12


@dataclass
class BnBStats:
    solves: int = 0
    skipped: int = 0
    undecided: int = 0
    nodes: int = 0
    extra: dict = field(default_factory=dict)


def sign_patterns(param: Parametrization, m: int, mu: float, friction: bool = True,
                  first_only: bool = False, stats: BnBStats | None = None,
                  order: list[int] | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Feasible full patterns (zero_u, zero_r) at mu, depth first; in contact-
    before-gap order at each level (so the list is in a canonical order)."""
    stats = stats if stats is not None else BnBStats()
    order = list(range(m)) if order is None else list(order)
    found = []
    zu0, zr0 = np.zeros(m, dtype=bool), np.zeros(m, dtype=bool)
    stack = [(0, zu0, zr0, None)]
    while stack:
        depth, zu, zr, x = stack.pop()
        stats.nodes += 1
        if x is None:
            stats.solves += 1
            status, x = lp_feasible(pattern_rows(param, m, zu, zr, friction), mu if friction else 0.0)
            if status == INFEASIBLE:
                continue
            if x is None:
                stats.undecided += 1
        else:
            stats.skipped += 1
        if depth == m:
            found.append((zu, zr))
            if first_only:
                break
            continue
        i = order[depth]
        kids = []
        for contact in (True, False):
            czu, czr = zu.copy(), zr.copy()
            (czu if contact else czr)[i] = True
            meets = x is not None and _meets(param, m, x, i, contact)
            kids.append((depth + 1, czu, czr, x if meets else None))
        stack.extend(reversed(kids))
    return found


def _meets(param: Parametrization, m: int, x: np.ndarray, i: int, contact: bool) -> bool:
    scale = max(np.abs(param.U @ x).max(), np.abs(param.R @ x).max(), 1e-300)
    if contact:
        return abs(param.U[i] @ x) <= MEETS_TOL * scale
    return max(abs(param.R[i] @ x), abs(param.R[m + i] @ x)) <= MEETS_TOL * scale


def global_mu_critical(param: Parametrization, m: int, mu_max: float, method: str = "accurate",
                       tol: float = 1e-6, stats: BnBStats | None = None) -> tuple[float | None, str]:
    """Least mu with any solution, by branch and bound over patterns with an incumbent.

    Returns (mu_c, status): status "found", "none_at_any_mu" (the relaxation with
    r_t free has no solution) or "none_up_to_mu_max".
    """
    stats = stats if stats is not None else BnBStats()
    if not sign_patterns(param, m, np.inf, friction=False, first_only=True, stats=stats):
        return None, "none_at_any_mu"
    best = None
    bound = mu_max
    while True:
        leaf = sign_patterns(param, m, bound, first_only=True, stats=stats)
        if not leaf:
            break
        zu, zr = leaf[0]
        r = mu_critical(param, m, zu, zr, mu_hi=bound, method=method, tol=tol)
        stats.solves += r.lps
        if r.mu_c is None or (best is not None and r.mu_c >= best):
            break
        best = r.mu_c
        bound = best * (1 - 1e-7)
    if best is None:
        return None, "none_up_to_mu_max"
    # patterns whose mu^c lies within the last step below `best`: settle them all
    top = best * (1 + 1e-9)
    for zu, zr in sign_patterns(param, m, top, stats=stats):
        r = mu_critical(param, m, zu, zr, mu_hi=top, method=method, tol=tol)
        stats.solves += r.lps
        if r.mu_c is not None:
            best = min(best, r.mu_c)
    return best, "found"
