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


@dataclass(frozen=True)
class Subtree:
    """A partial sign pattern: the first `depth` nodes of the search order are
    fixed, node i to contact when bit i of `contact` is set, to gap when bit i
    of `gap` is set. Small and picklable: the unit of work the parallel layer
    moves around and the checkpoint stores (three integers)."""

    depth: int
    contact: int = 0
    gap: int = 0

    def masks(self, m: int) -> tuple[np.ndarray, np.ndarray]:
        """(zero_u, zero_r) boolean masks over the m nodes."""
        bits = 1 << np.arange(m, dtype=object)
        return (np.array([bool(self.contact & b) for b in bits], dtype=bool),
                np.array([bool(self.gap & b) for b in bits], dtype=bool))


@dataclass
class Explored:
    """What one call of PatternTree.explore produced: the feasible full
    patterns found, the roots of the subtrees left open (budget spent), stats."""

    found: list[Subtree]
    open: list[Subtree]
    stats: BnBStats


class PatternTree:
    """The sign-pattern search tree of one problem at one mu, explored by
    subtrees: a pure function of (problem, mu, order), resumable from any set
    of open subtree roots. Node order: `order` (default 0..m-1)."""

    def __init__(self, param: Parametrization, m: int, mu: float, friction: bool = True,
                 order: list[int] | None = None):
        self.param, self.m, self.mu, self.friction = param, m, mu, friction
        self.order = list(range(m)) if order is None else list(order)

    def root(self) -> Subtree:
        return Subtree(0)

    def explore(self, subtree: Subtree, budget: int | None = None,
                first_only: bool = False) -> Explored:
        """Depth-first from `subtree`, contact before gap, for at most `budget`
        tree nodes (None: to the end). Returns found patterns in discovery order
        and the open subtrees (their union with the explored part is `subtree`)."""
        m, param = self.m, self.param
        stats = BnBStats()
        found: list[Subtree] = []
        stack = [(subtree, None)]
        while stack:
            if budget is not None and stats.nodes >= budget:
                break
            node, x = stack.pop()
            stats.nodes += 1
            if x is None:
                stats.solves += 1
                zu, zr = node.masks(m)
                status, x = lp_feasible(pattern_rows(param, m, zu, zr, self.friction),
                                        self.mu if self.friction else 0.0)
                if status == INFEASIBLE:
                    continue
                if x is None:
                    stats.undecided += 1
            else:
                stats.skipped += 1
            if node.depth == m:
                found.append(node)
                if first_only:
                    stack.clear()
                    break
                continue
            i = self.order[node.depth]
            kids = []
            for contact in (True, False):
                kid = Subtree(node.depth + 1, node.contact | (1 << i) if contact else node.contact,
                              node.gap if contact else node.gap | (1 << i))
                meets = x is not None and _meets(param, m, x, i, contact)
                kids.append((kid, x if meets else None))
            stack.extend(reversed(kids))
        return Explored(found, [node for node, _ in reversed(stack)], stats)


def sign_patterns(param: Parametrization, m: int, mu: float, friction: bool = True,
                  first_only: bool = False, stats: BnBStats | None = None,
                  order: list[int] | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Feasible full patterns (zero_u, zero_r) at mu, depth first, in contact-
    before-gap order at each level (a canonical order), serially."""
    out = PatternTree(param, m, mu, friction, order).explore(Subtree(0), first_only=first_only)
    if stats is not None:
        for k in ("solves", "skipped", "undecided", "nodes"):
            setattr(stats, k, getattr(stats, k) + getattr(out.stats, k))
    return [node.masks(m) for node in out.found]


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
