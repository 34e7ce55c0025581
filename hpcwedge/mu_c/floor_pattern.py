"""A sign pattern whose mu^c meets the certified lower bound of a free body
(lower_bound.rigid_bound), found by pivoting on the bound's certificate (2D and 3D).

At the floor mu_f the certificate w (lower_bound.certificate_at) gives each node a dual
vector g_i = (G w)_i with g_n,i >= mu_f ||g_t,i||, and every self-equilibrated r in the cones
has sum_i g_i . r_i = 0, each term >= 0. So a wedge at mu_f has r_i = 0 wherever g_i lies
inside the dual cone, and elsewhere ("tight" nodes) r_i on the one ray of the cone orthogonal
to g_i: r_t,i = mu_f r_n,i e_i, e_i = -g_t,i / ||g_t,i||. For a contact set C (u_n = 0, r_i on
its ray) and gaps (r_i = 0) these are d linear equations in x; their null vector (one, for a
body in general position), scaled to sum r_n = 1, is a wedge at mu_f when r_n >= 0 on C and
u_n >= 0 on the gaps. The pivots start from C = every tight node and move the nodes that
break a sign (r_n < 0: to the gaps; a tight gap with u_n < 0: to C) until none does.

The pattern is a candidate only: the caller decides it with its own certified mu^c
(mu_c.critical), and where that meets the bound the global mu^c is certified
(block2d rows = 159, m = 320: the all-contact pattern's value is 0.46 % above tan 10 deg, its
top corners pull; with them open the pattern meets the bound at once, where steps of a MILP
took minutes each).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from hpcwedge.contact.problem import Parametrization, blocks
from hpcwedge.mu_c.lower_bound import BOUND_RTOL, bound_at, equilibrium_rows, rigid_bound
from hpcwedge.dense import null_space
from hpcwedge.parallel.cancel import task_tick
from hpcwedge.solvers.rows import problem_dim

#: a node is tight when g_n - mu_f ||g_t|| <= TIGHT_RTOL max_i ||g_i|| (the certificate's
#: margin is ~1e-10 at the floor, rigid_bound's tolerance; an untight node's is O(1))
TIGHT_RTOL = 1e-6
#: singular values below NULL_RTOL times the largest count as zero (null_space's rcond)
NULL_RTOL = 1e-10
#: a sign is broken below -SIGN_RTOL times the largest |r_n| (|u_n|) of the null vector
SIGN_RTOL = 1e-9


class FloorWedge(NamedTuple):
    """floor_pattern's pattern, zero_u and zero_r bool (m,) masks, and its wedge x (d,) at the
    floor (x-space, sum r_n = 1): a witness that the pattern is feasible just above it."""

    zero_u: np.ndarray
    zero_r: np.ndarray
    x: np.ndarray


def floor_pattern(param: Parametrization, m: int, floor: float,
                  max_pivots: int | None = None) -> tuple[FloorWedge | None, int]:
    """(FloorWedge, pivots): a pattern with a wedge at mu = floor (module
    doc), or None with the pivots spent when none is found (no certificate at floor, a null
    space not of dimension 1, a pattern met again, an untight node that would need contact,
    or more than max_pivots (default m) pivot steps). floor: a certified lower bound > 0.
    TaskCancelled (cancel.task_tick) between pivots when the engine stops."""
    cert = bound_at(param, m, floor)
    if cert is None or cert.w is None:
        return None, 0
    dim = problem_dim(param, m)
    G = equilibrium_rows(param)
    g = blocks(G @ cert.w, m, dim)
    gn, gt = g[0], np.stack(g[1:], axis=1)                       # (m,), (m, dim - 1)
    size = np.sqrt(gn ** 2 + (gt ** 2).sum(axis=1))
    gt_norm = np.linalg.norm(gt, axis=1)
    tight = (gn - floor * gt_norm <= TIGHT_RTOL * size.max()) & (gt_norm > 0)
    ray = -gt / np.where(gt_norm > 0, gt_norm, 1.0)[:, None]     # e_i, (m, dim - 1)
    Un, (Rn, *Rt) = blocks(param.U, m, dim)[0], blocks(param.R, m, dim)
    contact, seen, cap = tight.copy(), set(), m if max_pivots is None else max_pivots
    for pivots in range(cap + 1):
        task_tick()                        # an SVD of d x d a pivot (m = 320: 0.2 s)
        key = contact.tobytes()
        if key in seen:
            return None, pivots
        seen.add(key)
        x = _null_vector(Un, Rn, Rt, contact, floor * ray)
        if x is None:
            return None, pivots
        rn, un = Rn @ x, Un @ x
        pull = contact & (rn < -SIGN_RTOL * np.abs(rn).max())
        bite = ~contact & (un < -SIGN_RTOL * max(np.abs(un).max(), 1e-300))
        if not (pull.any() or bite.any()):
            return FloorWedge(contact.copy(), ~contact, x / rn.sum()), pivots
        if (bite & ~tight).any():
            return None, pivots
        contact = (contact & ~pull) | bite
    return None, cap


def _null_vector(Un: np.ndarray, Rn: np.ndarray, Rt: list, contact: np.ndarray,
                 slope: np.ndarray) -> np.ndarray | None:
    """x (d,) spanning the null space of the pattern's equations at the floor (module doc),
    signed so that sum r_n > 0; None unless that null space has dimension 1. slope (m, dim-1):
    mu_f e_i."""
    gap = ~contact
    rows = [Un[contact]]
    rows += [Rt[a][contact] - slope[contact, a:a + 1] * Rn[contact] for a in range(len(Rt))]
    rows += [Rn[gap]] + [Rt[a][gap] for a in range(len(Rt))]
    null = null_space(np.vstack(rows), rcond=NULL_RTOL)
    if null.shape[1] != 1:
        return None
    x = null[:, 0]
    total = (Rn @ x).sum()
    return None if total == 0 else x * np.sign(total)


def floor_candidate(param: Parametrization, m: int, floor: float | None, stats) -> FloorWedge | None:
    """floor_pattern's FloorWedge, or None (none found, or floor None or 0); its
    pivots counted into stats.extra["floor_pivots"], its certificate's conic program into
    ["bound_solves"] and its outcome into stats.statuses ("floor_pattern",
    "floor_pattern_none"). stats: a patterns.tree.BnBStats."""
    if not floor:
        return None
    found, pivots = floor_pattern(param, m, floor)
    stats.extra["floor_pivots"] = stats.extra.get("floor_pivots", 0) + pivots
    stats.extra["bound_solves"] = stats.extra.get("bound_solves", 0) + 1
    key = "floor_pattern" if found is not None else "floor_pattern_none"
    stats.statuses[key] = stats.statuses.get(key, 0) + 1
    return found


def certified_floor(param: Parametrization, m: int, mu_max: float, stats) -> float | None:
    """The certified lower bound on the global mu^c (lower_bound.rigid_bound up to mu_max,
    to 1e-10), None when there is none above 0 (a supported body); its conic programs counted
    into stats.extra["bound_solves"]. stats: a patterns.tree.BnBStats."""
    value, solves = rigid_bound(param, m, mu_max)
    stats.extra["bound_solves"] = stats.extra.get("bound_solves", 0) + solves
    return value if value else None


def floor_start(param: Parametrization, m: int, mu_max: float, stats) -> FloorWedge | None:
    """floor_candidate's FloorWedge at the certified_floor (None: no floor above 0 below mu_max,
    or no pattern), counted into stats as those two count."""
    floor = certified_floor(param, m, mu_max, stats)
    return floor_candidate(param, m, floor, stats) if floor and floor < mu_max else None


def bound_meets(param: Parametrization, m: int, best: float, stats) -> bool:
    """Is no wedge below best (1 - BOUND_RTOL), by the certified lower bound
    (lower_bound.bound_at; False for a supported body)? Counted into stats (a BnBStats).extra:
    "bound_solves", and on success "bound_certified" = 1 and "bound" (the certified value)."""
    b = bound_at(param, m, best * (1 - BOUND_RTOL))
    if b is None:
        return False
    stats.extra["bound_solves"] = stats.extra.get("bound_solves", 0) + b.solves
    if b.certified:
        stats.extra["bound_certified"] = 1
        stats.extra["bound"] = b.mu
    return b.certified
