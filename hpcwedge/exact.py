"""Exact rational linear algebra (python-flint) for the verification mode.

Floats enter exactly (every double is a dyadic rational); nothing is rounded.
Matrices are flint.fmpq_mat; helpers convert to and from numpy.
"""
from __future__ import annotations

from fractions import Fraction
from math import gcd, lcm

import flint
import numpy as np


def to_q(A: np.ndarray) -> flint.fmpq_mat:
    """Exact rational copy of a float (or int) 2-D array."""
    A = np.atleast_2d(np.asarray(A))
    rows = []
    for row in A:
        r = []
        for v in row:
            f = Fraction(v) if not isinstance(v, Fraction) else v
            r.append(flint.fmpq(f.numerator, f.denominator))
        rows.append(r)
    return flint.fmpq_mat(A.shape[0], A.shape[1], [x for r in rows for x in r])


def q_scalar(v: float) -> flint.fmpq:
    f = Fraction(v)
    return flint.fmpq(f.numerator, f.denominator)


def to_float(M: flint.fmpq_mat) -> np.ndarray:
    return np.array([[float(Fraction(int(x.p), int(x.q))) for x in row] for row in M.tolist()],
                    dtype=float).reshape(M.nrows(), M.ncols())


def nullspace(M: flint.fmpq_mat) -> flint.fmpq_mat:
    """Basis of {x : M x = 0} as columns (n x (n - rank))."""
    R, rank = M.rref()
    n = M.ncols()
    pivots, row = [], 0
    for j in range(n):
        if row < rank and R[row, j] != 0:
            pivots.append(j)
            row += 1
    free = [j for j in range(n) if j not in pivots]
    Z = flint.fmpq_mat(n, len(free))
    for k, f in enumerate(free):
        Z[f, k] = 1
        for r, p in enumerate(pivots):
            Z[p, k] = -R[r, f]
    return Z


def hstack(*Ms: flint.fmpq_mat) -> flint.fmpq_mat:
    n = Ms[0].nrows()
    cols = sum(M.ncols() for M in Ms)
    out = flint.fmpq_mat(n, cols)
    c0 = 0
    for M in Ms:
        for i in range(n):
            for j in range(M.ncols()):
                out[i, c0 + j] = M[i, j]
        c0 += M.ncols()
    return out


def take_rows(M: flint.fmpq_mat, rows) -> flint.fmpq_mat:
    out = flint.fmpq_mat(len(rows), M.ncols())
    for a, i in enumerate(rows):
        for j in range(M.ncols()):
            out[a, j] = M[i, j]
    return out


def integer_rows(M: flint.fmpq_mat) -> np.ndarray:
    """Each row scaled by a positive rational to coprime integers: object array of int."""
    out = np.empty((M.nrows(), M.ncols()), dtype=object)
    for i, row in enumerate(M.tolist()):
        den = 1
        for x in row:
            den = lcm(den, int(x.q))
        ints = [int(x.p) * (den // int(x.q)) for x in row]
        g = 0
        for v in ints:
            g = gcd(g, v)
        g = g or 1
        out[i] = [v // g for v in ints]
    return out


def primitive(v: np.ndarray) -> np.ndarray:
    """An integer vector (object array) divided by the gcd of its entries."""
    g = 0
    for x in v:
        g = gcd(g, int(x))
        if g == 1:
            return v
    return v // g if g > 1 else v
