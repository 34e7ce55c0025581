"""ContactProblem: the condensed contact stiffness, its rigid modes, and the
one place that states the constraints every engine uses.

Local block ordering (SPEC §1): 2D [n_1..n_m, t_1..t_m], 3D [n.., t1.., t2..].

Rigid modes are handled exactly (SPEC §1): with N the rigid modes, every
solution is u = F r + N alpha, N^T r = 0, F the pseudo-inverse of K on
range(K) = N^perp. We parametrise

    r = B y,  u = F B y + N W beta,   x = (y, beta) in R^d,

with B a basis of N^perp and W a basis of range(N_n^T) (alpha is taken
orthogonal to ker N_n: the rigid slides with u_n = 0 and r = 0 — the
lineality — are factored out). F B comes from the bordered system
[K N; N^T 0][X; L] = [B; 0], which never asks rounding to decide a null space.
For a supported body (k = 0): x = r, u = K^-1 r.
"""
from __future__ import annotations

import math

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
import scipy.linalg as sla

from hpcwedge import exact as xq
from hpcwedge.dense import dense_call, null_space

#: constraint kinds inside a node, in the node-wise constraint numbering 3*i + kind
U_N, F_PLUS, F_MINUS = 0, 1, 2


@dataclass(frozen=True)
class ContactProblem:
    """Condensed, block-ordered local stiffness K (n x n, n = dim*m, symmetric PSD)
    and rigid modes N (n x k, k = 0 for a supported body). eigenvalues: eigvalsh(K)
    when the builder has computed it already (else computed once, on first use)."""

    dim: int
    K: np.ndarray
    N: np.ndarray
    eigenvalues: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def m(self) -> int:
        return self.K.shape[0] // self.dim

    @property
    def n(self) -> int:
        return self.K.shape[0]

    @property
    def free(self) -> bool:
        return self.N.shape[1] > 0

    @cached_property
    def spectrum(self) -> np.ndarray:
        """The eigenvalues of K, ascending (np.linalg.eigvalsh), computed once."""
        return np.linalg.eigvalsh(self.K) if self.eigenvalues is None else self.eigenvalues


def stiffness_range(problem: ContactProblem) -> tuple[float, float]:
    """(smallest, largest) eigenvalue of K on range(K) = N^perp: the k smallest
    eigenvalues (the rigid modes, zero up to rounding) left out."""
    lam = problem.spectrum
    k = problem.N.shape[1]
    return (float(lam[k]), float(lam[-1])) if lam.size > k else (1.0, 1.0)


@dataclass(frozen=True)
class Parametrization:
    """u = U x, r = R x for x in R^d (lineality factored out).

    U, R: float (n x d) arrays; Uq, Rq: exact flint.fmpq_mat copies when exact.
    n_alpha: number of trailing x coordinates that are rigid-mode amplitudes (beta).
    """

    U: np.ndarray
    R: np.ndarray
    n_alpha: int
    Uq: object = None
    Rq: object = None

    @property
    def d(self) -> int:
        return self.U.shape[1]

    @property
    def exact(self) -> bool:
        return self.Uq is not None

    @cached_property
    def reactions(self) -> "ReactionCoordinates":
        """The same states in the coordinates x' = (r, beta) (ReactionCoordinates), computed
        once (`parametrize` sets them for a free body from its own factorisation)."""
        return reaction_coordinates(self.U, self.R, self.n_alpha)


def reaction_coordinates(U: np.ndarray, R: np.ndarray, n_alpha: int,
                         E: np.ndarray | None = None) -> "ReactionCoordinates":
    """A parametrisation's (U, R, n_alpha) in x' = (r, beta). E: orthonormal rows spanning
    the complement of range(B), B = R's first d - n_alpha columns, when the caller has them
    (None: from an SVD of B^T, O(n^3): 10 s at n = 2,560)."""
    ny = U.shape[1] - n_alpha
    B = R[:, :ny]
    if E is None:
        E = null_space(B.T).T if ny < B.shape[0] else np.zeros((0, B.shape[0]))
    return ReactionCoordinates(U=np.hstack([U[:, :ny] @ B.T, U[:, ny:]]), E=E, B=B)


@dataclass(frozen=True)
class ReactionCoordinates:
    """A parametrisation in x' = (r, beta) (r the n reactions, beta the rigid amplitudes):
    u = U x', with E r = 0 (E (n - rank B, n), orthonormal rows: equilibrium N^T r = 0),
    and x = (B^T r, beta). A friction cone in x' is a coordinate cone (mu r_n, r_t1, r_t2),
    which keeps the 3D pattern SOCP sparse (socp.reaction_socp). T: the parametrisation's x is
    T (B^T r, beta) (problem.balanced; None: the identity)."""

    U: np.ndarray
    E: np.ndarray
    B: np.ndarray
    T: np.ndarray | None = None

    def to_x(self, r: np.ndarray, beta: np.ndarray) -> np.ndarray:
        """x = (B^T r, beta) for r (n,) on range(B), times T when given."""
        x = np.concatenate([self.B.T @ r, beta])
        return x if self.T is None else self.T @ x

    def pullback(self, c: np.ndarray) -> np.ndarray:
        """Weights c on x as weights on (B^T r, beta): c . x = pullback(c) . (B^T r, beta)."""
        return c if self.T is None else self.T.T @ c


def kept_on(obj, key: str, build):
    """build(), computed once per `obj` and kept in its __dict__ under `key` (derived data
    of a frozen Parametrization / ReactionCoordinates that depends on an argument, e.g. m)."""
    value = obj.__dict__.get(key)
    if value is None:
        value = obj.__dict__[key] = build()
    return value


def blocks(M: np.ndarray, m: int, dim: int) -> tuple[np.ndarray, ...]:
    """The dim row blocks of M (dim*m rows in the block order of SPEC §1): (normal,
    tangent) in 2D, (normal, tangent 1, tangent 2) in 3D, m rows each; views of M."""
    return tuple(M[k * m:(k + 1) * m] for k in range(dim))


def lineality_rows(N: np.ndarray, m: int, rtol: float = 1e-9) -> list[int]:
    """Rows of N_n = N[:m] forming a basis of its row space (pivoted QR).

    The same choice serves the float and the exact route, so both factor out
    the same lineality. rtol is relative to the largest |R_jj| (geometry O(1)).
    """
    Nn = N[:m]
    if Nn.size == 0:
        return []
    _, Rr, piv = sla.qr(Nn.T, pivoting=True, mode="economic")
    diag = np.abs(np.diag(Rr))
    if diag.size == 0 or diag[0] == 0:
        return []
    rank = int(np.sum(diag > rtol * diag[0]))
    return sorted(piv[:rank].tolist())


def parametrize(problem: ContactProblem, exact: bool = False) -> Parametrization:
    """The (y, beta) parametrisation of SPEC §1 (see module docstring)."""
    K, N, m = problem.K, problem.N, problem.m
    n, k = K.shape[0], N.shape[1]
    rows = lineality_rows(N, m) if k else []
    if not exact:
        if k == 0:
            return Parametrization(U=np.linalg.inv(K), R=np.eye(n), n_alpha=0)
        Qn, _ = np.linalg.qr(N)
        B = null_space(Qn.T)                          # orthonormal basis of N^perp
        FB = np.linalg.solve(_bordered(K, Qn), np.vstack([B, np.zeros((k, B.shape[1]))]))[:n]
        W = N[rows].T
        U = np.hstack([FB, N @ W])
        R = np.hstack([B, np.zeros((n, len(rows)))])
        out = Parametrization(U=U, R=R, n_alpha=len(rows))
        if B.shape[1] == n - k:
            # the complement of range(B) = N^perp is range(N): Qn's columns, no SVD of B^T
            out.__dict__["reactions"] = reaction_coordinates(U, R, len(rows), E=np.ascontiguousarray(Qn.T))
        return out
    Kq = xq.to_q(K)
    if k == 0:
        Uq = Kq.inv()
        Rq = xq.to_q(np.eye(n))
        return Parametrization(U=xq.to_float(Uq), R=np.eye(n), n_alpha=0, Uq=Uq, Rq=Rq)
    Nq = _snap_dependent_rows(N, m, rows)
    B = xq.nullspace(Nq.transpose())
    rhs = xq.to_q(np.zeros((n + k, B.ncols())))
    for i in range(n):
        for j in range(B.ncols()):
            rhs[i, j] = B[i, j]
    Bord = xq.to_q(np.zeros((n + k, n + k)))
    for i in range(n + k):
        for j in range(n + k):
            Bord[i, j] = Kq[i, j] if i < n and j < n else (
                Nq[i, j - n] if i < n and j >= n else (Nq[j, i - n] if j < n else 0))
    FB = xq.take_rows(Bord.solve(rhs), range(n))
    W = xq.take_rows(Nq, rows).transpose()
    Uq = xq.hstack(FB, Nq * W)
    Rq = xq.hstack(B, xq.to_q(np.zeros((n, len(rows)))))
    return Parametrization(U=xq.to_float(Uq), R=xq.to_float(Rq), n_alpha=len(rows), Uq=Uq, Rq=Rq)


def _snap_dependent_rows(N: np.ndarray, m: int, rows: list[int]):
    """Exact copy of N in which each normal row outside `rows` is an exact rational
    combination of the basis rows (coefficients snapped to small denominators when
    that moves them by < 1e-13). Geometry known to float precision keeps its
    dependencies (collinear nodes on one wall stay collinear) instead of rounding
    creating tiny extra facets of the lift-off cone in exact arithmetic."""
    from fractions import Fraction
    Nq = xq.to_q(N)
    if not rows:
        return Nq
    base = N[rows]
    for j in range(m):
        if j in rows:
            continue
        c, *_ = np.linalg.lstsq(base.T, N[j], rcond=None)
        coef = []
        for v in c:
            f = Fraction(v).limit_denominator(10**6)
            coef.append(f if abs(float(f) - v) < 1e-13 else Fraction(v))
        for col in range(N.shape[1]):
            acc = xq.q_scalar(0.0)
            for f, r in zip(coef, rows):
                acc += xq.flint.fmpq(f.numerator, f.denominator) * Nq[r, col]
            Nq[j, col] = acc
    return Nq


def _bordered(K: np.ndarray, N: np.ndarray) -> np.ndarray:
    k = N.shape[1]
    return np.block([[K, N], [N.T, np.zeros((k, k))]])


def balanced(param: Parametrization, mu: float, m: int, s: float,
             cond: bool = True) -> tuple[Parametrization, float, np.ndarray]:
    """The same cone P(mu) in coordinates x' = T x balanced at mu (2D and 3D; the dimension
    from R's rows).

    With M = [s U_n; R_n; R_t / mu] (2D: 3m x d; 3D, both tangents: 4m x d) and M = Q T its QR
    factorisation, x' = T x makes x' -> (s u_n, r_n, r_t / mu) an isometry: a unit ray is a
    unit state and the constraint rows are rows of Q. s > 0 is a stiffness that weighs u_n
    against r (pipeline: sqrt(lambda_min lambda_max) of K on range(K), so that the coordinates
    do not depend on the units of K). Without it the 2D DD's zero tests see the friction slack
    mu r_n - r_t relative to |r_t| + |r_n|, which near mu^c on a small taper is ~ delta
    tan(taper) (2e-12 at 0.1 deg and mu = mu^c (1 + 1e-9)); scaling r_t by 1/mu makes it
    ~ delta (scripts/stress.py, family near_mu_c). 3D: the SOCPs of a small mu^c (plug3d 2 x 4
    at a 0.1 deg taper: the all-contact pattern's mu^c in 4 SOCPs, polished to 8e-14, against
    136 SOCPs, 24 undecided and an unpolished 5e-10 in the plain coordinates).
    Returns (float Parametrization with U' = U T^-1, R' = R T^-1 — the rows taken from Q
    itself, not from a solve with T — and n_alpha = 0 since the rigid amplitudes are mixed
    in; cond(T) (NaN with cond=False: an SVD of T, 2.5 s at d = 2,563, that the mu^c
    computations do not read); T, to map a point back: x = T^-1 x').
    """
    U, R = param.U, param.R
    dim = R.shape[0] // m
    Un, Rb = blocks(U, m, dim)[0], blocks(R, m, dim)
    Q, T = dense_call(np.linalg.qr, np.vstack([s * Un, Rb[0], *(Rt / mu for Rt in Rb[1:])]))
    Up = sla.solve_triangular(T, U.T, trans="T").T
    Rp = sla.solve_triangular(T, R.T, trans="T").T
    Qb = blocks(Q, m, dim + 1)
    Upn, Rpb = blocks(Up, m, dim)[0], blocks(Rp, m, dim)
    Upn[...], Rpb[0][...] = Qb[0] / s, Qb[1]
    for Rpt, Qt in zip(Rpb[1:], Qb[2:]):
        Rpt[...] = mu * Qt
    out = Parametrization(U=Up, R=Rp, n_alpha=0)
    # the reaction form (r, beta) is the same states', reached through T: param's, composed
    rc = param.reactions
    out.__dict__["reactions"] = ReactionCoordinates(rc.U, rc.E, rc.B, T if rc.T is None else T @ rc.T)
    return out, float(dense_call(np.linalg.cond, T)) if cond else math.nan, T


def friction_rows_2d(param: Parametrization, mu: float, m: int, exact: bool = False):
    """Node-wise constraint rows of the 2D cone P(mu) = {x : A x >= 0}.

    Row 3*i + U_N: u_n,i;  3*i + F_PLUS: mu r_n,i + r_t,i;  3*i + F_MINUS: mu r_n,i - r_t,i.
    (r_n >= 0 follows from the two friction rows.) Float rows are scaled to unit
    norm; exact rows are primitive integer vectors (object array), same directions.
    """
    if not exact:
        (Un, _), (Rn, Rt) = blocks(param.U, m, 2), blocks(param.R, m, 2)
        A = np.empty((3 * m, param.d))
        A[U_N::3] = Un
        A[F_PLUS::3] = mu * Rn + Rt
        A[F_MINUS::3] = mu * Rn - Rt
        return A / np.linalg.norm(A, axis=1, keepdims=True)
    U, R, muq = param.Uq, param.Rq, xq.q_scalar(mu)
    A = xq.to_q(np.zeros((3 * m, param.d)))
    for i in range(m):
        for j in range(param.d):
            A[3 * i + U_N, j] = U[i, j]
            A[3 * i + F_PLUS, j] = muq * R[i, j] + R[m + i, j]
            A[3 * i + F_MINUS, j] = muq * R[i, j] - R[m + i, j]
    return xq.integer_rows(A)


def ray_vectors(param: Parametrization, X: np.ndarray, m: int,
                wedged: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Map rays x (rows of X, float or exact ints) to full local (u, r) vectors.

    wedged: (R,) bool, r != 0 (decided combinatorially by the zero sets).
    Returns (wedged, V (R, 2n)) with V rows [u..., r...] normalised to sum(r_n) = 1
    for wedged rays and to sum(u_n) = 1 for trivial ones (r set to exact zero).
    Exact rays are mapped and normalised in rational arithmetic, rounded once.
    Float rays: a BLAS product, whose rounding depends on the BLAS thread count
    (OpenBLAS); the thread policy (environment.py) keeps that at one thread, so the
    bits are the same serially and on any rank count.
    """
    n = param.U.shape[0]
    if X.dtype == object:
        out = np.zeros((len(X), 2 * n))
        if len(X) == 0:
            return wedged, out
        Xq = xq.to_q(np.array([[int(v) for v in row] for row in X], dtype=object).T)
        Uq, Rq = param.Uq * Xq, param.Rq * Xq
        for c in range(len(X)):
            src = Rq if wedged[c] else Uq
            s = src[0, c]
            for i in range(1, m):
                s += src[i, c]
            col = [Uq[i, c] / s for i in range(n)] + [Rq[i, c] / s for i in range(n)]
            out[c] = [int(v.p) / int(v.q) for v in col]
        return wedged, out
    V = np.empty((len(X), 2 * n))
    np.matmul(X, param.U.T, out=V[:, :n])
    np.matmul(X, param.R.T, out=V[:, n:])
    V[~wedged, n:] = 0.0
    V /= np.where(wedged, V[:, n:n + m].sum(1), V[:, :m].sum(1))[:, None]
    return wedged, V


def strip_exact(param):
    """A parametrisation without its exact (flint) copies: the float engines'
    context, cheap to pickle."""
    if getattr(param, "Uq", None) is None and getattr(param, "Rq", None) is None:
        return param
    return replace(param, Uq=None, Rq=None)
