"""Learnt infeasible cores of the 3D sign-pattern tree: the part of a pattern that a
verified infeasibility certificate really uses (`infeasible_core`), and the set of
cores that rules tree nodes out without a solve (`Cores`)."""
from __future__ import annotations

import numpy as np

from hpcwedge.solvers.rows import ConeRows, NodeRows
from hpcwedge.solvers.socp import CERT_TOL


def infeasible_core(nr: NodeRows, rows: ConeRows, mu: float, zu: np.ndarray, zr: np.ndarray,
                    z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The part of the pattern (zu, zr) that a verified Clarabel certificate z of its
    infeasibility at mu really uses: masks (core_u <= zu, core_r <= zr) such that
    every pattern fixing at least core_u to contact and core_r to gap is
    infeasible at mu (and at any smaller mu).

    Node-wise, a certificate is a multiplier lam_i of u_n,i (>= 0 unless i is in
    contact, where it is free) and zeta_i of (mu r_n, r_t1, r_t2)_i (in the second-
    order cone unless i is in gap, where it is free) with

        norm + sum_i lam_i un_i + sum_i zeta_i . C_i(mu) = 0       (x-space)

    (then sum r_n = 1 and the constraints give 0 = 1 + (>= 0)). z gives lam and zeta
    for the free nodes; least squares gives the multipliers of the pattern's
    equalities. A fixed node whose multiplier already has the sign (lies in the
    cone) of a free node is left out of the core; so are those whose multiplier is
    cleaned to that (clipped at 0 / projected onto the cone) within half of
    CERT_TOL in total. The cleaned certificate is checked like Clarabel's own
    (residual <= CERT_TOL with sum r_n's multiplier 1); if it fails, the core is
    the whole pattern (what the solve proved anyway)."""
    whole = (zu.copy(), zr.copy())
    m, d = nr.un.shape
    if not np.isfinite(z).all() or z[0] >= 0:
        return whole
    z = z / -z[0]
    L = rows.lin.shape[0]
    C = nr.cone * np.array([mu, 1.0, 1.0])[None, :, None]        # (m, 3, d) at mu
    lam, zeta = np.zeros(m), np.zeros((m, 3))
    lam[rows.lin_nodes] = z[1:1 + L]
    zeta[rows.nodes] = z[1 + L:].reshape(-1, 3)
    # multipliers of the pattern's equalities: least squares on their rows
    cu, cr = np.flatnonzero(zu), np.flatnonzero(zr)
    h = nr.norm + nr.un.T @ lam + np.einsum("ik,ikd->d", zeta, C)
    M = np.vstack([nr.un[cu], C[cr].reshape(-1, d)])
    if M.shape[0]:
        nu = np.linalg.lstsq(M.T, -h, rcond=None)[0]
        lam[cu] = nu[:len(cu)]
        zeta[cr] = nu[len(cu):].reshape(-1, 3)

    def residual(lam, zeta):
        return np.abs(nr.norm + nr.un.T @ lam + np.einsum("ik,ikd->d", zeta, C)).max()

    if residual(lam, zeta) > CERT_TOL / 2:
        return whole
    # what each fixed node's multiplier lacks to be a free node's (its cleaning cost:
    # the rows are unit-sized, C's at most max(mu, 1))
    lam_c = np.maximum(lam, 0.0)
    zeta_c = _soc_project(zeta)
    cost = np.zeros(m)
    cost[cu] = lam_c[cu] - lam[cu]                                  # >= 0: the clip
    cost[cr] = max(mu, 1.0) * np.linalg.norm(zeta[cr] - zeta_c[cr], axis=1)
    fixed = np.concatenate([cu, cr])
    kind = np.concatenate([np.zeros(len(cu), bool), np.ones(len(cr), bool)])
    order = np.argsort(cost[fixed], kind="stable")
    spent = np.cumsum(cost[fixed][order])
    out = spent <= CERT_TOL / 2
    core_u, core_r = zu.copy(), zr.copy()
    for j in order[out]:
        i = fixed[j]
        if kind[j]:
            core_r[i] = False
            zeta[i] = zeta_c[i]
        else:
            core_u[i] = False
            lam[i] = lam_c[i]
    if residual(lam, zeta) > CERT_TOL:
        return whole
    return core_u, core_r


def _soc_project(v: np.ndarray) -> np.ndarray:
    """Rows of v (k, 3) projected onto the second-order cone {||v[1:]|| <= v[0]}."""
    t, w = v[:, 0], v[:, 1:]
    nw = np.linalg.norm(w, axis=1)
    out = v.copy()
    below = nw <= -t                              # in the polar cone: to 0
    out[below] = 0.0
    mid = (nw > np.abs(t))
    a = (t[mid] + nw[mid]) / 2
    out[mid, 0] = a
    out[mid, 1:] = w[mid] * (a / nw[mid])[:, None]
    return out


class Cores:
    """Partial patterns proven infeasible by a certificate that uses only their
    fixings (infeasible_core): a tree node fixing at least one core's nodes
    the same way is infeasible without a solve. A core is kept only when it is
    smaller than the node it came from (two nodes of one tree never extend each
    other unless one is below the other, whose subtree is gone anyway). Bit sets
    in uint64 words, so m <= MAX_M."""

    MAX_M = 64

    def __init__(self, m: int):
        self.m = m
        self._c = np.zeros(64, dtype=np.uint64)
        self._g = np.zeros(64, dtype=np.uint64)
        self.n = 0

    def add(self, node, core_u: np.ndarray, core_r: np.ndarray) -> None:
        w = np.uint64(1) << np.arange(self.m, dtype=np.uint64)
        c, g = int(w[core_u].sum()), int(w[core_r].sum())
        if (c, g) == (node.contact, node.gap):
            return
        if self.n == len(self._c):
            self._c, self._g = np.resize(self._c, 2 * self.n), np.resize(self._g, 2 * self.n)
        self._c[self.n], self._g[self.n] = c, g
        self.n += 1

    def covers(self, node) -> bool:
        if not self.n:
            return False
        c, g = np.uint64(node.contact), np.uint64(node.gap)
        return bool(((self._c[:self.n] & ~c) | (self._g[:self.n] & ~g)).min() == 0)
