"""adjacency.py: adjacent_pairs against the definition, on the extreme rays of small
random cones (with degenerate rays) found by brute force: (p, q) on the two sides of a
new row are adjacent iff no third extreme ray's zero set contains Z(p) & Z(q)."""
import itertools

import numpy as np
import pytest

from hpcwedge.nodesets import RowBits
from hpcwedge.rays.adjacency import adjacent_pairs

TOL = 1e-9


def extreme_rays(A: np.ndarray, rows: list[int]) -> np.ndarray:
    """Zero flags (R, len(A)) over every row of A of the extreme rays of {x : A[rows] x >= 0}
    (pointed), each once."""
    d = A.shape[1]
    found = {}
    for S in itertools.combinations(rows, d - 1):
        _, s, vt = np.linalg.svd(A[list(S)])
        if s[-1] < 1e-9 * s[0]:
            continue
        for y in (vt[-1], -vt[-1]):
            v = A @ y
            if np.all(v[rows] >= -TOL):
                z = np.abs(v) <= TOL
                found[tuple(z)] = (z, v)
    return found


def cone(seed: int, degenerate: bool):
    """m = 4 nodes, d = 4: rows u_n and F_PLUS of every node are in (no node finished),
    row 2 (node 0's F_MINUS) is the new one. Degenerate: rows 0, 1, 3, 4 vanish on y0 and
    rows 0, 1, 6, 7 on y1: two extreme rays with 4 zeros each, on either side of row 2,
    adjacent (the face of rows 0, 1 is 2-dimensional)."""
    rng = np.random.default_rng(seed)
    m, d = 4, 4
    rows = [0, 1, 3, 4, 6, 7, 9, 10]
    while True:
        A = rng.normal(size=(3 * m, d))
        if degenerate:
            y0, y1 = rng.normal(size=d), rng.normal(size=d)
            Y = np.linalg.qr(np.stack([y0, y1], axis=1))[0]
            A[[0, 1]] -= A[[0, 1]] @ Y @ Y.T              # on both: they share 2 = d - 2 zeros
            for group, y, other in (([3, 4], y0, y1), ([6, 7], y1, y0)):
                for r in group:
                    A[r] -= (A[r] @ y) / (y @ y) * y
                    A[r] *= np.sign(A[r] @ other)
            for r in (9, 10):
                if not (A[r] @ y0 > 0 and A[r] @ y1 > 0):
                    A[r] = A[r] - A[r] @ Y @ Y.T + Y @ (np.linalg.lstsq(np.stack([y0, y1]) @ Y, np.ones(2),
                                                                         rcond=None)[0])
            if not (A[2] @ y0 > 0 > A[2] @ y1):
                continue
        A /= np.linalg.norm(A, axis=1, keepdims=True)
        if np.linalg.matrix_rank(A[rows]) == d and len(extreme_rays(A, rows)) > 2:
            return A, m, d, rows


@pytest.mark.parametrize("degenerate", [False, True])
@pytest.mark.parametrize("seed", range(15))
def test_adjacent_pairs_is_the_combinatorial_test(seed, degenerate):
    A, m, d, rows = cone(seed, degenerate)
    rays = extreme_rays(A, rows)
    zero = np.array([z for z, _ in rays.values()])
    vals = np.array([v for _, v in rays.values()])
    inside = np.zeros(3 * m, dtype=bool)
    inside[rows] = True
    bits = RowBits(m)
    Z = bits.pack(zero & inside)                     # zero sets over the rows taken so far
    h = 2                                            # the new row (node 0's F_MINUS)
    P, M = np.flatnonzero(vals[:, h] > TOL), np.flatnonzero(vals[:, h] < -TOL)
    stats = {"pairs_tested": 0, "pairs_adjacent": 0}
    none = np.zeros(bits.W, dtype=np.uint64)
    pi, qi = adjacent_pairs(P, M, Z, none, none, d - 1, bits, stats, {})
    got = set(zip(pi.tolist(), qi.tolist()))
    want = set()
    for p, q in itertools.product(P, M):
        C = Z[p] & Z[q]
        if int(np.bitwise_count(C).sum()) < d - 2:
            continue
        holders = np.all((Z & C) == C, axis=1)
        if holders.sum() == 2:
            want.add((int(p), int(q)))
    assert got == want and len(got) == stats["pairs_adjacent"]
    if degenerate:                                   # the degenerate paths ran
        deg = np.bitwise_count(Z).sum(axis=1) > d - 1
        assert deg[P].any() and deg[M].any()
        assert any(deg[p] and deg[q] for p, q in got)
