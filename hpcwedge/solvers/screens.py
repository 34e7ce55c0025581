"""Polyhedral LP screens in front of the 3D tree's SOCPs (`PyramidScreens`).

At a tree node (some nodes fixed to contact, u_n = 0, or gap, r = 0) every friction cone
is replaced by a k-facet pyramid, and the node's problem becomes an LP:
  inner  the inscribed pyramid (facets at mu cos(pi / k)) lies inside the cone: a point of
         its LP, verified on the circular cones (socp.verified), is a point of the node's
         problem => the node is FEASIBLE, no SOCP;
  outer  the circumscribed pyramid contains the cone: its LP infeasible => the node is
         INFEASIBLE, no SOCP (the same rule as feasibility.decide's pyramid fallback);
and only a node that neither decides gets its SOCP (feasibility.decide).

Both LPs are posed in generator form, one model per tree and kept warm in COIN-OR CLP
(cylp, dual simplex): columns (lambda, beta), r = G lambda with lambda >= 0 on the k edges
of every node's pyramid, x' = (r, beta) the reaction coordinates of
problem.ReactionCoordinates; rows E G lambda = 0 (equilibrium), u_n >= 0 (= 0 at a contact
node), sum lambda = 1 (each edge has r_n = 1); a gap node's k lambdas fixed to 0. A tree
node changes bounds only. The inner LP minimises fixed generic weights on lambda and on
u_n (lambda in a simplex and u_n >= 0 keep it bounded): its optimum is unique up to a
lineality of beta that moves no u_n and no reaction, so the point it returns — and the
branching that follows from it — does not depend on which LP was solved before (the
split of the tree over tasks, ranks and resumes). The outer LP has no objective; only its
status is used.

Measured on plug3d 3 x 6 at mu 0.65 without symmetry (scripts/bench_search_3d.py): the
screens from 0.4 of the depth on (SCREEN_FROM) take the SOCPs per feasible pattern from 57
to 6.7 in about the same CPU time; above that depth hardly a node of that body is
infeasible, and the SOCP's interior points choose better branchings than LP vertices.
"""
from __future__ import annotations

import importlib.util
import math

import numpy as np

from hpcwedge.contact.problem import Parametrization
from hpcwedge.solvers.feasibility import Decision
from hpcwedge.solvers.rows import ConeRows, Status, count
from hpcwedge.solvers.socp import beta_whitening, verified

#: facets per friction cone of both pyramids
SCREEN_FACETS = 8
#: the screens run at tree nodes with at least this share of the m nodes fixed (plug3d at
#: mu 0.65: from 0.35 to 0.6 the same CPU time within 3 %; SOCPs per pattern at 0.4 and 0.5:
#: m = 18 6.7 and 8.5, m = 24 9.2 and 12.8)
SCREEN_FROM = 0.4
#: what CLP takes for an infinite bound (COIN_DBL_MAX)
BIG = float(np.finfo(float).max)
#: CLP's primal feasibility tolerance on the inner LP (lp.LP_OPTIONS' for HiGHS)
INNER_TOL = 1e-10
#: the seed of the inner LP's generic weights (fixed: the tree is a function of the node)
WEIGHT_SEED = 20100
#: CLP's statuses (CyClpSimplex.getStatusCode) in the package's vocabulary: 0 optimal (a
#: point), 1 primal infeasible; 2 dual infeasible (neither LP is unbounded: numerics),
#: 3 stopped on iterations or time, 4 stopped on errors, 5 stopped by an event handler,
#: -1 unknown: nothing decided
CLP_STATUS = {0: Status.FEASIBLE, 1: Status.INFEASIBLE, 2: Status.UNDECIDED, 3: Status.UNDECIDED,
              4: Status.UNDECIDED, 5: Status.UNDECIDED, -1: Status.UNDECIDED}


def screens_available() -> bool:
    """Whether CLP (cylp, the `screens` extra) is installed."""
    return importlib.util.find_spec("cylp") is not None


def pyramid_edges(facets: int, inner: bool) -> np.ndarray:
    """(k, 2): the tangential part per unit r_n (mu = 1) of the k edges of the pyramid
    rows.pyramid_rows builds with a facet normal on t1 (phase 0): facet normals at angles
    2 pi j / k, at distance cos(pi / k) (inner) or 1 (outer); its edges lie between two
    adjacent normals, at angle pi / k + 2 pi j / k and radius 1 (inner) or 1 / cos(pi / k)."""
    th = np.pi / facets + 2 * np.pi * np.arange(facets) / facets
    rad = 1.0 if inner else 1.0 / np.cos(np.pi / facets)
    return rad * np.stack([np.cos(th), np.sin(th)], axis=1)


def edge_matrix(m: int, mu: float, facets: int, inner: bool) -> np.ndarray:
    """G (3m, m k): the reactions r (block order n, t1, t2, m rows each) as r = G lambda,
    lambda >= 0 on the k edges of every node's pyramid at mu (pyramid_edges; node i's edges
    are columns i k .. i k + k - 1, each with r_n = 1)."""
    edges = mu * pyramid_edges(facets, inner)
    G = np.zeros((3 * m, m * facets))
    for a, coef in enumerate((np.ones(facets), edges[:, 0], edges[:, 1])):
        G[a * m + np.repeat(np.arange(m), facets), np.arange(m * facets)] = np.tile(coef, m)
    return G


class PyramidLP:
    """The generator-form LP (module doc) of one pyramid at mu, held warm in CLP.
    `solve(zu, zr)` -> (status (CLP_STATUS), x-space point or None: the inner LP's optimum;
    the outer LP returns its status alone); zu, zr: (m,) bool, the
    nodes fixed to contact and to gap."""

    def __init__(self, param: Parametrization, m: int, mu: float, inner: bool,
                 facets: int = SCREEN_FACETS):
        import scipy.sparse as sp
        from cylp.cy import CyClpSimplex
        from cylp.cy.CyCoinPackedMatrix import CyCoinPackedMatrix
        rc = param.reactions
        n, k = rc.E.shape[1], rc.E.shape[0]
        nb = rc.U.shape[1] - n
        f = m * facets
        G = edge_matrix(m, mu, facets, inner)
        #: the rigid amplitudes whitened as in the SOCP (beta = W beta'): unwhitened, CLP's
        #: outer LP pruned 7 feasible nodes of plug3d 2 x 5 at a 0.001 deg taper (a pattern lost)
        self.W = beta_whitening(rc, m)
        A_u = np.hstack([rc.U[:m, :n] @ G, rc.U[:m, n:] if self.W is None else rc.U[:m, n:] @ self.W])
        A_u /= np.linalg.norm(A_u, axis=1, keepdims=True)
        A = np.vstack([np.hstack([rc.E @ G, np.zeros((k, nb))]), A_u,
                       np.concatenate([np.ones(f), np.zeros(nb)])])
        #: outer: beta = beta+ - beta-, both >= 0. CLP's dual simplex with free columns
        #: declared feasible nodes infeasible (14 of 825 screened nodes of plug3d 2 x 6 when
        #: every solve started from the root's basis); the inner LP keeps beta free (faster,
        #: and every point it returns is verified)
        self.split = not inner
        if self.split:
            A, A_u = np.hstack([A, -A[:, f:]]), np.hstack([A_u, -A_u[:, f:]])
        cost = np.zeros(A.shape[1])
        if inner:
            w = np.random.default_rng(WEIGHT_SEED).uniform(1.0, 2.0, f + m)
            cost[:f] = w[:f]
            cost += w[f:] @ A_u
        col_lo = np.zeros(A.shape[1])
        col_lo[f:] = 0.0 if self.split else -BIG
        row_lo = np.concatenate([np.zeros(k + m), [1.0]])
        row_hi = np.concatenate([np.zeros(k), np.full(m, BIG), [1.0]])
        C = sp.csc_matrix(A).tocoo()                      # CoinPackedMatrix wants column order
        M = CyCoinPackedMatrix(True, C.row.astype(np.int32), C.col.astype(np.int32), C.data.astype(float))
        s = CyClpSimplex()
        s.loadProblem(M, col_lo, np.full(A.shape[1], BIG), cost, row_lo, row_hi)
        s.logLevel = 0
        s.scaling = 0                  # the rows are unit already: 7 % less time (plug3d 3 x 6)
        if inner:
            # a point CLP accepts at its default 1e-7 can fail socp.verified's 1e-8 or pass
            # it by the warm start it came from (plug3d 3 x 6: 2 of 10,869 LPs differed
            # between splits of the tree); at 1e-10 none did, on any split measured
            s.primalTolerance = INNER_TOL
        s.dual()
        self._s, self.rc, self.G, self.m, self.k, self.facets, self.fixed = s, rc, G, m, k, facets, f
        self.calls = 0

    def solve(self, zu: np.ndarray, zr: np.ndarray) -> tuple[Status, np.ndarray | None]:
        f, k, m, s = self.fixed, self.k, self.m, self._s
        # CLP's own bound arrays, written in place (cylp's setters would hand CLP a numpy
        # buffer that CLP later frees); "x" keeps its work areas: a warm start
        s.variablesUpper[:f] = np.where(np.repeat(zr, self.facets), 0.0, BIG)
        s.constraintsUpper[k:k + m] = np.where(zu, 0.0, BIG)
        s.dual(startFinishOptions="x")
        self.calls += 1
        status = CLP_STATUS.get(s.getStatusCode(), Status.UNDECIDED)
        if status != Status.FEASIBLE or self.split:
            return status, None
        xp = np.array(s.primalVariableSolution)
        beta = xp[f:]
        if self.split:
            beta = beta[:beta.size // 2] - beta[beta.size // 2:]
        return status, self.rc.to_x(self.G @ xp[:f], beta if self.W is None else self.W @ beta)


class PyramidScreens:
    """The inner and outer screens (module doc) of one tree (param, m, mu), their CLP models
    made on first use. `decide(rows, zu, zr, counts)`: a Decision, or None (the SOCP must
    decide). counts: "screen_lps" (LPs solved), "screen_feasible", "screen_infeasible"."""

    def __init__(self, param: Parametrization, m: int, mu: float,
                 facets: int = SCREEN_FACETS, from_share: float = SCREEN_FROM):
        self.param, self.m, self.mu, self.facets = param, m, mu, facets
        #: the fewest fixed nodes at which the screens run
        self.from_depth = math.ceil(from_share * m)
        self._lps: dict[bool, PyramidLP] = {}

    def __getstate__(self):
        return {**self.__dict__, "_lps": {}}            # CLP models are made again where used

    def _lp(self, inner: bool) -> PyramidLP:
        if inner not in self._lps:
            self._lps[inner] = PyramidLP(self.param, self.m, self.mu, inner, self.facets)
        return self._lps[inner]

    def applies(self, zu: np.ndarray, zr: np.ndarray) -> bool:
        """At this tree node: deep enough, and some node not in gap (else decide's own rule)."""
        return bool((~zr).any()) and int(np.count_nonzero(zu | zr)) >= self.from_depth

    def decide(self, rows: ConeRows, zu: np.ndarray, zr: np.ndarray,
               counts: dict | None = None) -> Decision | None:
        # the outer LP first: 10,145 LPs against 10,869 inner first on plug3d 3 x 6 (more of
        # the screened nodes are infeasible, 3,485 against 2,761 feasible)
        status, _ = self._lp(False).solve(zu, zr)
        count(counts, "screen_lps")
        if status == Status.INFEASIBLE:
            count(counts, "screen_infeasible")
            return Decision(Status.INFEASIBLE)
        status, x = self._lp(True).solve(zu, zr)
        count(counts, "screen_lps")
        x = verified(rows, self.mu, x) if status == Status.FEASIBLE else None
        if x is None:
            return None
        count(counts, "screen_feasible")
        return Decision(Status.FEASIBLE, x)
