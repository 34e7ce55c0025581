"""The pattern feasibility problem as constraint rows, and the vocabulary of its answers.

A (partial) sign pattern is two boolean masks over the m nodes:
zero_u (u_n,i = 0: contact) and zero_r (r_i = 0: gap). A node in neither is
free (u_n >= 0, r_n >= 0, no complementarity: the branch-and-bound relaxation);
a node in both has u_n = r_n = 0. Every problem is normalised by sum(r_n) = 1.

2D: the problem is an LP (`Rows`, solved by lp.py). mu = inf drops the friction rows
(r_t free): the relaxation that decides "no wedge at any mu".

3D: the problem is an SOCP (`ConeRows`, solved by socp.py) in x in R^d:

    eq x = 0                 u_n,i = 0 (contact), r_i = 0 (gap)
    lin x >= 0               u_n,i >= 0 (every node not in contact)
    ||rt_i x|| <= mu rn_i x  every node not in gap (implies r_n,i >= 0)
    norm x = 1               sum r_n = 1

in the coordinates w of the null space of `eq` (x = Z w: the pattern equalities are
eliminated once, by an SVD, so the solver never meets dependent equality rows). With
friction=False (r_t free) it is the LP {eq, lin, r_n >= 0} (a `Rows`). `pyramid_rows`:
the LP with every friction cone replaced by a polyhedral pyramid (feasibility.py's
fallback).
"""
from __future__ import annotations

import enum
import functools
import math
from dataclasses import dataclass

import numpy as np

from hpcwedge.contact.problem import Parametrization, ReactionCoordinates, blocks, kept_on
from hpcwedge.dense import dense_call


class Status(enum.StrEnum):
    """The answer to a feasibility question (the values reach the stats' counter keys,
    e.g. "lp_feasible"), and the package's reading of every solver's status (each solver's
    map: conic.CLARABEL_STATUS, lp.HIGHS_STATUS, screens.CLP_STATUS). UNDECIDED: no solver
    decided it; callers keep the subtree / take the point as feasible (nothing is pruned on
    doubt)."""

    FEASIBLE = "feasible"
    INFEASIBLE = "infeasible"
    UNDECIDED = "undecided"


def count(counts: dict | None, key: str, n: int = 1) -> None:
    """counts[key] += n (counts None: nothing): how problems were decided, for the stats."""
    if counts is not None:
        counts[key] = counts.get(key, 0) + n


#: relative size under which a constraint row is taken as identically zero
ZERO_ROW_RTOL = 1e-12
#: rank decision on the unit-scaled pattern equalities
EQ_RANK_RTOL = 1e-10


@dataclass(frozen=True)
class Rows:
    """Homogeneous constraint rows (a0 + mu * a1) . x  (>= 0 or == 0), unit-scaled at
    build time; `eq` marks equalities. `norm` is the row of sum(r_n)."""

    a0: np.ndarray
    a1: np.ndarray
    eq: np.ndarray
    norm: np.ndarray

    @functools.cached_property
    def Z(self) -> np.ndarray | None:
        """(d, p) orthonormal basis of the null space of the equality rows (eq_null_space);
        None when an equality row depends on mu (then no basis serves every mu)."""
        if np.any(self.a1[self.eq]):
            return None
        return eq_null_space(unit_rows(self.a0[self.eq]), self.a0.shape[1])


def _gathered(block: str, index: str) -> functools.cached_property:
    """A ConeRows field cut from its node blocks on first use: node_blocks.<block>[<index>]."""
    def cut(self):
        return getattr(self.node_blocks, block)[getattr(self, index)]
    return functools.cached_property(cut)


@dataclass(frozen=True)
class ConeRows:
    """The 3D pattern SOCP (module doc) of the pattern zero_u, zero_r (m,), its rows cut on
    first use from `node_blocks`, the parametrisation's node rows (a solve in reaction
    coordinates, socp.reaction_socp, needs none of them): eq (E, d), lin (L, d): unit rows;
    rn (c, d), rt (c, 2, d): the cone nodes `nodes`, each node's three rows scaled by one
    common factor (scale (c,), applied as rows / scale); norm (d,): sum r_n. lin_nodes
    (L,): the node of each lin row, lin_scale (L,) the norm it was scaled by. reactions:
    the parametrisation in x' = (r, beta) (problem.ReactionCoordinates)."""

    zero_u: np.ndarray
    zero_r: np.ndarray
    nodes: np.ndarray
    norm: np.ndarray
    reactions: ReactionCoordinates
    node_blocks: _NodeBlocks

    @functools.cached_property
    def eq_index(self) -> np.ndarray:
        """eq's rows among the node rows [u_n; r_n; r_t1; r_t2] (4m): u_n of contact nodes,
        (r_n, r_t1, r_t2) of gap nodes, zero rows dropped."""
        zr = self.zero_r
        return self.node_blocks.nonzero(np.concatenate([self.zero_u, zr, zr, zr]).nonzero()[0])

    @functools.cached_property
    def lin_nodes(self) -> np.ndarray:
        return self.node_blocks.nonzero((~self.zero_u).nonzero()[0])

    eq = _gathered("unit", "eq_index")
    lin = _gathered("unit", "lin_nodes")
    lin_scale = _gathered("size", "lin_nodes")
    rn = _gathered("rn", "nodes")
    rt = _gathered("rt", "nodes")
    scale = _gathered("scale", "nodes")

    def at(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rows at x (d,): eq x, lin x and the cones' (rn x, rt1 x, rt2 x) (3, c), from
        one product with every node's rows (equal to the blocks' own products up to
        rounding)."""
        m = self.zero_u.shape[0]
        y = self.node_blocks.stacked @ x
        return y[self.eq_index], y[self.lin_nodes], y[4 * m:].reshape(3, m)[:, self.nodes]

    @functools.cached_property
    def Z(self) -> np.ndarray:
        """(d, p) orthonormal basis of the null space of eq (socp.pattern_socp's
        coordinates, x = Z w), computed on first use."""
        return eq_null_space(self.eq, self.norm.shape[0])


def problem_dim(param: Parametrization, m: int) -> int:
    """2 or 3, from the parametrisation's row count (dim * m)."""
    return param.U.shape[0] // m


def unit_rows(A: np.ndarray) -> np.ndarray:
    """Rows scaled to unit norm; rows that are identically zero (relative to the
    largest) dropped."""
    A = A[kept_rows(A)]
    return A / np.linalg.norm(A, axis=1, keepdims=True)


def kept_rows(A: np.ndarray) -> np.ndarray:
    """The rows of A that `unit_rows` keeps (boolean mask)."""
    return kept_sizes(np.linalg.norm(A, axis=1))


def kept_sizes(size: np.ndarray) -> np.ndarray:
    """Of rows with norms `size`, those not identically zero: above ZERO_ROW_RTOL times the
    largest (boolean mask)."""
    return size > ZERO_ROW_RTOL * max(np.maximum.reduce(size, initial=0.0), 1e-300)


def pattern_rows(param: Parametrization, m: int, zero_u: np.ndarray, zero_r: np.ndarray,
                 friction: bool = True) -> Rows | ConeRows:
    """The pattern problem in x in R^d: 2D -> `Rows` (LP); 3D -> `ConeRows` (SOCP),
    or `Rows` (LP) when friction=False."""
    if problem_dim(param, m) == 3:
        return _pattern_rows_3d(param, m, np.asarray(zero_u, bool), np.asarray(zero_r, bool), friction)
    U, R = param.U, param.R
    Un, (Rn, Rt) = blocks(U, m, 2)[0], blocks(R, m, 2)
    z = np.zeros_like(Un)
    a0, a1, eq = [], [], []

    def add(r0, r1, is_eq):
        a0.append(r0)
        a1.append(r1)
        eq.append(np.full(len(r0), is_eq))

    add(Un[zero_u], z[zero_u], True)
    add(Rn[zero_r], z[zero_r], True)
    add(Rt[zero_r], z[zero_r], True)
    add(Un[~zero_u], z[~zero_u], False)
    fr = ~zero_r
    if friction:
        add(Rt[fr], Rn[fr], False)
        add(-Rt[fr], Rn[fr], False)
    else:
        add(Rn[fr], z[fr], False)
    A0, A1, E = np.vstack(a0), np.vstack(a1), np.concatenate(eq)
    return Rows(a0=A0, a1=A1, eq=E, norm=Rn.sum(axis=0))


def _pattern_rows_3d(param, m, zu, zr, friction):
    nb = _node_blocks(param, m)
    rows = ConeRows(zero_u=zu, zero_r=zr, nodes=(~zr).nonzero()[0], norm=nb.norm,
                    reactions=param.reactions, node_blocks=nb)
    if friction:
        return rows
    eq, lin, rn = rows.eq, rows.lin, unit_rows(nb.rows[m:2 * m][~zr])
    A0 = np.vstack([eq, lin, rn])
    E = np.concatenate([np.ones(len(eq), bool), np.zeros(len(lin) + len(rn), bool)])
    return Rows(a0=A0, a1=np.zeros_like(A0), eq=E, norm=nb.norm)


@dataclass(frozen=True)
class _NodeBlocks:
    """The rows of a 3D parametrisation that every pattern's rows are cut from: rows (4m, d)
    [u_n; r_n; r_t1; r_t2], each row's norm `size` and the rows over it `unit` (zero rows
    stay zero); rn (m, d), rt (m, 2, d) over each node's cone factor `scale` (m,); norm (d,)
    sum r_n; stacked (7m, d): [unit; rn; rt1; rt2] (ConeRows.at); all_kept: every row above
    ZERO_ROW_RTOL times the largest (so kept_sizes keeps every row of any selection of them)."""

    rows: np.ndarray
    size: np.ndarray
    unit: np.ndarray
    rn: np.ndarray
    rt: np.ndarray
    scale: np.ndarray
    norm: np.ndarray
    stacked: np.ndarray
    all_kept: bool

    def nonzero(self, pick: np.ndarray) -> np.ndarray:
        """Of the rows `pick` (indices into rows), those kept_sizes keeps."""
        return pick if self.all_kept else pick[kept_sizes(self.size[pick])]


def _node_blocks(param: Parametrization, m: int) -> _NodeBlocks:
    """_NodeBlocks of (param, m), computed once per parametrisation (kept on it)."""
    def build() -> _NodeBlocks:
        Un, (Rn, Rt1, Rt2) = blocks(param.U, m, 3)[0], blocks(param.R, m, 3)
        rows = np.ascontiguousarray(np.vstack([Un, Rn, Rt1, Rt2]))
        size = np.linalg.norm(rows, axis=1)
        unit = rows / np.where(size > 0, size, 1.0)[:, None]
        sc = _cone_scale(Rn, Rt1, Rt2)
        rn, rt = Rn / sc[:, None], np.stack([Rt1, Rt2], axis=1) / sc[:, None, None]
        return _NodeBlocks(rows=rows, size=size, unit=unit, rn=rn, rt=rt, scale=sc, norm=Rn.sum(axis=0),
                           stacked=np.vstack([unit, rn, rt[:, 0], rt[:, 1]]),
                           all_kept=bool(size.min() > ZERO_ROW_RTOL * size.max()))
    return kept_on(param, f"_node_blocks_{m}", build)


def eq_null_space(eq: np.ndarray, d: int) -> np.ndarray:
    """(d, p) orthonormal basis of the null space of the unit equality rows eq (E, d), by
    an SVD; rank: singular values above EQ_RANK_RTOL times the largest."""
    if not eq.shape[0]:
        return np.eye(d)
    _, s, vt = dense_call(np.linalg.svd, eq)
    rank = int((s > EQ_RANK_RTOL * s[0]).sum())
    return vt[rank:].T


def _cone_scale(Rn: np.ndarray, Rt1: np.ndarray, Rt2: np.ndarray) -> np.ndarray:
    """The common factor of each node's (r_n, r_t1, r_t2) rows in the SOCP."""
    sc = np.sqrt((Rn ** 2).sum(1) + (Rt1 ** 2).sum(1) + (Rt2 ** 2).sum(1))
    sc[sc == 0] = 1.0
    return sc


def pyramid_rows(rows: ConeRows, sides: int, inner: bool, phase: np.ndarray | None = None) -> Rows:
    """LP rows of the pattern problem with every friction cone replaced by a pyramid of
    `sides` facets: inscribed (inner) or circumscribed (outer). phase (c,): per cone
    node, the angle in the (t1, t2) plane of one facet normal (default: half a
    facet off the t1 axis)."""
    c = rows.rn.shape[0]
    base = 2 * np.pi * np.arange(sides) / sides
    ph = np.full(c, np.pi / sides) if phase is None else np.asarray(phase, float)
    th = ph[:, None] + base[None, :]                                  # (c, k)
    dirs = np.stack([np.cos(th), np.sin(th)], axis=2)                 # (c, k, 2)
    d = rows.norm.shape[0]
    f0 = -np.einsum("cka,cad->ckd", dirs, rows.rt).reshape(-1, d)        # -(t . r_t)
    f1 = np.repeat((math.cos(math.pi / sides) if inner else 1.0) * rows.rn, sides, axis=0)
    a0 = np.vstack([rows.eq, rows.lin, f0])
    a1 = np.vstack([np.zeros((rows.eq.shape[0] + rows.lin.shape[0], d)), f1])
    eq = np.concatenate([np.ones(rows.eq.shape[0], bool), np.zeros(a0.shape[0] - rows.eq.shape[0], bool)])
    return Rows(a0=a0, a1=a1, eq=eq, norm=rows.norm)
