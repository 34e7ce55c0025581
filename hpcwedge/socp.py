"""The Clarabel adapter: the one builder of conic problems, the solver settings (values,
no module state), the retry ladder of attempts, and the checks of what Clarabel returns
(a point's violation, a Farkas certificate).

Every conic problem here has the form  min 1/2 w'Pw + q.w  s.t.  A w + s = b,  s in K,
with K = [zero cone (n_zero) | nonnegative (n_lin) | second-order cones of size 3 (n_soc)]
(`ConicProblem`). The pattern SOCP (`pattern_socp`, rows.ConeRows) is one; Dinkelbach's
steps (dinkelbach.py) and the signed KKT multipliers (kkt.py) are others.

The ladder (`attempts`): attempt k uses `settings(k, tight)`. 0: plain; 1: the least-norm
feasible point (P = I; when the plain solve returned a point that does not verify: the
iterates can run off along rigid lift-offs, measured up to ||x|| ~ 1e17; P = I is not the
default because it weakens the infeasibility certificates: 732 of 2,126 failed the Farkas
check on plug3d + 30 random free bodies, none with P = 0); 2: static regularisation 1e-7;
3: Clarabel's defaults (equilibration on). The caller stops it when satisfied.

A feasibility problem (no objective) starts with static regularisation 1e-7 and no iterative
refinement: with Clarabel's 1e-8 the first attempt stopped at NumericalError after one
zero-length step on 37 % of plug3d 3 x 6's SOCPs (62 % at 4 x 6), every one of which 1e-7
decides; refinement adds nothing to a problem without an objective and cost a third of the
solve time (scripts/bench_socp_count.py; issue 13's measurements in docs/benchmarks.md). Its
tolerances are 1e-10: a point Clarabel calls solved must pass VERIFY_TOL, which at the
default 1e-8 the points of problems within ~1e-7 of their mu^c did not (the 3D global mu^c
on plug3d 3 x 6 without symmetry: 161 of 738 tree SOCPs, each retried down the ladder; none
at 1e-10, and the enumeration's 6,791 SOCPs cost the same).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from typing import Iterator

import numpy as np
import scipy.sparse as sp

from .rows import ConeRows

#: a returned x is feasible when every row holds to VERIFY_TOL * ||x|| (the order of
#: Clarabel's own feasibility tolerance: an optimum on the boundary misses by 1e-9..3e-9;
#: 2D: HiGHS's primal feasibility tolerance is 1e-7)
VERIFY_TOL = 1e-8
#: an infeasibility certificate z holds when ||A^T z|| and the dual-cone violation are
#: <= CERT_TOL * |b^T z| (b^T z < 0 strictly)
CERT_TOL = 1e-7
#: the attempts of the ladder (module doc), and the one that seeks the least-norm point
ATTEMPTS = 4
LEAST_NORM_ATTEMPT = 1


def violation(rows: ConeRows, mu: float, x: np.ndarray) -> float:
    """Largest violation of the pattern problem at x (unit rows; each cone's rows
    scaled together), x first scaled to sum r_n = 1 (sum r_n <= 0: inf).
    Equalities and u_n rows are measured relative to ||x||; the friction cones
    relative to the size of the reactions, ||(r_n, r_t)|| over the cone nodes —
    not to ||x||, which a rigid lift-off (r = 0, u_n > 0) can make arbitrarily
    large without changing any reaction."""
    nr = rows.norm @ x
    if not np.isfinite(nr) or nr <= 0:
        return math.inf
    x = x / nr
    size = max(np.linalg.norm(x), 1e-300)
    v = 0.0
    if rows.eq.shape[0]:
        v = max(v, np.abs(rows.eq @ x).max() / size)
    if rows.lin.shape[0]:
        v = max(v, -(rows.lin @ x).min() / size)
    if rows.rn.shape[0]:
        rn, rt = rows.rn @ x, np.linalg.norm(rows.rt @ x, axis=1)
        rsize = max(np.sqrt((rn ** 2).sum() + (rt ** 2).sum()), 1e-300)
        v = max(v, (rt - mu * rn).max() / (max(mu, 1.0) * rsize))
    return float(v)


@functools.lru_cache(maxsize=32)
def settings(attempt: int, tight: bool = False, feasibility: bool = False):
    """Clarabel settings of attempt 0..ATTEMPTS-1 (module doc). tight: feasibility and gap
    tolerances 1e-10 (an optimisation: the branch and bound's steered solves; or every solve
    when the caller's options ask for it). feasibility: the problem has no objective (its
    first attempt is regularised, module doc). The rows are unit-scaled already, and Ruiz
    equilibration on top of that measured worse: on plug3d (m = 10, all 1,024 partitions,
    mu = 0.55 / 0.65 / 1.0) 7 % non-definitive statuses with it, none without. Shared
    (cached): do not modify the object returned."""
    import clarabel
    s = clarabel.DefaultSettings()
    s.verbose = False
    if attempt < 3:
        s.equilibrate_enable = False
    if attempt == 0 and feasibility:
        # P = 0, q = 0: the KKT (1,1) block is the static regularisation alone (module doc)
        s.static_regularization_constant = 1e-7
        s.iterative_refinement_enable = tight
        s.tol_feas = s.tol_gap_abs = s.tol_gap_rel = 1e-10
    if attempt == 2:
        s.static_regularization_constant = 1e-7
        s.max_iter = 400
    if tight:
        # an optimum (the branch and bound's steered solves) lies on the boundary,
        # where the default 1e-8 tolerances left cone rows 1e-8..4e-8 short of
        # VERIFY_TOL relative to the reactions (66 of 945 solves on plug3d, mu = 1)
        s.tol_feas = s.tol_gap_abs = s.tol_gap_rel = 1e-10
    return s


@dataclass(frozen=True)
class ConicProblem:
    """min 1/2 w'Pw + q.w s.t. A w + s = b, s in [zero (n_zero) | nonnegative (n_lin) |
    n_soc second-order cones of size 3]. q None: a feasibility problem (q = 0; P = I on
    the least-norm attempt, else P = 0)."""

    A: np.ndarray
    b: np.ndarray
    n_zero: int
    n_lin: int
    n_soc: int
    q: np.ndarray | None = None


@dataclass(frozen=True)
class Solution:
    """What Clarabel returned: its status name ("Solved", "PrimalInfeasible", ...), the
    primal point w and the dual z."""

    status: str
    x: np.ndarray
    z: np.ndarray


def pattern_socp(rows: ConeRows, mu: float) -> ConicProblem:
    """The pattern SOCP at mu in w (x = Z w): rows [sum r_n = 1 | lin | cones]."""
    Z = rows.Z
    blocks = [(rows.norm @ Z)[None, :], -(rows.lin @ Z)]
    for i in range(rows.rn.shape[0]):
        blocks.append(-np.vstack([mu * rows.rn[i], rows.rt[i]]) @ Z)
    A = np.vstack(blocks)
    b = np.zeros(A.shape[0])
    b[0] = 1.0
    return ConicProblem(A, b, 1, rows.lin.shape[0], rows.rn.shape[0])


def solve(problem: ConicProblem, attempt: int, tight: bool) -> Solution:
    """One Clarabel solve of `problem` with the settings of `attempt`."""
    import clarabel
    cones = [clarabel.ZeroConeT(problem.n_zero)]
    if problem.n_lin:
        cones.append(clarabel.NonnegativeConeT(problem.n_lin))
    cones += [clarabel.SecondOrderConeT(3) for _ in range(problem.n_soc)]
    n = problem.A.shape[1]
    if problem.q is None:
        P, q = (_csc_eye(n) if attempt == LEAST_NORM_ATTEMPT else _csc_zero(n)), np.zeros(n)
    else:
        P, q = _csc_zero(n), problem.q
    opts = settings(attempt, tight, feasibility=problem.q is None)
    sol = clarabel.DefaultSolver(P, q, _csc_dense(problem.A), problem.b, cones, opts).solve()
    return Solution(str(sol.status), np.asarray(sol.x), np.asarray(sol.z))


def attempts(plain: ConicProblem, tight: bool,
             steered: ConicProblem | None = None) -> Iterator[tuple[int, Solution]]:
    """The ladder (module doc): (attempt, solution) of each attempt in turn, lazily.
    steered: the same problem with an objective the caller may drop (attempt 0 solves it,
    tight; the retries solve `plain`). A `plain` with an objective of its own skips the
    least-norm attempt (it would replace that objective)."""
    for attempt in range(ATTEMPTS):
        if attempt == 0 and steered is not None:
            yield attempt, solve(steered, attempt, True)
        elif attempt != LEAST_NORM_ATTEMPT or plain.q is None:
            yield attempt, solve(plain, attempt, tight)


@dataclass(frozen=True)
class Outcome:
    """One attempt at the pattern SOCP, read: status (Clarabel's name); x: the point
    (x-space, Solved); farkas, certified: the certificate z (its rows laid out as in
    `pattern_socp`) and whether it passed `certificate_ok` (PrimalInfeasible); positive:
    Solved with an objective whose verified dual proves it > 0 on the feasible set."""

    attempt: int
    status: str
    x: np.ndarray | None = None
    farkas: np.ndarray | None = None
    certified: bool | None = None
    positive: bool = False


def pattern_attempts(rows: ConeRows, mu: float, tight: bool,
                     objective: np.ndarray | None = None) -> Iterator[Outcome]:
    """The pattern SOCP at mu through the ladder, each attempt read (Outcome). objective
    (x-space): minimised on attempt 0 only (a steering: the retries are plain)."""
    plain = pattern_socp(rows, mu)
    steered = None if objective is None else replace(plain, q=rows.Z.T @ objective)
    for attempt, sol in attempts(plain, tight, steered):
        if sol.status == "Solved":
            positive = False
            if attempt == 0 and steered is not None:
                # the optimal dual z (A^T z + q = 0, z in K*) with b^T z < 0 is a Farkas
                # certificate of {A w + s = b, q . w = 0}: check it like any other
                positive = certificate_ok(np.vstack([steered.q[None, :], plain.A]),
                                          np.concatenate([[0.0], plain.b]),
                                          np.concatenate([[1.0], sol.z]), 2, plain.n_lin)
            yield Outcome(attempt, sol.status, x=rows.Z @ sol.x, positive=positive)
        elif sol.status == "PrimalInfeasible":
            yield Outcome(attempt, sol.status, farkas=sol.z,
                          certified=certificate_ok(plain.A, plain.b, sol.z, 1, plain.n_lin))
        else:
            yield Outcome(attempt, sol.status)


def certificate_ok(A, b, z, n_zero, n_lin) -> bool:
    """Farkas check of {A w + s = b, s in K} infeasible, rows laid out [zero cone
    (n_zero) | nonnegative (n_lin) | second-order cones of size 3]: with z scaled to
    b^T z = -1, ||A^T z||_inf and z's distance from the dual cone (K* = K here; free
    on the zero cone) must be <= CERT_TOL, i.e. no point w with ||w||_1 below about
    1 / CERT_TOL is feasible."""
    bz = b @ z
    if not np.isfinite(bz) or bz >= 0:
        return False
    z = z / -bz
    if np.abs(A.T @ z).max() > CERT_TOL:
        return False
    zl = z[n_zero:n_zero + n_lin]
    if n_lin and zl.min() < -CERT_TOL:
        return False
    zc = z[n_zero + n_lin:].reshape(-1, 3)
    if len(zc) and (np.linalg.norm(zc[:, 1:], axis=1) - zc[:, 0]).max() > CERT_TOL:
        return False
    return True


def _csc_dense(A: np.ndarray) -> sp.csc_matrix:
    """A dense matrix as CSC with every entry stored (the from-dense conversion of
    scipy costs more than the solve here)."""
    r, c = A.shape
    return sp.csc_matrix((np.ascontiguousarray(A.T).ravel(), np.tile(np.arange(r, dtype=np.int64), c),
                          np.arange(0, r * c + 1, r, dtype=np.int64)), shape=(r, c))


@functools.lru_cache(maxsize=256)
def _csc_eye(n: int) -> sp.csc_matrix:
    return sp.identity(n, format="csc")


@functools.lru_cache(maxsize=256)
def _csc_zero(n: int) -> sp.csc_matrix:
    return sp.csc_matrix((np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(n + 1, dtype=np.int64)),
                         shape=(n, n))
