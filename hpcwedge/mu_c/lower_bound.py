"""A certified lower bound on the global mu^c of a free body (2D and 3D): the rigid part of
the root relaxation.

Every wedged state has reactions r != 0 with N^T r = 0 (self-equilibrated) and each node's
r_i in the friction cone K_mu = {||r_t|| <= mu r_n}. A vector g = G w in range(N) (G the
parametrisation's equilibrium rows, problem.ReactionCoordinates.E, transposed: (n, k)) with
every node's (g_n, g_t) strictly inside the dual cone, g_n > mu ||g_t||, makes g . r > 0 for
every such r, while g . r = w . (E r) = 0: no wedge at mu, nor (the cones grow with mu) at any
smaller mu. So mu^c_global > mu.

The certificate w is found by a small conic program in floats (`certificate_at`: max t with
g_n,i - mu ||g_t,i|| >= t, sum g_n = 1; Clarabel) and accepted only by `verified`, which
recomputes g = G w and the inequalities g_n > 0, g_n^2 > mu^2 ||g_t||^2 in rational arithmetic
(python-flint) on the float data G, w and mu: the solver's tolerance never decides.
A supported body (no rigid modes, k = 0) has no such bound (None throughout).
"""
from __future__ import annotations

from dataclasses import dataclass

import flint
import numpy as np

from hpcwedge import exact as xq
from hpcwedge.contact.problem import Parametrization, blocks, kept_on
from hpcwedge.solvers.conic import ConicProblem, solve
from hpcwedge.solvers.rows import Status, problem_dim

#: the relative gap below a value at which global_search asks for a certificate
BOUND_RTOL = 1e-9


@dataclass(frozen=True)
class Bound:
    """The outcome of one certified-bound question: `mu` the trial value, `certified`
    (the exact check passed: mu^c_global > mu), `solves` the conic programs it took,
    `w` (k,) the certificate (None when the program found none)."""

    mu: float
    certified: bool
    solves: int
    w: np.ndarray | None = None


def equilibrium_rows(param: Parametrization) -> np.ndarray | None:
    """G (n, k): the transposed equilibrium rows E of the reaction coordinates (orthonormal
    columns spanning the rigid modes); None for a supported body (k = 0)."""
    E = param.reactions.E
    return None if E.shape[0] == 0 else np.ascontiguousarray(E.T)


def certificate_at(G: np.ndarray, m: int, dim: int, mu: float) -> tuple[np.ndarray | None, Status]:
    """(w, status): w (k,) maximising the least margin t = min_i g_n,i - mu ||g_t,i|| of
    g = G w over sum g_n = 1 (one Clarabel solve; 2D: the cones as two rows per node), when
    that optimum has t > 0; else None. status: Clarabel's answer in the package's words."""
    k = G.shape[1]
    Gb = blocks(G, m, dim)
    one = np.ones((m, 1))
    eq = np.hstack([Gb[0].sum(0, keepdims=True), [[0.0]]])
    if dim == 2:
        cone = np.vstack([np.hstack([-(Gb[0] - mu * Gb[1]), one]), np.hstack([-(Gb[0] + mu * Gb[1]), one])])
        A, n_lin, n_soc = np.vstack([eq, cone]), 2 * m, 0
    else:
        rows = np.empty((3 * m, k + 1))
        rows[0::3] = np.hstack([-Gb[0], one])
        rows[1::3] = np.hstack([-mu * Gb[1], 0 * one])
        rows[2::3] = np.hstack([-mu * Gb[2], 0 * one])
        A, n_lin, n_soc = np.vstack([eq, rows]), 0, m
    b = np.zeros(A.shape[0])
    b[0] = 1.0
    q = np.zeros(k + 1)
    q[-1] = -1.0
    sol = solve(ConicProblem(A, b, 1, n_lin, n_soc, q), attempt=0, tight=True)
    if sol.status != Status.FEASIBLE or not sol.x[-1] > 0:
        return None, sol.status
    return sol.x[:k].copy(), sol.status


def verified(G, m: int, dim: int, mu: float, w: np.ndarray) -> bool:
    """Does w certify mu^c_global > mu? In rational arithmetic on the floats G (or G's exact
    copy, a flint.fmpq_mat), w and mu: every node of g = G w has g_n > 0 and
    g_n^2 > mu^2 ||g_t||^2."""
    Gq = xq.to_q(G) if isinstance(G, np.ndarray) else G
    wq, muq = xq.to_q(np.asarray(w, dtype=float).reshape(-1, 1)), xq.q_scalar(mu)
    g = Gq * wq
    mu2 = muq * muq
    for i in range(m):
        gn = g[i, 0]
        gt2 = sum((g[a * m + i, 0] ** 2 for a in range(1, dim)), flint.fmpq(0))
        if not (gn > 0 and gn * gn > mu2 * gt2):
            return False
    return True


def bound_at(param: Parametrization, m: int, mu: float) -> Bound | None:
    """Is mu^c_global > mu certified (module doc)? None for a supported body."""
    G = kept_on(param, "_equilibrium_rows", lambda: equilibrium_rows(param))
    if G is None or not mu > 0:
        return None
    dim = problem_dim(param, m)
    w, _ = certificate_at(G, m, dim, mu)
    ok = w is not None and verified(kept_on(param, "_equilibrium_rows_q", lambda: xq.to_q(G)), m, dim, mu, w)
    return Bound(mu, ok, 1, w)


def rigid_bound(param: Parametrization, m: int, mu_hi: float, rtol: float = 1e-10) -> tuple[float | None, int]:
    """(L, solves): the largest certified lower bound L <= mu_hi found by bisection to rtol
    (0.0 when none above 0 certifies; None for a supported body). The bisection stops
    where hi <= rtol mu_hi too (a body wedged at every mu > 0, e.g. a plug at a 0 deg taper:
    before, hi halved until mid underflowed to 0)."""
    first = bound_at(param, m, mu_hi)
    if first is None:
        return None, 0
    if first.certified:
        return mu_hi, 1
    lo, hi, solves = 0.0, mu_hi, 1
    while hi - lo > rtol * hi and hi > rtol * mu_hi:
        mid = 0.5 * (lo + hi)
        b = bound_at(param, m, mid)
        solves += 1
        lo, hi = (mid, hi) if b.certified else (lo, mid)
    return lo, solves

