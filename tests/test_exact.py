"""Exact rational arithmetic (exact.py) against fractions.Fraction: conversions without
rounding, a null space checked by exact products and a Fraction Gaussian elimination,
integer rows and primitive vectors checked by gcds and exact ratios."""
from fractions import Fraction
from math import gcd

import flint
import numpy as np
import pytest

from hpcwedge import exact as xq


def frac(x) -> Fraction:
    return Fraction(int(x.p), int(x.q))


def as_fractions(M) -> list[list[Fraction]]:
    return [[frac(x) for x in row] for row in M.tolist()]


def rank(rows: list[list[Fraction]]) -> int:
    """Rank by Gaussian elimination in Fractions."""
    A = [r[:] for r in rows]
    r = 0
    for j in range(len(A[0]) if A else 0):
        p = next((i for i in range(r, len(A)) if A[i][j] != 0), None)
        if p is None:
            continue
        A[r], A[p] = A[p], A[r]
        for i in range(len(A)):
            if i != r and A[i][j] != 0:
                f = A[i][j] / A[r][j]
                A[i] = [a - f * b for a, b in zip(A[i], A[r])]
        r += 1
    return r


def awkward_floats(rng, shape) -> np.ndarray:
    """Floats over many binades, signs, exact zeros and integers."""
    A = rng.standard_normal(shape) * 10.0 ** rng.integers(-300, 300, size=shape)
    A[rng.random(shape) < 0.2] = 0.0
    ints = rng.random(shape) < 0.2
    A[ints] = rng.integers(-9, 10, size=int(ints.sum()))
    return A


@pytest.mark.parametrize("seed", range(10))
def test_to_q_and_back_is_exact(seed):
    rng = np.random.default_rng(seed)
    A = awkward_floats(rng, (4, 5))
    Q = xq.to_q(A)
    assert (Q.nrows(), Q.ncols()) == A.shape
    assert as_fractions(Q) == [[Fraction(v) for v in row] for row in A]     # no rounding
    assert np.array_equal(xq.to_float(Q), A)
    v = float(A[1, 2])
    assert frac(xq.q_scalar(v)) == Fraction(v)
    assert as_fractions(xq.to_q(np.array([1.5, -0.25]))) == [[Fraction(3, 2), Fraction(-1, 4)]]


def test_to_q_takes_fractions_as_they_are():
    A = np.array([[Fraction(1, 3), Fraction(-2, 7)]], dtype=object)
    assert as_fractions(xq.to_q(A)) == [[Fraction(1, 3), Fraction(-2, 7)]]


@pytest.mark.parametrize("seed", range(20))
def test_nullspace_is_a_basis_of_the_kernel(seed):
    rng = np.random.default_rng(100 + seed)
    n, k = int(rng.integers(2, 7)), int(rng.integers(1, 5))
    B = rng.integers(-3, 4, size=(k, n)).astype(float)
    A = rng.integers(-2, 3, size=(int(rng.integers(1, 5)), k)).astype(float) @ B     # rank <= k
    if rng.random() < 0.5:
        A = A / 3.0 + 0.0                       # rationals with denominators, exactly as floats
    M = xq.to_q(A)
    Z = xq.nullspace(M)
    rows = as_fractions(M)
    cols = list(zip(*as_fractions(Z))) if Z.ncols() else []
    assert Z.nrows() == n and Z.ncols() == n - rank(rows)
    for z in cols:                              # M z = 0, exactly
        assert all(sum(a * b for a, b in zip(r, z)) == 0 for r in rows)
    if cols:                                    # independent columns
        assert rank([list(z) for z in cols]) == len(cols)


def test_nullspace_of_a_full_rank_matrix_is_empty():
    Z = xq.nullspace(xq.to_q(np.eye(3)))
    assert (Z.nrows(), Z.ncols()) == (3, 0)


def test_hstack_and_take_rows():
    a, b = xq.to_q(np.array([[1.0, 2.0], [3.0, 4.0]])), xq.to_q(np.array([[0.5], [-1.0]]))
    assert as_fractions(xq.hstack(a, b)) == [[1, 2, Fraction(1, 2)], [3, 4, -1]]
    assert as_fractions(xq.take_rows(xq.hstack(a, b), [1, 1, 0])) == [[3, 4, -1], [3, 4, -1],
                                                                      [1, 2, Fraction(1, 2)]]


@pytest.mark.parametrize("seed", range(10))
def test_integer_rows_are_coprime_positive_multiples(seed):
    rng = np.random.default_rng(200 + seed)
    A = rng.integers(-50, 51, size=(5, 4)) / rng.integers(1, 12, size=(5, 4)).astype(float)
    A[0] = 0.0
    A[1, :2] = 0.0
    Q = xq.to_q(A)
    out = xq.integer_rows(Q)
    assert out.shape == A.shape and out.dtype == object
    for row_q, row_i in zip(as_fractions(Q), out):
        ints = [int(v) for v in row_i]
        if not any(ints):
            assert not any(row_q)
            continue
        g = 0
        for v in ints:
            g = gcd(g, v)
        assert g == 1
        j = next(j for j, v in enumerate(ints) if v)
        c = Fraction(ints[j]) / row_q[j]
        assert c > 0 and all(Fraction(v) == c * q for v, q in zip(ints, row_q))


def test_primitive():
    v = np.array([6, -9, 0, 12], dtype=object)
    assert xq.primitive(v).tolist() == [2, -3, 0, 4]
    w = np.array([3, 5], dtype=object)
    assert xq.primitive(w) is w
    assert xq.primitive(np.array([0, 0], dtype=object)).tolist() == [0, 0]
    assert xq.primitive(np.array([flint.fmpz(4), flint.fmpz(-8)], dtype=object)).tolist() == [1, -2]
