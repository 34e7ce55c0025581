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
union of those of the 2^k faces F (faces.split_faces), deduplicated (faces.merge_results);
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

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from hpcwedge import exact as xq
from hpcwedge.contact.problem import F_MINUS, F_PLUS, U_N
from hpcwedge.nodesets import Face, RowBits, canonical_face
from hpcwedge.rays.adjacency import adjacent_pairs

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
CHUNK = 1 << 12                  # rows per block of new-ray arithmetic (stays in cache)


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
                       face: Face | None = None, well_posed: float = BASIS_WELL_POSED) -> DDResult:
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
      the complementary extreme rays of P that lie on it. See faces.split_faces and
      faces.merge_results; a face run is a pure function of (A, m, exact, face, order).
    well_posed: initial_basis's threshold for a well-posed basis row (float runs).
    """
    t0 = time.perf_counter()
    bits = RowBits(m)
    greedy, order = _row_order(order, exact, m)
    X, Z, added, fixed, nz1 = _start_cone(A, m, bits, order, exact, face_rows(face, m), well_posed)
    done = np.zeros(bits.W, dtype=np.uint64)
    for i in range(m):
        if _node_finished(i, added):
            bits.add_node(done, i)
    keep = bits.complementary_at(Z, done)
    X, Z = X[keep], Z[keep]
    rest = [3 * i + U_N for i in order if 3 * i + U_N not in added]
    rest += [c for c in range(A.shape[0]) if c not in added and c not in rest]
    stats = _initial_stats(X, exact, face)
    total = len(rest)
    work: dict = {}                  # buffers reused from step to step
    pending = list(rest)
    for step in range(1, total + 1):
        h = _next_row(pending, A, X, Z, added, bits) if greedy else pending[0]
        pending.remove(h)
        added.add(h)
        done_after = done.copy()
        if _node_finished(h // 3, added):
            bits.add_node(done_after, h // 3)
        X, Z = _add_constraint(A[h], h, X, Z, done, done_after, fixed, nz1, bits, exact, stats, work)
        done = done_after
        stats["max_rays"] = max(stats["max_rays"], int(X.shape[0]))
        if progress is not None:
            progress({"done": step, "total": total, "rays": int(X.shape[0]),
                      "bytes": int(X.nbytes + Z.nbytes), "elapsed": time.perf_counter() - t0})
    stats["seconds"] = time.perf_counter() - t0
    return DDResult(X=X, zero=bits.unpack(Z), stats=stats)


def _row_order(order: list[int] | str | None, exact: bool, m: int) -> tuple[bool, list[int]]:
    """(whether rows are chosen greedily, the node order) of complementary_rays's `order`."""
    if isinstance(order, str) and order not in ("greedy", "static"):
        raise ValueError(f'order must be a list of nodes, "greedy" or "static", got {order!r}')
    greedy = (order is None and not exact) or (isinstance(order, str) and order == "greedy")
    if greedy and exact:
        raise ValueError('order="greedy" needs float arithmetic')
    return greedy, list(range(m)) if order is None or isinstance(order, str) else [int(i) for i in order]


def _node_finished(i: int, added: set[int]) -> bool:
    """Whether all three rows of node i are in."""
    return {3 * i, 3 * i + 1, 3 * i + 2} <= added


def _start_cone(A, m: int, bits: RowBits, order: list[int], exact: bool, eq: list[int], well_posed: float):
    """The face {a_c x = 0, c in eq} of the simplicial start cone of initial_basis: its rays X,
    their packed zero sets Z, the rows taken in (basis and implied), the packed bits of the
    equality rows (`fixed`), and the number of zeros of a simple ray of the face (`nz1`)."""
    nc, d = A.shape
    basis, implied = initial_basis(A, m, order, exact, eq, well_posed)
    X = _initial_rays(A[basis], exact)
    # the face of the simplicial cone: rays that are tight at every equality row
    on_face = np.array([c not in eq for c in basis], dtype=bool)
    zero = np.zeros((len(basis), nc), dtype=bool)
    for j, c in enumerate(basis):
        zero[:, c] = True
        zero[j, c] = False
    zero[:, implied] = True          # equality rows dependent on the chosen ones
    X, zero = X[on_face], zero[on_face]
    fixed = np.zeros(bits.W, dtype=np.uint64)
    for c in eq + implied:
        w, bit = bits.pos(c)
        fixed[w] |= bit
    # a simple ray of the face has d - 1 zeros plus one per dependent equality row
    return X, bits.pack(zero), set(basis) | set(implied), fixed, d - 1 + len(implied)


def _initial_stats(X: np.ndarray, exact: bool, face: Face | None) -> dict:
    """The counters of a run before its first step."""
    stats = {"initial_rays": int(X.shape[0]), "pairs_tested": 0, "pairs_adjacent": 0,
             "max_rays": int(X.shape[0])}
    if not exact:
        stats.update(close_calls=0, closest=None, cancellation=1.0)
    if face is not None:
        stats["face"] = canonical_face(face)
    return stats


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


def face_rows(face: Face | None, m: int) -> list[int]:
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


def closest_to_tolerance(values) -> float | None:
    """Of "closest" values (stats of float DD runs or steps; None: no close call), the one
    nearest to FLOAT_ZERO_TOL in ratio (None if none)."""
    vals = [v for v in values if v is not None]
    return min(vals, key=lambda v: abs(math.log(v / FLOAT_ZERO_TOL))) if vals else None


def initial_basis(A, m, order, exact, eq=(), well_posed: float = BASIS_WELL_POSED) -> tuple[list[int], list[int]]:
    """d independent rows: equality rows first, then friction rows, then u_n rows,
    nodes in `order`. Returns (basis, implied): implied are the rows outside the basis
    that lie in the span of the chosen equality rows (they vanish on the whole face).
    Float: a row whose distance to the span of those chosen before it is below
    well_posed is passed over at first (a nearly dependent basis row makes the
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
        if distance(c) > well_posed:
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
    pi, qi = adjacent_pairs(P, M, Z, done, fixed, nz1, bits, stats, work)
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
    stats["closest"] = closest_to_tolerance([stats["closest"], v])


def _note_cancellation(nrm: np.ndarray, sp: np.ndarray, sq: np.ndarray, stats: dict) -> None:
    """stats["cancellation"]: the least |o| / (|s_p| + |s_q|) over the new rays
    o = s_p x_q - s_q x_p (unit x, so 1 means no cancellation). A new ray's relative
    rounding error is about eps over this ratio: below CANCELLATION_MIN it reaches the
    zero tolerance."""
    if nrm.size:
        stats["cancellation"] = min(stats["cancellation"], float((nrm / (np.abs(sp) + np.abs(sq))).min()))
