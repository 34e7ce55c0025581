"""Complementarity-pruned double description (float and exact rational).

Input: node-wise constraint rows A (3m x d) of a pointed cone P = {x : A x >= 0}
(row 3i: u_n,i; rows 3i+1, 3i+2: the two friction edges; see problem.py).
Output: every extreme ray of P that is complementary (u_n,i = 0 or r_n,i = 0 at
every node), with its zero set.

Pruning. Once the three rows of node i are in, a ray with u_n,i > 0 and
r_n,i > 0 is dropped: every complementary extreme ray of the final cone lies on
a face {u_n,i = 0} or {r_n,i = 0} of each intermediate cone, and a DD
combination lies on a face only if both parents do. Pairs are combined only if
at every finished node they share a face (so the child can be complementary).

Adjacency (exact after pruning). For such a pair (p, q) every ray r whose zero
set contains Z(p) & Z(q) shares those faces, so r is complementary at every
finished node and was *not* pruned. The combinatorial test "no third ray's zero
set contains Z(p) & Z(q)" is therefore run against a set that still holds every
possible witness, and stays exact. (Pairs that share no face would not be exact
this way; they are never tested.) tests/test_dd.py checks it against an
unpruned run and against brute force.

Faces (SPEC §5). Every complementary ray lies on {u_n,i = 0} or {r_n,i = 0} at
every node, so for k branching nodes the complementary extreme rays of P are the
union of those of the 2^k faces F (split_faces), deduplicated (merge_results);
the extreme rays of a face of P are the extreme rays of P lying on it. A face run
starts from the equality rows E of F: they are taken first into the initial basis,
and only the initial rays tight at all of them are kept (the face of the
simplicial start cone); every later combination stays on F. Rows in the span of
the chosen rows of E vanish on F ("implied"); with t of them a ray of F is simple
when it has d - 1 + t zeros, and every count below shifts by t (it is 0 without a
face). The pruning and adjacency arguments above hold verbatim on F, a pointed cone.

Zero sets are bitsets: node i's three rows occupy bits 3*(i % 21) + kind of
uint64 word i // 21, so each node's test stays inside one word.
"""
from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from . import exact as xq
from .problem import F_MINUS, F_PLUS, U_N

NODES_PER_WORD = 21
FLOAT_ZERO_TOL = 1e-10   # on unit-norm rows and unit-norm rays


@dataclass
class DDResult:
    """Rays X (R x d; float, or object ints when exact) and their zero flags
    zero (R x 3m bool) on the constraint rows; stats: counters and timings."""

    X: np.ndarray
    zero: np.ndarray
    stats: dict = field(default_factory=dict)

    def zero_u(self) -> np.ndarray:
        """(R, m) bool: u_n,i = 0."""
        return self.zero[:, U_N::3]

    def zero_r(self) -> np.ndarray:
        """(R, m) bool: r_n,i = 0 (both friction edges tight)."""
        return self.zero[:, F_PLUS::3] & self.zero[:, F_MINUS::3]

    def wedged(self) -> np.ndarray:
        """(R,) bool: r != 0 (not a rigid lift-off)."""
        return ~self.zero_r().all(axis=1)


class _Bits:
    """Bit layout of zero sets and node masks."""

    def __init__(self, m: int):
        self.m = m
        self.W = max(1, -(-m // NODES_PER_WORD))
        self.node_mask = np.zeros(self.W, dtype=np.uint64)   # bits 3j of every node slot used
        for i in range(m):
            w, b = divmod(i, NODES_PER_WORD)
            self.node_mask[w] |= np.uint64(1) << np.uint64(3 * b)

    def pos(self, c: int) -> tuple[int, np.uint64]:
        i, kind = divmod(c, 3)
        w, b = divmod(i, NODES_PER_WORD)
        return w, np.uint64(1) << np.uint64(3 * b + kind)

    def pack(self, zero: np.ndarray) -> np.ndarray:
        """(R, 3m) bool -> (R, W) uint64."""
        Z = np.zeros((zero.shape[0], self.W), dtype=np.uint64)
        for c in range(zero.shape[1]):
            w, bit = self.pos(c)
            Z[zero[:, c], w] |= bit
        return Z

    def unpack(self, Z: np.ndarray) -> np.ndarray:
        out = np.zeros((Z.shape[0], 3 * self.m), dtype=bool)
        for c in range(3 * self.m):
            w, bit = self.pos(c)
            out[:, c] = (Z[:, w] & bit) != 0
        return out

    def faces(self, Z: np.ndarray, done: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(R, W) zero words -> (u, r) words with bit 3j set where finished node j has
        u_n = 0 (u) or r_n = 0 (r)."""
        one, two = np.uint64(1), np.uint64(2)
        return Z & done, (Z >> one) & (Z >> two) & done

    def complementary_at(self, Z: np.ndarray, done: np.ndarray) -> np.ndarray:
        """(..., W) zero words -> (...) bool: at every node in `done` (W words of
        bits 3j) u_n = 0 or both friction rows tight."""
        one, two = np.uint64(1), np.uint64(2)
        ok = (Z | ((Z >> one) & (Z >> two))) & done
        return np.all(ok == done, axis=-1)


Face = tuple[tuple[int, ...], tuple[int, ...]]


def complementary_rays(A: np.ndarray, m: int, exact: bool = False,
                       order: list[int] | None = None,
                       progress: Callable[[dict], None] | None = None,
                       face: Face | None = None) -> DDResult:
    """All complementary extreme rays of {x : A x >= 0} (pointed, rank d).

    A: (3m, d) node-wise rows (float unit rows, or exact integer object rows).
    order: node order in which the u_n rows are added (default 0..m-1).
    progress: called after every constraint with {"done", "total", "rays", "elapsed"}.
    face: (contact, gap), node indices: only the rays on the face of P where
      u_n,i = 0 for i in contact and r_i = 0 (both friction rows tight, so r_n,i =
      r_t,i = 0) for i in gap (a node may be in both). The DD then runs on that face
      (a pointed cone of lower dimension): its complementary extreme rays are exactly
      the complementary extreme rays of P that lie on it. See split_faces and
      merge_results; a face run is a pure function of (A, m, exact, face, order).
    """
    t0 = time.perf_counter()
    nc, d = A.shape
    bits = _Bits(m)
    order = list(range(m)) if order is None else list(order)
    eq = _face_rows(face, m)
    basis, implied = _initial_basis(A, m, order, exact, eq)
    X = _initial_rays(A[basis], exact)
    # the face of the simplicial cone: rays that are tight at every equality row
    on_face = np.array([c not in eq for c in basis], dtype=bool)
    zero = np.zeros((len(basis), nc), dtype=bool)
    for j, c in enumerate(basis):
        zero[:, c] = True
        zero[j, c] = False
    zero[:, implied] = True          # equality rows dependent on the chosen ones
    X, zero = X[on_face], zero[on_face]
    Z = bits.pack(zero)
    added = set(basis) | set(implied)
    fixed = np.zeros(bits.W, dtype=np.uint64)          # bits of the equality rows
    for c in eq + implied:
        w, bit = bits.pos(c)
        fixed[w] |= bit
    # a simple ray of the face has d - 1 zeros plus one per dependent equality row
    nz1 = d - 1 + len(implied)
    done = np.zeros(bits.W, dtype=np.uint64)
    for i in range(m):
        if {3 * i, 3 * i + 1, 3 * i + 2} <= added:
            w, b = divmod(i, NODES_PER_WORD)
            done[w] |= np.uint64(1) << np.uint64(3 * b)
    keep = bits.complementary_at(Z, done)
    X, Z = X[keep], Z[keep]
    rest = [3 * i + U_N for i in order if 3 * i + U_N not in added]
    rest += [c for c in range(nc) if c not in added and c not in rest]
    stats = {"initial_rays": int(X.shape[0]), "pairs_tested": 0, "pairs_adjacent": 0,
             "max_rays": int(X.shape[0])}
    if face is not None:
        stats["face"] = _canonical_face(face)
    total = len(rest)
    for step, h in enumerate(rest, 1):
        X, Z = _add_constraint(A[h], h, X, Z, done, fixed, nz1, bits, exact, stats)
        added.add(h)
        i = h // 3
        if {3 * i, 3 * i + 1, 3 * i + 2} <= added:
            w, b = divmod(i, NODES_PER_WORD)
            done[w] |= np.uint64(1) << np.uint64(3 * b)
            keep = bits.complementary_at(Z, done)
            X, Z = X[keep], Z[keep]
        stats["max_rays"] = max(stats["max_rays"], int(X.shape[0]))
        if progress is not None:
            progress({"done": step, "total": total, "rays": int(X.shape[0]),
                      "elapsed": time.perf_counter() - t0})
    stats["seconds"] = time.perf_counter() - t0
    return DDResult(X=X, zero=bits.unpack(Z), stats=stats)


def _canonical_face(face: Face) -> Face:
    contact, gap = face
    return (tuple(sorted({int(i) for i in contact})), tuple(sorted({int(i) for i in gap})))


def _face_rows(face: Face | None, m: int) -> list[int]:
    """Constraint rows that are equalities on the face (u_n rows of contact nodes,
    both friction rows of gap nodes)."""
    if face is None:
        return []
    contact, gap = _canonical_face(face)
    for i in contact + gap:
        if not 0 <= i < m:
            raise ValueError(f"face node {i} is not in 0..{m - 1}")
    rows = [3 * i + U_N for i in contact] + [3 * i + k for i in gap for k in (F_PLUS, F_MINUS)]
    return sorted(rows)


def split_faces(m: int, nodes) -> list[Face]:
    """The 2^k faces of P given by k branching nodes: for every node, u_n = 0
    (contact) or r = 0 (gap). Every complementary ray lies on one of them (on
    several if u_n = r_n = 0 at a branching node). Listed in canonical order
    (node by node, contact before gap; the first node varies slowest)."""
    nodes = [int(i) for i in nodes]
    if len(set(nodes)) != len(nodes) or any(not 0 <= i < m for i in nodes):
        raise ValueError(f"branching nodes must be distinct nodes of 0..{m - 1}: {nodes}")
    faces = []
    for choice in itertools.product((0, 1), repeat=len(nodes)):
        contact = tuple(sorted(i for i, c in zip(nodes, choice) if c == 0))
        gap = tuple(sorted(i for i, c in zip(nodes, choice) if c == 1))
        faces.append((contact, gap))
    return faces


def merge_results(results: list[DDResult]) -> DDResult:
    """Union of face runs (any order), duplicates removed, rays in canonical order
    (lexicographic in the zero flags, as pipeline._fill_rays). A ray found on
    several faces is taken from the first face in canonical face order, so the
    merge does not depend on the order in which the results arrive."""
    if not results:
        raise ValueError("nothing to merge")
    results = sorted(results, key=lambda r: r.stats.get("face", ((), ())))
    X = np.concatenate([r.X for r in results])
    zero = np.concatenate([r.zero for r in results])
    order = np.lexsort(zero.T[::-1])          # stable: first face first among equals
    X, zero = X[order], zero[order]
    if len(zero):
        new = np.ones(len(zero), dtype=bool)
        new[1:] = np.any(zero[1:] != zero[:-1], axis=1)
        X, zero = X[new], zero[new]
    stats = {"faces": len(results),
             "rays_found": int(sum(len(r.X) for r in results)),
             "initial_rays": int(sum(r.stats.get("initial_rays", 0) for r in results)),
             "pairs_tested": int(sum(r.stats.get("pairs_tested", 0) for r in results)),
             "pairs_adjacent": int(sum(r.stats.get("pairs_adjacent", 0) for r in results)),
             "max_rays": int(max(r.stats.get("max_rays", 0) for r in results)),
             "seconds": float(sum(r.stats.get("seconds", 0.0) for r in results)),
             "face_seconds": [float(r.stats.get("seconds", 0.0)) for r in results]}
    return DDResult(X=X, zero=zero, stats=stats)


def _initial_basis(A, m, order, exact, eq=()) -> tuple[list[int], list[int]]:
    """d independent rows: equality rows first, then friction rows, then u_n rows,
    nodes in `order`. Returns (basis, implied): implied are the rows outside the basis
    that lie in the span of the chosen equality rows (they vanish on the whole face)."""
    eq = list(eq)
    rest = [c for c in ([3 * i + k for i in order for k in (F_PLUS, F_MINUS)]
                        + [3 * i + U_N for i in order]) if c not in eq]
    d = A.shape[1]
    chosen: list[int] = []
    if exact:
        def rows(idx):
            return xq.to_q(np.array([[int(v) for v in A[r]] for r in idx], dtype=object))

        def independent(c):
            return rows(chosen + [c]).rank() > len(chosen)

        def take(c):
            chosen.append(c)
    else:
        Q = np.zeros((0, d))

        def independent(c):
            return np.linalg.norm(A[c] - Q.T @ (Q @ A[c])) > 1e-9

        def take(c):
            nonlocal Q
            v = A[c] - Q.T @ (Q @ A[c])
            Q = np.vstack([Q, v / np.linalg.norm(v)])
            chosen.append(c)
    for c in eq:
        if len(chosen) < d and independent(c):
            take(c)
    implied = [c for c in range(A.shape[0]) if c not in chosen and not independent(c)] if eq else []
    for c in rest:
        if len(chosen) == d:
            break
        if c not in implied and independent(c):
            take(c)
    if len(chosen) < d:
        raise ValueError(f"the cone is not pointed: constraint rank {len(chosen)} < {d}")
    return chosen, implied


def _initial_rays(AS, exact) -> np.ndarray:
    """Rays of the simplicial cone {x : AS x >= 0}: the columns of AS^-1 (as rows)."""
    if exact:
        inv = xq.to_q(np.array([[int(v) for v in row] for row in AS], dtype=object)).inv()
        return xq.integer_rows(inv.transpose())
    X = np.linalg.inv(AS).T
    return X / np.linalg.norm(X, axis=1, keepdims=True)


def _add_constraint(a, h, X, Z, done, fixed, nz1, bits, exact, stats):
    """One DD step with complementarity-restricted, exactly tested adjacency."""
    s = X.dot(a)
    if exact:
        pos = np.array([v > 0 for v in s], dtype=bool)
        neg = np.array([v < 0 for v in s], dtype=bool)
    else:
        pos, neg = s > FLOAT_ZERO_TOL, s < -FLOAT_ZERO_TOL
    zer = ~(pos | neg)
    P, M = np.flatnonzero(pos), np.flatnonzero(neg)
    w, bit = bits.pos(h)
    pi, qi = _adjacent_pairs(P, M, Z, done, fixed, nz1, bits, stats)
    Zn = Z[pi] & Z[qi]
    Zn[:, w] |= bit
    if exact:
        Xn = np.empty((len(pi), X.shape[1]), dtype=object)
        for k, (p, q) in enumerate(zip(pi, qi)):
            Xn[k] = xq.primitive(s[p] * X[q] - s[q] * X[p])
    else:
        Xn = s[pi, None] * X[qi] - s[qi, None] * X[pi]
        Xn /= np.linalg.norm(Xn, axis=1, keepdims=True)
    Zz = Z[zer].copy()
    Zz[:, w] |= bit
    return np.concatenate([X[pos], X[zer], Xn]), np.concatenate([Z[pos], Zz, Zn])


def _adjacent_pairs(P, M, Z, done, fixed, nz1, bits, stats):
    """Pairs (p in P, q in M) that share a face at every finished node, have
    |Z(p) & Z(q)| >= nz1 - 1, and are adjacent (combinatorial test, exact).

    Simple rays (exactly nz1 = d - 1 (+ implied face rows) zeros) are joined by
    hashing: for simple p and q, Z(p) & Z(q) has nz1 - 1 elements and equals Z(p) minus one bit and Z(q) minus
    one bit, and every simple witness has that set among its own "keys"
    (its zero set minus one bit). So (p, q) is adjacent iff its key occurs once
    among the keys of P, once among those of M, never among the other rays'
    keys, and no degenerate ray (more than nz1 zeros) contains it. Pairs with a
    degenerate ray are searched by brute force (they are few).
    """
    empty = np.zeros(0, dtype=np.intp)
    if len(P) == 0 or len(M) == 0:
        return empty, empty
    R = Z.shape[0]
    simple = np.bitwise_count(Z).sum(axis=1, dtype=np.int64) == nz1
    sign = np.zeros(R, dtype=np.int8)
    sign[P], sign[M] = 1, -1
    deg = np.flatnonzero(~simple)
    out_p, out_q = [], []
    # simple x simple: hash join on keys
    kp, rp = _keys(Z, P[simple[P]], done, fixed)
    km, rm = _keys(Z, M[simple[M]], done, fixed)
    ko, _ = _keys(Z, np.flatnonzero(simple & (sign == 0)), done, fixed)
    pi, qi = _join_keys(kp, rp, km, rm, ko)
    stats["pairs_tested"] += len(pi)
    if len(pi):
        Zc = Z[pi] & Z[qi]
        good = bits.complementary_at(Zc, done)
        if len(deg):
            Zd = Z[deg]
            for c0 in range(0, len(pi), 4096):
                zc = Zc[c0:c0 + 4096]
                hit = np.all((Zd[None, :, :] & zc[:, None, :]) == zc[:, None, :], axis=-1).any(axis=1)
                good[c0:c0 + 4096] &= ~hit
        stats["pairs_adjacent"] += int(good.sum())
        out_p.append(pi[good])
        out_q.append(qi[good])
    # pairs with a degenerate ray: brute force, witnesses among all rays
    # (a witness of such a pair shares >= nz1-1 zeros with its degenerate member g)
    for g in P[~simple[P]]:
        pi, qi = _candidates(np.array([g]), M, Z, done, nz1, bits)
        near = np.bitwise_count(Z & Z[g]).sum(axis=1, dtype=np.int64) >= nz1 - 1
        pi, qi = _adjacent(pi, qi, Z, Z[near], stats)
        out_p.append(pi)
        out_q.append(qi)
    sp = P[simple[P]]
    for g in M[~simple[M]]:
        pi, qi = _candidates(sp, np.array([g]), Z, done, nz1, bits)
        near = np.bitwise_count(Z & Z[g]).sum(axis=1, dtype=np.int64) >= nz1 - 1
        pi, qi = _adjacent(pi, qi, Z, Z[near], stats)
        out_p.append(pi)
        out_q.append(qi)
    if not out_p:
        return empty, empty
    return np.concatenate(out_p), np.concatenate(out_q)


def _join_keys(kp, rp, km, rm, ko):
    """Pairs (p, q) whose key occurs exactly twice among all keys: once for p in P,
    once for q in M (one sort of every key, labelled by side)."""
    keys = np.concatenate([kp, km, ko])
    side = np.concatenate([np.zeros(len(kp), np.int8), np.ones(len(km), np.int8),
                           np.full(len(ko), 2, np.int8)])
    owner = np.concatenate([rp, rm, np.zeros(len(ko), dtype=np.intp)])
    order = np.argsort(keys, kind="stable")
    ks, ss, os_ = keys[order], side[order], owner[order]
    n = len(ks)
    if n < 2:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    same = ks[1:] == ks[:-1]
    # a run of exactly two: same[i] and not same[i-1] and not same[i+1]
    prev = np.concatenate([[False], same[:-1]])
    nxt = np.concatenate([same[1:], [False]])
    start = np.flatnonzero(same & ~prev & ~nxt)
    ok = (ss[start] == 0) & (ss[start + 1] == 1)
    start = start[ok]
    return os_[start], os_[start + 1]


def _keys(Z, rows, done, fixed):
    """Keys of simple rays: each zero set with one *removable* bit removed (one
    whose loss keeps a face at every finished node: only such keys can be the
    common zero set of a combinable pair or of its witnesses), as comparable
    scalars; returns (keys, ray index of each key)."""
    if len(rows) == 0:
        return _as_key(np.zeros((0, Z.shape[1]), dtype=np.uint64)), np.zeros(0, dtype=np.intp)
    Zr = Z[rows]
    one, two = np.uint64(1), np.uint64(2)
    u = Zr & done
    f = (Zr >> one) & (Zr >> two) & done
    wild = u & f
    req_u, req_f = u & ~wild, f & ~wild
    removable = Zr & ~(req_u | (req_f << one) | (req_f << two) | fixed)
    keys, owner = [], []
    for w in range(Z.shape[1]):
        col = removable[:, w]
        present = np.bitwise_or.reduce(col) if len(col) else np.uint64(0)
        for b in range(64):
            bit = np.uint64(1) << np.uint64(b)
            if not present & bit:
                continue
            sel = np.flatnonzero(col & bit)
            K = Zr[sel]
            K[:, w] ^= bit
            keys.append(K)
            owner.append(rows[sel])
    if not keys:
        return _as_key(np.zeros((0, Z.shape[1]), dtype=np.uint64)), np.zeros(0, dtype=np.intp)
    return _as_key(np.concatenate(keys)), np.concatenate(owner)


def _as_key(K):
    if K.shape[1] == 1:
        return K[:, 0].copy()
    K = np.ascontiguousarray(K)
    return K.view(np.dtype((np.void, 8 * K.shape[1]))).ravel()


def _candidates(P, M, Z, done, nz1, bits):
    """All (p, q) in P x M with a shared face at finished nodes and |Z(p) & Z(q)| >= nz1-1."""
    ZP = Z[P]
    chunk = max(1, (1 << 20) // max(1, len(P)))
    out_p, out_q = [], []
    for a in range(0, len(M), chunk):
        q = M[a:a + chunk]
        common = ZP[None, :, :] & Z[q][:, None, :]            # (cq, |P|, W)
        ok = np.bitwise_count(common).sum(axis=-1, dtype=np.int64) >= nz1 - 1
        ok &= bits.complementary_at(common, done)
        qq, pp = np.nonzero(ok)
        out_p.append(P[pp])
        out_q.append(q[qq])
    return np.concatenate(out_p), np.concatenate(out_q)


def _adjacent(pi, qi, Z, Zw, stats):
    """Keep pairs for which no ray of Zw but p and q has a zero set containing Z(p) & Z(q)
    (Zw must hold p, q and every possible witness)."""
    stats["pairs_tested"] += len(pi)
    if len(pi) == 0:
        return pi, qi
    keep = np.zeros(len(pi), dtype=bool)
    chunk = max(1, (1 << 22) // max(1, Zw.shape[0] * Zw.shape[1]))
    for a in range(0, len(pi), chunk):
        Zc = Z[pi[a:a + chunk]] & Z[qi[a:a + chunk]]          # (c, W)
        contains = np.all((Zw[None, :, :] & Zc[:, None, :]) == Zc[:, None, :], axis=-1)
        keep[a:a + chunk] = contains.sum(axis=1) == 2
    stats["pairs_adjacent"] += int(keep.sum())
    return pi[keep], qi[keep]
