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

Row order. The order in which rows are added changes the intermediate ray sets
(by 2x and more on plug2d and on faces), never the result. Float runs choose each
next row greedily (_next_row: smallest expected ray set after the step, scored on
a sample of the rays); exact runs, and runs given a node order, use the static
order (u_n rows node by node, then the friction rows left out of the basis).

Zero sets are bitsets in nodesets.RowBits's layout: node i's three rows occupy
bits 3*(i % 21) + kind of uint64 word i // 21, so each node's test stays inside one word.
"""
from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from . import exact as xq
from .nodesets import Face, RowBits, canonical_face, canonical_order
from .problem import F_MINUS, F_PLUS, U_N

FLOAT_ZERO_TOL = 1e-10   # on unit-norm rows and unit-norm rays
BASIS_DEPENDENT = 1e-9   # a unit row this close to the span of others is dependent
BASIS_WELL_POSED = 1e-3  # initial basis rows are taken this far from the span first
#: a float sign decision |a.x| within this factor of FLOAT_ZERO_TOL (either side) is a
#: close call: rounding may have decided it (stats["close_calls"]; numerics.py falls back
#: to exact arithmetic or reports it). Measured (scripts/stress.py): every float result
#: that differed from exact arithmetic had close calls, or cancelled (CANCELLATION_MIN), or
#: came from an ill-conditioned K; plug2d at taper 10 deg up to m = 16 has none.
CLOSE_CALL_FACTOR = 10.0
#: a new ray whose computation cancels to this fraction of its terms carries a relative
#: rounding error of eps / CANCELLATION_MIN = FLOAT_ZERO_TOL: its later zero tests are
#: decided by rounding (stats["cancellation"], numerics.py)
CANCELLATION_MIN = float(np.finfo(float).eps) / FLOAT_ZERO_TOL


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


def complementary_rays(A: np.ndarray, m: int, exact: bool = False,
                       order: list[int] | str | None = None,
                       progress: Callable[[dict], None] | None = None,
                       face: Face | None = None) -> DDResult:
    """All complementary extreme rays of {x : A x >= 0} (pointed, rank d).

    A: (3m, d) node-wise rows (float unit rows, or exact integer object rows).
    order: the order in which the remaining rows are added (it changes the work,
      never the result). A list of nodes: their u_n rows in that order, then the
      friction rows left out of the initial basis ("static"). "greedy": each step
      takes the row after which the ray set is expected to be smallest (_next_row;
      float only). "static": nodes 0..m-1. None (default): "greedy" in float,
      "static" in exact mode.
    progress: called after every constraint with {"done", "total", "rays", "bytes" (of the
      live rays and their zero flags), "elapsed"}.
    face: (contact, gap), node indices: only the rays on the face of P where
      u_n,i = 0 for i in contact and r_i = 0 (both friction rows tight, so r_n,i =
      r_t,i = 0) for i in gap (a node may be in both). The DD then runs on that face
      (a pointed cone of lower dimension): its complementary extreme rays are exactly
      the complementary extreme rays of P that lie on it. See split_faces and
      merge_results; a face run is a pure function of (A, m, exact, face, order).
    """
    t0 = time.perf_counter()
    nc, d = A.shape
    bits = RowBits(m)
    if isinstance(order, str) and order not in ("greedy", "static"):
        raise ValueError(f'order must be a list of nodes, "greedy" or "static", got {order!r}')
    greedy = (order is None and not exact) or (isinstance(order, str) and order == "greedy")
    if greedy and exact:
        raise ValueError('order="greedy" needs float arithmetic')
    order = list(range(m)) if order is None or isinstance(order, str) else [int(i) for i in order]
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
            bits.add_node(done, i)
    keep = bits.complementary_at(Z, done)
    X, Z = X[keep], Z[keep]
    rest = [3 * i + U_N for i in order if 3 * i + U_N not in added]
    rest += [c for c in range(nc) if c not in added and c not in rest]
    stats = {"initial_rays": int(X.shape[0]), "pairs_tested": 0, "pairs_adjacent": 0,
             "max_rays": int(X.shape[0])}
    if not exact:
        stats.update(close_calls=0, closest=None, cancellation=1.0)
    if face is not None:
        stats["face"] = canonical_face(face)
    total = len(rest)
    work: dict = {}                  # buffers reused from step to step
    pending = list(rest)
    for step in range(1, total + 1):
        h = _next_row(pending, A, X, Z, added, bits) if greedy else pending[0]
        pending.remove(h)
        added.add(h)
        i = h // 3
        done_after = done.copy()
        if {3 * i, 3 * i + 1, 3 * i + 2} <= added:
            bits.add_node(done_after, i)
        X, Z = _add_constraint(A[h], h, X, Z, done, done_after, fixed, nz1, bits, exact, stats, work)
        done = done_after
        stats["max_rays"] = max(stats["max_rays"], int(X.shape[0]))
        if progress is not None:
            progress({"done": step, "total": total, "rays": int(X.shape[0]),
                      "bytes": int(X.nbytes + Z.nbytes), "elapsed": time.perf_counter() - t0})
    stats["seconds"] = time.perf_counter() - t0
    return DDResult(X=X, zero=bits.unpack(Z), stats=stats)


GREEDY_ALPHA = 1.5      # expected new rays per ray on the smaller side of a step
GREEDY_SAMPLE = 20000   # rays sampled to score the candidate rows


def _next_row(pending, A, X, Z, added, bits):
    """The greedy choice of the next row: the pending row c after which the ray set
    is expected to be smallest, i.e. rays kept (c.x >= 0, and complementary at c's
    node if c finishes it) + GREEDY_ALPHA x the smaller of #(c.x > 0), #(c.x < 0)
    (new rays), counted on every k-th ray (at most GREEDY_SAMPLE of them). First
    minimum wins, so the choice is a deterministic function of the ray set."""
    R = X.shape[0]
    if len(pending) == 1 or R == 0:
        return pending[0]
    k = max(1, R // GREEDY_SAMPLE)
    Xs, Zs = X[::k], Z[::k]
    S = np.einsum("ij,kj->ik", Xs, A[pending])
    pos, neg = S > FLOAT_ZERO_TOL, S < -FLOAT_ZERO_TOL
    npos, nneg = pos.sum(axis=0), neg.sum(axis=0)
    pruned = np.zeros(len(pending), dtype=np.int64)

    def tight(c):
        w, bit = bits.pos(c)
        return (Zs[:, w] & bit) != 0
    for j, c in enumerate(pending):
        i = c // 3
        if all(r in added or r == c for r in (3 * i, 3 * i + 1, 3 * i + 2)):
            # c finishes node i: a ray with c.x > 0 survives only on the other face
            other = tight(3 * i + F_PLUS) & tight(3 * i + F_MINUS) if c % 3 == U_N else tight(3 * i + U_N)
            pruned[j] = int((pos[:, j] & ~other).sum())
    score = (len(Xs) - nneg - pruned) + GREEDY_ALPHA * np.minimum(npos, nneg)
    return pending[int(np.argmin(score))]


def _face_rows(face: Face | None, m: int) -> list[int]:
    """Constraint rows that are equalities on the face (u_n rows of contact nodes,
    both friction rows of gap nodes)."""
    if face is None:
        return []
    contact, gap = canonical_face(face)
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
    order, words = canonical_order(zero, return_words=True)   # stable: first face first
    words = words[order]
    new = np.ones(len(zero), dtype=bool)
    new[1:] = np.any(words[1:] != words[:-1], axis=1)
    keep = order[new]
    X, zero = X[keep], zero[keep]
    stats = {"faces": len(results),
             "rays_found": int(sum(len(r.X) for r in results)),
             "initial_rays": int(sum(r.stats.get("initial_rays", 0) for r in results)),
             "pairs_tested": int(sum(r.stats.get("pairs_tested", 0) for r in results)),
             "pairs_adjacent": int(sum(r.stats.get("pairs_adjacent", 0) for r in results)),
             "max_rays": int(max(r.stats.get("max_rays", 0) for r in results)),
             "seconds": float(sum(r.stats.get("seconds", 0.0) for r in results)),
             "close_calls": int(sum(r.stats.get("close_calls", 0) for r in results)),
             "cancellation": float(min(r.stats.get("cancellation", 1.0) for r in results)),
             "closest": _closest(r.stats.get("closest") for r in results),
             "face_seconds": [float(r.stats.get("seconds", 0.0)) for r in results]}
    return DDResult(X=X, zero=zero, stats=stats)


#: run.face_split = "auto" splits from this m on (below, one DD takes < 1 s)
FACE_SPLIT_MIN_M = 16
#: at most this many branching nodes: the face where every branching node is in
#: contact holds ~97% of plug2d's rays and costs ~40% of the full run whatever k is,
#: so more faces only add work (scripts/bench_dd_faces.py, plug2d m = 18: k = 3
#: sums 6.4 s CPU, largest face 2.8 s; k = 4 sums 8.6 s, largest 4.2 s)
MAX_BRANCHING_NODES = 3


def branching_nodes(m: int, split: int | str = "auto") -> list[int]:
    """The nodes whose faces split the DD (SPEC §5): the last k nodes m-k..m-1, k
    from the scene's run.face_split — "auto": MAX_BRANCHING_NODES when m >=
    FACE_SPLIT_MIN_M, else 0 (one DD); an integer: that many — at most m - 1.

    A function of the scene alone, never of the rank count: a ray's floats depend on
    the DD's path to it, so one split gives the same bits on 1 or 100 ranks. (On
    plug2d the last nodes are the top of the right wall; splitting there was the
    cheapest of the node sets measured: the bottom nodes or both top corners cost
    1.5-2x more CPU in total.)"""
    k = (MAX_BRANCHING_NODES if m >= FACE_SPLIT_MIN_M else 0) if split == "auto" else int(split)
    k = max(0, min(k, m - 1))
    return list(range(m - k, m))


def _closest(values) -> float | None:
    """Of the face runs' "closest" values (None: no close call), the one nearest to
    FLOAT_ZERO_TOL in ratio."""
    vals = [v for v in values if v is not None]
    return min(vals, key=lambda v: abs(math.log(v / FLOAT_ZERO_TOL))) if vals else None


def _initial_basis(A, m, order, exact, eq=()) -> tuple[list[int], list[int]]:
    """d independent rows: equality rows first, then friction rows, then u_n rows,
    nodes in `order`. Returns (basis, implied): implied are the rows outside the basis
    that lie in the span of the chosen equality rows (they vanish on the whole face).
    Float: a row whose distance to the span of those chosen before it is below
    BASIS_WELL_POSED is passed over at first (a nearly dependent basis row makes the
    initial rays, and every ray built from them, inaccurate); if fewer than d rows
    are taken, the rest are taken largest distance first, down to BASIS_DEPENDENT."""
    eq = list(eq)
    rest = [c for c in ([3 * i + k for i in order for k in (F_PLUS, F_MINUS)]
                        + [3 * i + U_N for i in order]) if c not in eq]
    d = A.shape[1]
    chosen: list[int] = []
    if exact:
        def rows(idx):
            return xq.to_q(np.array([[int(v) for v in A[r]] for r in idx], dtype=object))

        def distance(c):
            return 1.0 if rows(chosen + [c]).rank() > len(chosen) else 0.0

        def take(c):
            chosen.append(c)
    else:
        Q = np.zeros((0, d))

        def distance(c):
            return float(np.linalg.norm(A[c] - Q.T @ (Q @ A[c])))

        def take(c):
            nonlocal Q
            v = A[c] - Q.T @ (Q @ A[c])
            Q = np.vstack([Q, v / np.linalg.norm(v)])
            chosen.append(c)
    for c in eq:
        if len(chosen) < d and distance(c) > BASIS_DEPENDENT:
            take(c)
    implied = [c for c in range(A.shape[0]) if c not in chosen and distance(c) <= BASIS_DEPENDENT] if eq else []
    rest = [c for c in rest if c not in implied]
    for c in rest:
        if len(chosen) == d:
            break
        if distance(c) > BASIS_WELL_POSED:
            take(c)
    while len(chosen) < d:
        left = [c for c in rest if c not in chosen]
        far = [distance(c) for c in left]
        if not far or max(far) <= BASIS_DEPENDENT:
            break
        take(left[int(np.argmax(far))])
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


def _add_constraint(a, h, X, Z, done, done_after, fixed, nz1, bits, exact, stats, work):
    """One DD step with complementarity-restricted, exactly tested adjacency.

    Returns the rays of the new cone (old rays with a >= 0 in their order, then the
    new ones), minus those that are not complementary at the nodes of done_after
    (dropped before they are copied)."""
    # (einsum, not BLAS: no BLAS threads spinning next to the other ranks)
    s = X.dot(a) if exact else np.einsum("ij,j->i", X, a)
    if exact:
        pos = np.array([v > 0 for v in s], dtype=bool)
        neg = np.array([v < 0 for v in s], dtype=bool)
    else:
        pos, neg = s > FLOAT_ZERO_TOL, s < -FLOAT_ZERO_TOL
        _count_close_calls(s, stats)
    zer = ~(pos | neg)
    P, M = np.flatnonzero(pos), np.flatnonzero(neg)
    w, bit = bits.pos(h)
    pi, qi = _adjacent_pairs(P, M, Z, done, fixed, nz1, bits, stats, work)
    Z = Z.copy()
    Z[zer, w] |= bit
    Zn = Z[pi] & Z[qi]
    Zn[:, w] |= bit
    keep = ~neg
    if np.any(done_after != done):
        keep &= bits.complementary_at(Z, done_after)
        new_ok = bits.complementary_at(Zn, done_after)
        pi, qi, Zn = pi[new_ok], qi[new_ok], Zn[new_ok]
    n0 = int(keep.sum())
    Xo = np.empty((n0 + len(pi), X.shape[1]), dtype=X.dtype)
    np.compress(keep, X, axis=0, out=Xo[:n0])
    if exact:
        for k, (p, q) in enumerate(zip(pi, qi)):
            Xo[n0 + k] = xq.primitive(s[p] * X[q] - s[q] * X[p])
    else:
        tmp = np.empty((min(CHUNK, len(pi)), X.shape[1]))
        for c in range(0, len(pi), CHUNK):
            p, q = pi[c:c + CHUNK], qi[c:c + CHUNK]
            o, t = Xo[n0 + c:n0 + c + len(p)], tmp[:len(p)]
            np.take(X, q, axis=0, out=o)
            o *= s[p][:, None]
            np.take(X, p, axis=0, out=t)
            t *= s[q][:, None]
            o -= t
            nrm = np.sqrt(np.einsum("ij,ij->i", o, o))
            o /= nrm[:, None]
            _note_cancellation(nrm, s[p], s[q], stats)
    return Xo, np.concatenate([Z[keep], Zn])


def _count_close_calls(s: np.ndarray, stats: dict) -> None:
    """Count the values of s (one float DD step's a.x) within CLOSE_CALL_FACTOR of
    FLOAT_ZERO_TOL into stats["close_calls"]; stats["closest"]: the |a.x| nearest to the
    tolerance (in ratio) so far. One pass over s; the log only over the close ones."""
    a = np.abs(s)
    close = a[(a > FLOAT_ZERO_TOL / CLOSE_CALL_FACTOR) & (a < FLOAT_ZERO_TOL * CLOSE_CALL_FACTOR)]
    if close.size == 0:
        return
    stats["close_calls"] += int(close.size)
    v = float(close[np.argmin(np.abs(np.log(close / FLOAT_ZERO_TOL)))])
    stats["closest"] = _closest([stats["closest"], v])


def _note_cancellation(nrm: np.ndarray, sp: np.ndarray, sq: np.ndarray, stats: dict) -> None:
    """stats["cancellation"]: the least |o| / (|s_p| + |s_q|) over the new rays
    o = s_p x_q - s_q x_p (unit x, so 1 means no cancellation). A new ray's relative
    rounding error is about eps over this ratio: below CANCELLATION_MIN it reaches the
    zero tolerance."""
    if nrm.size:
        stats["cancellation"] = min(stats["cancellation"], float((nrm / (np.abs(sp) + np.abs(sq))).min()))


CHUNK = 1 << 12                  # rows per block of new-ray arithmetic (stays in cache)
HASH_MUL = (np.uint64(0x9E3779B97F4A7C15), np.uint64(0xC2B2AE3D27D4EB4F), np.uint64(0x165667B19E3779F9))
P_SIDE, M_SIDE, O_SIDE, PROBE = 0, 1, 2, 3


def _adjacent_pairs(P, M, Z, done, fixed, nz1, bits, stats, work):
    """Pairs (p in P, q in M) that share a face at every finished node, have
    |Z(p) & Z(q)| >= nz1 - 1, and are adjacent (combinatorial test, exact).

    A ray is simple when it has exactly nz1 zeros (d - 1, plus the rows implied by
    a face), else degenerate. The *keys* of a simple ray are its zero set minus one removable bit (one whose loss keeps a face
    at every finished node). For simple p and q, C = Z(p) & Z(q) has nz1 - 1
    elements iff it is a key of both, and then every simple witness (a third ray
    whose zero set contains C) has C among its keys too. So (p, q) is adjacent iff
    C occurs once among the keys of P, once among those of M, never among those of
    the other simple rays, and no degenerate ray (more than nz1 zeros) contains C.
    For a degenerate g and a simple q, C = Z(g) & Z(q) with |C| >= nz1 - 1 is a key
    of q (C is not Z(q): two extreme rays never have nested zero sets), so the pair
    is adjacent iff C occurs exactly once among the simple rays' keys (q's own) and
    no degenerate ray but g contains C: C is looked up as a "probe" in the same join.
    Pairs of two degenerate rays are tested by brute force (they are rare).
    (In exact arithmetic the counting conditions always hold once C is a key of a
    simple ray: its nz1 - 1 rows have rank d - 2, so the face {x : A_C x = 0} is
    2-dimensional and holds no third extreme ray. They stay as a cheap check on
    float zero sets; the join's cost is in finding the common keys.)

    The join (_join) never sorts all keys: the hashes of the keys of the side with
    fewer keys (and of the probes) mark a table; the other side's keys are generated
    one removed bit at a time and kept only if their hash is marked; then the small
    side is filtered by a table of the survivors, and both once more with other hash
    bits. A key present on both sides (or probed) has every one of its occurrences
    survive, so the exact join by sorting, run on the survivors only (about two per
    adjacent pair), counts occurrences exactly. Hash collisions only let extra keys
    through to the exact join.
    """
    empty = np.zeros(0, dtype=np.intp)
    if len(P) == 0 or len(M) == 0:
        return empty, empty
    R = Z.shape[0]
    simple = np.bitwise_count(Z).sum(axis=1, dtype=np.int64) == nz1
    sign = np.zeros(R, dtype=np.int8)
    sign[P], sign[M] = 1, -1
    deg = np.flatnonzero(~simple)
    sP, sM = P[simple[P]], M[simple[M]]
    gP, gM = P[~simple[P]], M[~simple[M]]
    out_p, out_q = [], []
    # degenerate x simple: candidate pairs, probed in the join
    cand_p, cand_q = [empty], [empty]
    for g in gP:
        pi, qi = _candidates(np.array([g]), sM, Z, done, nz1, bits)
        cand_p.append(pi)
        cand_q.append(qi)
    for g in gM:
        pi, qi = _candidates(sP, np.array([g]), Z, done, nz1, bits)
        cand_p.append(pi)
        cand_q.append(qi)
    cand_p, cand_q = np.concatenate(cand_p), np.concatenate(cand_q)
    probes = Z[cand_p] & Z[cand_q]
    pi, qi, probe_ok = _join(Z, sP, sM, np.flatnonzero(simple & (sign == 0)), probes, done, fixed, work)
    stats["pairs_tested"] += len(pi) + len(cand_p)
    if len(deg):
        Zd = Z[deg]
        good = _contained_count(Z[pi] & Z[qi], Zd) == 0
        pi, qi = pi[good], qi[good]
        probe_ok &= _contained_count(probes, Zd) == 1          # g itself only
    stats["pairs_adjacent"] += len(pi) + int(probe_ok.sum())
    out_p += [pi, cand_p[probe_ok]]
    out_q += [qi, cand_q[probe_ok]]
    # degenerate x degenerate: brute force, witnesses among the rays sharing
    # >= nz1 - 1 zeros with the degenerate p
    for g in gP:
        pi, qi = _candidates(np.array([g]), gM, Z, done, nz1, bits)
        if len(pi):
            near = np.bitwise_count(Z & Z[g]).sum(axis=1, dtype=np.int64) >= nz1 - 1
            pi, qi = _adjacent(pi, qi, Z, Z[near], stats)
            out_p.append(pi)
            out_q.append(qi)
    return np.concatenate(out_p), np.concatenate(out_q)


def _contained_count(C, Zd):
    """(n, W) sets C, (k, W) sets Zd -> (n,) number of rows of Zd containing each C."""
    out = np.zeros(len(C), dtype=np.int64)
    step = max(1, (1 << 22) // max(1, Zd.shape[0] * Zd.shape[1]))
    for a in range(0, len(C), step):
        c = C[a:a + step]
        out[a:a + step] = np.all((Zd[None, :, :] & c[:, None, :]) == c[:, None, :], axis=-1).sum(axis=1)
    return out


def _table(work: dict, B: int) -> np.ndarray:
    """A zeroed bool table of 2^B slots, from a buffer reused across steps (a fresh
    one would page-fault in every step)."""
    buf = work.get("table")
    if buf is None or len(buf) < (1 << B):
        buf = work["table"] = np.zeros(1 << B, dtype=bool)
        return buf
    table = buf[:1 << B]
    table.fill(False)
    return table


def _removable(Zr, done, fixed):
    """Bits of each zero set whose removal keeps a face at every finished node (never
    an equality row of the face: those are in every zero set)."""
    one, two = np.uint64(1), np.uint64(2)
    u = Zr & done
    f = (Zr >> one) & (Zr >> two) & done
    wild = u & f
    req_u, req_f = u & ~wild, f & ~wild
    return Zr & ~(req_u | (req_f << one) | (req_f << two) | fixed)


def _key_bits(rem):
    """The removable bits present in rem (n, W): yields (w, bit, rows having it)."""
    for w in range(rem.shape[1]):
        col = rem[:, w]
        present = int(np.bitwise_or.reduce(col)) if len(col) else 0
        while present:
            low = present & -present
            present ^= low
            bit = np.uint64(low)
            yield w, bit, np.flatnonzero(col & bit)


def _hash(K):
    """(n, W) uint64 -> (n,) uint64, linear in the words (mod 2^64), so that the hash
    of a key is the hash of its zero set minus that of the removed bit. Table slots
    are its top bits."""
    h = K[:, 0] * HASH_MUL[0]
    for w in range(1, K.shape[1]):
        h += K[:, w] * HASH_MUL[w % len(HASH_MUL)]
    return h


def _bit_hash(w, bit):
    """_hash of the one-bit set (word w, bit)."""
    return np.uint64(int(bit) * int(HASH_MUL[w % len(HASH_MUL)]) % (1 << 64))


class _KeySet:
    """The keys of a set of simple rays (global indices rows, zero sets Zr), kept as
    (row, removed bit) and their hashes; keys are built only for the survivors."""

    def __init__(self, Zr, rows, done, fixed, side):
        self.Zr, self.rows, self.side = Zr, rows, side
        self.rem = _removable(Zr, done, fixed)
        self.count = int(np.bitwise_count(self.rem).sum(dtype=np.int64))
        self.hz = _hash(Zr)

    def chunks(self, shift):
        """Yields (w, bit, local rows, table slots) one removed bit at a time."""
        for w, bit, sel in _key_bits(self.rem):
            yield w, bit, sel, ((self.hz[sel] - _bit_hash(w, bit)) >> shift).view(np.int64)

    def keys(self, parts):
        """Keys and ray indices of the (w, bit, local rows) parts."""
        W = self.Zr.shape[1]
        if not parts:
            return np.zeros((0, W), dtype=np.uint64), np.zeros(0, dtype=np.intp)
        Ks, os_ = [], []
        for w, bit, sel in parts:
            K = self.Zr[sel]
            K[:, w] ^= bit
            Ks.append(K)
            os_.append(self.rows[sel])
        return np.concatenate(Ks), np.concatenate(os_)


def _join(Z, sP, sM, sO, probes, done, fixed, work):
    """Simple pairs (p, q) whose key occurs exactly twice among the simple rays' keys
    (once in P, once in M), and for each probe whether it occurs exactly once."""
    sets = [_KeySet(Z[sP], sP, done, fixed, P_SIDE), _KeySet(Z[sM], sM, done, fixed, M_SIDE)]
    small, big = sorted(sets, key=lambda k: k.count)
    other = _KeySet(Z[sO], sO, done, fixed, O_SIDE)
    B = int(np.clip(int(np.ceil(np.log2(max(small.count + len(probes), 1)))) + 3, 12, 28))
    shift = np.uint64(64 - B)
    hp = (_hash(probes) >> shift).view(np.int64)
    table = _table(work, B)
    small_parts = list(small.chunks(shift))
    for _, _, _, h in small_parts:
        table[h] = True
    table[hp] = True
    # the other side, filtered while it is generated; the simple rays outside P and M
    big_parts = []
    for w, bit, sel, h in big.chunks(shift):
        hit = table[h]
        big_parts.append((w, bit, sel[hit], h[hit]))
    other_parts = [(w, bit, sel[table[h]]) for w, bit, sel, h in other.chunks(shift)]
    table[:] = False
    for _, _, _, h in big_parts:
        table[h] = True
    table[hp] = True
    small_parts = [(w, bit, sel[hit], h[hit]) for w, bit, sel, h in small_parts
                   for hit in [table[h]]]
    # one more round each way with the next B bits of the hash (an independent
    # filter): false positives of the first round are mostly gone
    shift2 = np.uint64(64 - 2 * B)
    mask = np.int64((1 << B) - 1)
    hp2 = ((_hash(probes) >> shift2).view(np.int64)) & mask
    small_parts = [(w, bit, sel, ((small.hz[sel] - _bit_hash(w, bit)) >> shift2).view(np.int64) & mask)
                   for w, bit, sel, _ in small_parts]
    big_parts = [(w, bit, sel, ((big.hz[sel] - _bit_hash(w, bit)) >> shift2).view(np.int64) & mask)
                 for w, bit, sel, _ in big_parts]
    table[:] = False
    for _, _, _, h in small_parts:
        table[h] = True
    table[hp2] = True
    big_parts = [(w, bit, sel[hit], h[hit]) for w, bit, sel, h in big_parts for hit in [table[h]]]
    table[:] = False
    for _, _, _, h in big_parts:
        table[h] = True
    table[hp2] = True
    small_parts = [(w, bit, sel[table[h]]) for w, bit, sel, h in small_parts]
    del table
    Ks, os_ = small.keys(small_parts)
    Kb, ob = big.keys([(w, bit, sel) for w, bit, sel, _ in big_parts])
    Ko, oo = other.keys(other_parts)
    # exact join on the survivors
    keys = np.concatenate([Ks, Kb, Ko, probes])
    side = np.concatenate([np.full(len(Ks), small.side, np.int8), np.full(len(Kb), big.side, np.int8),
                           np.full(len(Ko), O_SIDE, np.int8), np.full(len(probes), PROBE, np.int8)])
    owner = np.concatenate([os_, ob, oo, np.arange(len(probes), dtype=np.intp)])
    probe_ok = np.zeros(len(probes), dtype=bool)
    empty = np.zeros(0, dtype=np.intp)
    if len(keys) == 0:
        return empty, empty, probe_ok
    order = np.argsort(_as_key(keys))
    ks, ss, os_ = keys[order], side[order], owner[order]
    first = np.ones(len(ks), dtype=bool)
    first[1:] = np.any(ks[1:] != ks[:-1], axis=1)
    run = np.cumsum(first) - 1
    nr = int(run[-1]) + 1
    real = ss != PROBE
    count = np.bincount(run[real], minlength=nr)
    isp, ism = ss == P_SIDE, ss == M_SIDE
    cp = np.bincount(run[isp], minlength=nr)
    cm = np.bincount(run[ism], minlength=nr)
    p_of = np.zeros(nr, dtype=np.intp)
    q_of = np.zeros(nr, dtype=np.intp)
    p_of[run[isp]] = os_[isp]
    q_of[run[ism]] = os_[ism]
    good = np.flatnonzero((count == 2) & (cp == 1) & (cm == 1))
    pr = ss == PROBE
    probe_ok[os_[pr]] = count[run[pr]] == 1
    return p_of[good], q_of[good], probe_ok


def _as_key(K):
    if K.shape[1] == 1:
        return K[:, 0].copy()
    K = np.ascontiguousarray(K)
    return K.view(np.dtype((np.void, 8 * K.shape[1]))).ravel()


def _candidates(P, M, Z, done, nz1, bits):
    """All (p, q) in P x M with a shared face at finished nodes and |Z(p) & Z(q)| >= nz1-1."""
    ZP = Z[P]
    chunk = max(1, (1 << 20) // max(1, len(P)))
    out_p, out_q = [np.zeros(0, dtype=np.intp)], [np.zeros(0, dtype=np.intp)]
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
