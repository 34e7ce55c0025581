"""Complementarity-pruned DD against exact arithmetic, an unpruned brute force, and
an LP per sign pattern, on random supported and free bodies."""
import itertools

import numpy as np
import pytest

from hpcwedge.lp import lp_feasible
from hpcwedge.dd import canonical_order, complementary_rays, merge_results, split_faces
from hpcwedge.problem import friction_rows_2d, parametrize
from hpcwedge.rows import Status, pattern_rows
from instances import random_problem


def brute_force_rays(A: np.ndarray) -> set:
    """Zero sets of all extreme rays of {A x >= 0}: every d-1 row subset of rank
    d-1, its null vector (either sign) if feasible; then the complementarity filter."""
    nc, d = A.shape
    found = set()
    for S in itertools.combinations(range(nc), d - 1):
        _, s, vt = np.linalg.svd(A[list(S)])
        if s[-1] < 1e-9 * s[0]:
            continue
        for y in (vt[-1], -vt[-1]):
            v = A @ y
            if np.all(v >= -1e-9):
                found.add(tuple(np.abs(v) <= 1e-9))
    return {z for z in found
            if all(z[3 * i] or (z[3 * i + 1] and z[3 * i + 2]) for i in range(nc // 3))}


def patterns_from_rays(zero: np.ndarray, m: int) -> set:
    """(C, G) is feasible iff a wedged ray has supp(r_n) in C and supp(u_n) in G."""
    out = set()
    for z in zero:
        zu, zr = z[0::3], z[1::3] & z[2::3]
        if zr.all():
            continue
        free = [i for i in range(m) if zu[i] and zr[i]]
        for bits in itertools.product((0, 1), repeat=len(free)):
            contact = set(np.flatnonzero(~zr)) | {i for i, b in zip(free, bits) if b}
            out.add(tuple(sorted(contact)))
    return out


CASES = [(seed, m, free) for seed in range(40) for m, free in
         [(1, False), (2, False), (2, True), (3, False), (3, True)]]


@pytest.mark.parametrize("seed,m,free", CASES)
def test_float_exact_bruteforce_agree(seed, m, free):
    rng = np.random.default_rng(1000 * seed + 10 * m + free)
    prob = random_problem(rng, m, free)
    mu = float(rng.uniform(0.2, 1.5))
    pf, pe = parametrize(prob), parametrize(prob, exact=True)
    rf = complementary_rays(friction_rows_2d(pf, mu, m), m)
    re = complementary_rays(friction_rows_2d(pe, mu, m, exact=True), m, exact=True)
    zf, ze = set(map(tuple, rf.zero)), set(map(tuple, re.zero))
    assert len(zf) == len(rf.zero) and len(ze) == len(re.zero)      # no duplicates
    assert zf == ze
    assert zf == brute_force_rays(friction_rows_2d(pf, mu, m))
    # the float rays really are rays of the cone with those zero sets
    A = friction_rows_2d(pf, mu, m)
    V = rf.X @ A.T
    assert np.all(V >= -1e-9)
    assert np.array_equal(np.abs(V) <= 1e-9, rf.zero)


@pytest.mark.parametrize("seed", range(20))
@pytest.mark.parametrize("m,free", [(4, False), (4, True), (5, True)])
def test_patterns_lp_per_pattern(seed, m, free):
    """Patterns implied by the rays = patterns with a feasible LP (one per partition)."""
    rng = np.random.default_rng(77 + 1000 * seed + 10 * m + free)
    prob = random_problem(rng, m, free)
    mu = float(rng.uniform(0.3, 1.5))
    p = parametrize(prob)
    dd = complementary_rays(friction_rows_2d(p, mu, m), m)
    lp = set()
    for bits in itertools.product((False, True), repeat=m):
        zu = np.array(bits)
        status, _ = lp_feasible(pattern_rows(p, m, zu, ~zu), mu)
        assert status in (Status.FEASIBLE, Status.INFEASIBLE)
        if status == Status.FEASIBLE:
            lp.add(tuple(np.flatnonzero(zu)))
    assert patterns_from_rays(dd.zero, m) == lp


@pytest.mark.parametrize("seed", range(6))
def test_exact_m6(seed):
    rng = np.random.default_rng(5 + seed)
    prob = random_problem(rng, 6, free=bool(seed % 2))
    pf, pe = parametrize(prob), parametrize(prob, exact=True)
    rf = complementary_rays(friction_rows_2d(pf, 0.8, 6), 6)
    re = complementary_rays(friction_rows_2d(pe, 0.8, 6, exact=True), 6, exact=True)
    assert set(map(tuple, rf.zero)) == set(map(tuple, re.zero))


def test_pruned_equals_unpruned_filtered():
    """Pruning loses nothing: compare with the full DD of all extreme rays
    (brute force) filtered for complementarity on a free m = 4 body."""
    rng = np.random.default_rng(3)
    prob = random_problem(rng, 4, free=True)
    p = parametrize(prob)
    A = friction_rows_2d(p, 0.9, 4)
    assert set(map(tuple, complementary_rays(A, 4).zero)) == brute_force_rays(A)


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("m,free", [(4, False), (5, True), (6, True)])
def test_row_orders_agree(seed, m, free):
    """The row order changes the work, never the result: greedy (the float default),
    static, and a random node order give the same rays."""
    rng = np.random.default_rng(300 + 1000 * seed + 10 * m + free)
    prob = random_problem(rng, m, free)
    A = friction_rows_2d(parametrize(prob), float(rng.uniform(0.3, 1.5)), m)
    ref = complementary_rays(A, m)
    assert len(ref.X) == len(set(map(tuple, ref.zero)))
    for order in ("static", "greedy", list(rng.permutation(m))):
        r = complementary_rays(A, m, order=order)
        assert set(map(tuple, r.zero)) == set(map(tuple, ref.zero))
        assert len(r.X) == len(ref.X)


def test_greedy_order_is_float_only():
    rng = np.random.default_rng(1)
    p = parametrize(random_problem(rng, 3, False), exact=True)
    A = friction_rows_2d(p, 0.8, 3, exact=True)
    with pytest.raises(ValueError):
        complementary_rays(A, 3, exact=True, order="greedy")
    with pytest.raises(ValueError):
        complementary_rays(A, 3, exact=True, order="fastest")


# --------------------------------------------------------------------- face splitting

def _on_face(zero: np.ndarray, face) -> np.ndarray:
    contact, gap = face
    ok = np.ones(len(zero), dtype=bool)
    for i in contact:
        ok &= zero[:, 3 * i]
    for i in gap:
        ok &= zero[:, 3 * i + 1] & zero[:, 3 * i + 2]
    return ok


FACE_CASES = [(seed, m, free, nodes) for seed in range(12) for m, free, nodes in
              [(2, False, (1,)), (2, True, (0, 1)), (3, True, (2,)), (3, False, (0, 2)),
               (4, True, (3, 1)), (4, False, (0, 1, 2)), (5, True, (4, 2))]]


@pytest.mark.parametrize("seed,m,free,nodes,exact",
                         [c + (ex,) for c in FACE_CASES for ex in (False, True) if c[1] <= 4 or not ex])
def test_faces_union_is_full(seed, m, free, nodes, exact):
    """Every face run gives exactly the full run's rays on that face; the merged
    union of the 2^k faces is the full ray set, without duplicates."""
    rng = np.random.default_rng(500 + 1000 * seed + 10 * m + free)
    prob = random_problem(rng, m, free)
    mu = float(rng.uniform(0.2, 1.5))
    p = parametrize(prob, exact=exact)
    A = friction_rows_2d(p, mu, m, exact=exact)
    full = complementary_rays(A, m, exact=exact)
    ref = set(map(tuple, full.zero))
    faces = split_faces(m, nodes)
    assert len(faces) == 2 ** len(nodes)
    results = [complementary_rays(A, m, exact=exact, face=f) for f in faces]
    for f, r in zip(faces, results):
        assert set(map(tuple, r.zero)) == set(map(tuple, full.zero[_on_face(full.zero, f)]))
        assert _on_face(r.zero, f).all()
    merged = merge_results(results)
    assert len(merged.zero) == len(ref) and set(map(tuple, merged.zero)) == ref
    # canonical order, independent of the order in which the face results arrive
    assert np.array_equal(np.lexsort(merged.zero.T[::-1]), np.arange(len(merged.zero)))
    again = merge_results(results[::-1])
    assert np.array_equal(again.zero, merged.zero)
    assert np.array_equal(again.X, merged.X)
    if not exact:
        V = merged.X @ A.T
        assert np.all(V >= -1e-9)
        assert np.array_equal(np.abs(V) <= 1e-9, merged.zero)


@pytest.mark.parametrize("seed", range(6))
def test_face_with_node_in_contact_and_gap(seed):
    """A face may fix u_n = 0 and r = 0 at the same node."""
    rng = np.random.default_rng(900 + seed)
    m = 4
    prob = random_problem(rng, m, free=bool(seed % 2))
    p = parametrize(prob)
    A = friction_rows_2d(p, 0.9, m)
    full = complementary_rays(A, m)
    for face in [((1,), (1,)), ((0, 2), (2, 3)), ((), ())]:
        r = complementary_rays(A, m, face=face)
        assert set(map(tuple, r.zero)) == set(map(tuple, full.zero[_on_face(full.zero, face)]))


def test_split_faces():
    assert split_faces(4, [2]) == [((2,), ()), ((), (2,))]
    assert split_faces(4, [3, 1]) == [((1, 3), ()), ((3,), (1,)), ((1,), (3,)), ((), (1, 3))]
    assert split_faces(4, []) == [((), ())]
    with pytest.raises(ValueError):
        split_faces(4, [4])
    with pytest.raises(ValueError):
        split_faces(4, [1, 1])


@pytest.fixture(scope="module")
def plug2d_rows():
    from hpcwedge.condense import condense
    from hpcwedge.models.library import plug2d
    from hpcwedge.problem import ContactProblem

    def rows(n, exact=False):
        K, N = condense(plug2d(n, 3, 10.0))
        p = parametrize(ContactProblem(2, K, N), exact=exact)
        return friction_rows_2d(p, 0.65, 2 * n, exact=exact)
    return rows


@pytest.mark.parametrize("rows,nodes,wedged", [(4, (7,), 244), (4, (3, 7), 244), (5, (9,), 1148),
                                               (5, (8, 9), 1148), (5, (4, 8, 9), 1148)])
def test_faces_plug2d_counts(plug2d_rows, rows, nodes, wedged):
    m = 2 * rows
    A = plug2d_rows(rows)
    full = complementary_rays(A, m)
    merged = merge_results([complementary_rays(A, m, face=f) for f in split_faces(m, nodes)])
    assert int(merged.wedged().sum()) == int(full.wedged().sum()) == wedged
    assert set(map(tuple, merged.zero)) == set(map(tuple, full.zero))
    assert len(merged.zero) == len(full.zero)


def test_faces_plug2d_exact(plug2d_rows):
    A = plug2d_rows(3, exact=True)
    full = complementary_rays(A, 6, exact=True)
    merged = merge_results([complementary_rays(A, 6, exact=True, face=f) for f in split_faces(6, (5, 2))])
    assert int(merged.wedged().sum()) == 44
    assert set(map(tuple, merged.zero)) == set(map(tuple, full.zero))


@pytest.mark.parametrize("R,k", [(0, 6), (7, 0), (200, 3), (500, 60), (500, 64), (500, 65), (300, 130)])
def test_canonical_order_is_lexsort(R, k):
    rng = np.random.default_rng(R + k)
    z = rng.random((R, k)) < 0.3
    z[R // 2:] = z[:R - R // 2]                       # duplicates: the order must be stable
    ref = np.lexsort(z.T[::-1]) if k else np.arange(R)
    assert np.array_equal(canonical_order(z), ref)
