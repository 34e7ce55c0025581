"""The Clarabel adapter: the one builder of conic problems, the solver settings (values,
no module state), the retry ladder of attempts, and the checks of what Clarabel returns
(a point's violation, a Farkas certificate).

Every conic problem here has the form  min 1/2 w'Pw + q.w  s.t.  A w + s = b,  s in K,
with K = [zero cone (n_zero) | nonnegative (n_lin) | second-order cones of size 3 (n_soc)]
(`ConicProblem`). The pattern SOCP (rows.ConeRows) is one, built twice: in reaction
coordinates for the first attempt (`reaction_socp`, sparse), in the null space of its
equalities for the retries (`pattern_socp`); Dinkelbach's
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

Long steps (`settings(long_steps=True)`, for the caller to choose): the first attempt of a
feasibility problem steps 0.999 of the way to the cone's boundary instead of Clarabel's
0.99. On 1,500 tree SOCPs of plug3d 3 x 6 (mu = 0.65) that takes 7.05 iterations on a
feasible problem against 8.10, and 7.97 on an infeasible one against 9.61, every answer
verified either way; the enumeration at a given mu uses them. Near a mu^c the feasible
set thins out and long steps fail more: the global mu^c tree on plug3d 4 x 6 left 1 node
undecided with them and 2 at 0.9999 (3 x 8: 0 and 2), none with 0.99, so the mu^c searches
keep Clarabel's steps.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from typing import Iterator

import numpy as np
import scipy.sparse as sp

from .problem import ReactionCoordinates, kept_on
from .rows import ConeRows, kept_sizes

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
#: max_step_fraction of a long-step first attempt (Clarabel's default: 0.99; module doc)
LONG_STEP = 0.999


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
def settings(attempt: int, tight: bool = False, feasibility: bool = False, long_steps: bool = False):
    """Clarabel settings of attempt 0..ATTEMPTS-1 (module doc). tight: feasibility and gap
    tolerances 1e-10 (an optimisation: the branch and bound's steered solves; or every solve
    when the caller's options ask for it). feasibility: the problem has no objective (its
    first attempt is regularised, module doc). The rows are unit-scaled already, and Ruiz
    equilibration on top of that measured worse: on plug3d (m = 10, all 1,024 partitions,
    mu = 0.55 / 0.65 / 1.0) 7 % non-definitive statuses with it, none without. long_steps
    (attempt 0 of a feasibility problem): each interior-point step goes LONG_STEP of the
    way to the cone's boundary (module doc). Shared (cached): do not modify the object
    returned."""
    import clarabel
    s = clarabel.DefaultSettings()
    s.verbose = False
    if attempt < 3:
        s.equilibrate_enable = False
    if attempt == 0 and feasibility:
        # P = 0, q = 0: the KKT (1,1) block is the static regularisation alone (module doc)
        s.static_regularization_constant = 1e-7
        s.iterative_refinement_enable = tight
        if long_steps:
            s.max_step_fraction = LONG_STEP
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


@dataclass(frozen=True)
class ReactionSOCP:
    """The pattern SOCP in x' = (r, beta) (`reaction_socp`): problem, rows laid out
    [sum r_n = 1 | equilibrium E r = 0 | contact u_n = 0 (zero cone) | lin (u_n >= 0) |
    cones]; w = (r on `cols`, beta). lin_nodes / lin_scale: the node of each lin row and
    the norm it was scaled by."""

    problem: ConicProblem
    rows: ConeRows
    cols: np.ndarray
    lin_nodes: np.ndarray
    lin_scale: np.ndarray

    def to_x(self, w: np.ndarray) -> np.ndarray:
        """The x-space point of w."""
        form = self.rows.reactions
        r = np.zeros(form.B.shape[0])
        r[self.cols] = w[:len(self.cols)]
        return form.to_x(r, w[len(self.cols):])

    def objective(self, c: np.ndarray) -> np.ndarray:
        """q with q . w = c . x (c x-space)."""
        B = self.rows.reactions.B
        return np.concatenate([(B @ c[:B.shape[1]])[self.cols], c[B.shape[1]:]])

    def farkas(self, z: np.ndarray) -> np.ndarray | None:
        """A certificate z of this problem in the layout of `pattern_socp` (the same
        multipliers, rescaled to its rows), or None when the two keep other lin rows."""
        rows, p = self.rows, self.problem
        if not np.array_equal(self.lin_nodes, rows.lin_nodes):
            return None
        lin = z[p.n_zero:p.n_zero + p.n_lin] * rows.lin_scale / self.lin_scale
        cones = (z[p.n_zero + p.n_lin:].reshape(-1, 3) * rows.scale[:, None]).ravel()
        return np.concatenate([z[:1], lin, cones])


def reaction_socp(rows: ConeRows, mu: float) -> ReactionSOCP:
    """The pattern SOCP at mu in x' = (r, beta) (problem.ReactionCoordinates): the gap
    nodes' reactions dropped, every cone a coordinate cone (one entry per row), the
    u_n rows and equilibrium dense: a KKT system a third the work of `pattern_socp`'s
    dense null-space form (plug3d 3 x 6: Clarabel 0.64 against 1.13 ms per SOCP, the same
    answers on all 6,791 of the enumeration's SOCPs), and no SVD. Dense rows unit-scaled,
    rows that vanish on the kept columns dropped (as rows.kept_rows does)."""
    form = rows.reactions
    n, m = form.B.shape[0], rows.zero_u.shape[0]
    k = form.E.shape[0]
    nodes = rows.nodes
    c, nb = len(nodes), form.U.shape[1] - n
    cols = (nodes[:, None] + _THREE * m).ravel()
    # [equilibrium; u_n of every node] on the kept columns, each row's norm
    rest = np.ascontiguousarray(_equilibrium_normal_rows(form, m)[:, np.concatenate([cols, np.arange(n, n + nb)])])
    size = np.sqrt(np.einsum("ij,ij->i", rest, rest))
    kept = kept_sizes(size)
    eq = np.flatnonzero(kept & np.concatenate([np.ones(k, bool), rows.zero_u]))
    lin = np.flatnonzero(kept & np.concatenate([np.zeros(k, bool), ~rows.zero_u]))
    lin_scale = size[lin]
    body = rest[np.concatenate([eq, lin])] / np.concatenate([size[eq], -lin_scale])[:, None]
    A = DenseDiag.of(body, 3 * c, mu)
    b = np.zeros(A.shape[0])
    b[0] = 1.0
    problem = ConicProblem(A, b, 1 + len(eq), len(lin), c)
    return ReactionSOCP(problem, rows, cols, lin - k, lin_scale)


def _equilibrium_normal_rows(form: ReactionCoordinates, m: int) -> np.ndarray:
    """[E 0; U_n] (E rows + m, n + n_beta): the rows `reaction_socp` cuts its dense block
    from, computed once per parametrisation (kept on `form`)."""
    def build() -> np.ndarray:
        k, n = form.E.shape
        rest = np.zeros((k + m, form.U.shape[1]))
        rest[:k, :n] = form.E
        rest[k:] = form.U[:m]
        return rest
    return kept_on(form, f"_equilibrium_normal_rows_{m}", build)


def solve(problem: ConicProblem, attempt: int, tight: bool, long_steps: bool = False) -> Solution:
    """One Clarabel solve of `problem` with the settings of `attempt` (long_steps: see
    `settings`)."""
    import clarabel
    cones = [clarabel.ZeroConeT(problem.n_zero)]
    if problem.n_lin:
        cones.append(clarabel.NonnegativeConeT(problem.n_lin))
    cones += [clarabel.SecondOrderConeT(3) for _ in range(problem.n_soc)]
    n = problem.A.shape[1]
    if problem.q is None:
        P, q = _csc_square(n, attempt == LEAST_NORM_ATTEMPT), np.zeros(n)
    else:
        P, q = _csc_square(n, False), problem.q
    opts = settings(attempt, tight, feasibility=problem.q is None, long_steps=long_steps)
    sol = clarabel.DefaultSolver(P, q, _clarabel_csc(problem.A), problem.b, cones, opts).solve()
    return Solution(str(sol.status), np.asarray(sol.x), np.asarray(sol.z))


def attempts(plain: ConicProblem, tight: bool, steered: ConicProblem | None = None,
             start: int = 0) -> Iterator[tuple[int, Solution]]:
    """The ladder (module doc): (attempt, solution) of each attempt from `start` on, lazily.
    steered: the same problem with an objective the caller may drop (attempt 0 solves it,
    tight; the retries solve `plain`). A `plain` with an objective of its own skips the
    least-norm attempt (it would replace that objective)."""
    for attempt in range(start, ATTEMPTS):
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
                     objective: np.ndarray | None = None, long_steps: bool = False) -> Iterator[Outcome]:
    """The pattern SOCP at mu through the ladder, each attempt read (Outcome): attempt 0
    in reaction coordinates (`reaction_socp`), the retries in the null space of the
    pattern's equalities (`pattern_socp`: no dependent equality row reaches the solver).
    objective (x-space): minimised on attempt 0 only (a steering: the retries are plain).
    long_steps: attempt 0 takes long interior-point steps (`settings`)."""
    first = reaction_socp(rows, mu)
    plain = first.problem
    steered = None if objective is None else replace(plain, q=first.objective(objective))
    sol = solve(plain if steered is None else steered, 0, tight or steered is not None, long_steps)
    yield _outcome(0, sol, plain, steered, first.to_x, first.farkas)
    plain = pattern_socp(rows, mu)
    for attempt, sol in attempts(plain, tight, start=1):
        yield _outcome(attempt, sol, plain, None, lambda w: rows.Z @ w, lambda z: z)


def _outcome(attempt: int, sol: Solution, plain: ConicProblem, steered: ConicProblem | None,
             to_x, farkas) -> Outcome:
    """One solution read: its point in x-space (to_x), its certificate checked on `plain`
    and handed on in `pattern_socp`'s layout (farkas)."""
    if sol.status == "Solved":
        positive = False
        if steered is not None:
            # the optimal dual z (A^T z + q = 0, z in K*) with b^T z < 0 is a Farkas
            # certificate of {A w + s = b, q . w = 0}: check it like any other
            positive = certificate_ok(plain.A, plain.b, sol.z, plain.n_zero, plain.n_lin, q=steered.q)
        return Outcome(attempt, sol.status, x=to_x(sol.x), positive=positive)
    if sol.status == "PrimalInfeasible":
        certified = certificate_ok(plain.A, plain.b, sol.z, plain.n_zero, plain.n_lin)
        return Outcome(attempt, sol.status, farkas=farkas(sol.z) if certified else None,
                       certified=certified)
    return Outcome(attempt, sol.status)


def certificate_ok(A, b, z, n_zero, n_lin, q: np.ndarray | None = None) -> bool:
    """Farkas check of {A w + s = b, s in K} infeasible, rows laid out [zero cone
    (n_zero) | nonnegative (n_lin) | second-order cones of size 3]: with z scaled to
    b^T z = -1, ||A^T z||_inf and z's distance from the dual cone (K* = K here; free
    on the zero cone) must be <= CERT_TOL, i.e. no point w with ||w||_1 below about
    1 / CERT_TOL is feasible. q: the check of {q . w = 0, A w + s = b} instead, the
    multiplier of the extra row 1 (an optimal dual z of min q . w over the set, for
    which A^T z + q = 0)."""
    bz = b @ z
    if not np.isfinite(bz) or bz >= 0:
        return False
    z = z / -bz
    ATz = _rmatvec(A, z)
    if q is not None:
        ATz += q / -bz
    if np.abs(ATz).max() > CERT_TOL:
        return False
    zl = z[n_zero:n_zero + n_lin]
    if n_lin and zl.min() < -CERT_TOL:
        return False
    zc = z[n_zero + n_lin:].reshape(-1, 3)
    if len(zc) and (np.linalg.norm(zc[:, 1:], axis=1) - zc[:, 0]).max() > CERT_TOL:
        return False
    return True


_THREE = np.arange(3)


@dataclass(frozen=True)
class DenseDiag:
    """The matrix [1_r; D; diag(d) 0] of `reaction_socp` (shape (k + nd, n), k = 1 + rows
    of D): a first row with 1 on every nd column that is an r_n (columns 0, 3, 6, ...),
    D (k - 1, n) dense with every entry stored, d = (-mu, -1, -1, ...) on the first nd
    columns. Kept as Clarabel reads a CSC matrix: `data` column by column (one column: its
    k dense entries, then its diagonal entry if it has one)."""

    data: np.ndarray
    k: int
    nd: int
    n: int

    @classmethod
    def of(cls, D: np.ndarray, nd: int, mu: float) -> "DenseDiag":
        k, n = D.shape[0] + 1, D.shape[1]
        A = cls(np.empty(nd * (k + 1) + (n - nd) * k), k, nd, n)
        head, tail = A._columns()
        head[:, 0] = 0.0
        head[0::3, 0] = 1.0
        head[:, 1:k] = D[:, :nd].T
        head[:, k] = -1.0
        head[0::3, k] = -mu
        tail[:, 0] = 0.0
        tail[:, 1:] = D[:, nd:].T
        return A

    def _columns(self) -> tuple[np.ndarray, np.ndarray]:
        """Views of `data`: the first nd columns (nd, k + 1: dense part, then the diagonal
        entry) and the others (n - nd, k)."""
        split = self.nd * (self.k + 1)
        return (self.data[:split].reshape(self.nd, self.k + 1),
                self.data[split:].reshape(self.n - self.nd, self.k))

    @property
    def shape(self) -> tuple[int, int]:
        return self.k + self.nd, self.n

    def rmatvec(self, z: np.ndarray) -> np.ndarray:
        """A^T z."""
        head, tail = self._columns()
        k = self.k
        return np.concatenate([head[:, :k] @ z[:k] + head[:, k] * z[k:], tail @ z[:k]])

    def toarray(self) -> np.ndarray:
        head, tail = self._columns()
        out = np.zeros(self.shape)
        out[:self.k] = np.concatenate([head[:, :self.k], tail]).T
        out[self.k + np.arange(self.nd), np.arange(self.nd)] = head[:, self.k]
        return out


def _rmatvec(A, z: np.ndarray) -> np.ndarray:
    """A^T z for a ConicProblem's A (dense, DenseDiag or scipy sparse)."""
    return A.rmatvec(z) if isinstance(A, DenseDiag) else A.T @ z


class _ClarabelCsc:
    """A CSC matrix as Clarabel's binding reads one (the attributes of a scipy csc_matrix in
    canonical format), its arrays as Python lists: the binding copies them element by
    element, which costs less from a list than from a numpy array (plug3d 3 x 6's tree
    SOCPs: setup 120 against 162 us)."""

    __slots__ = ("data", "indices", "indptr", "shape", "nnz")
    has_canonical_format = True

    def __init__(self, data: list, indices: list, indptr: list, shape: tuple[int, int]):
        self.data, self.indices, self.indptr, self.shape, self.nnz = data, indices, indptr, shape, len(data)


def _clarabel_csc(A) -> _ClarabelCsc:
    """A ConicProblem's A for Clarabel: a DenseDiag or a dense array with every entry
    stored (scipy's from-dense conversion costs more than the solve here), or a scipy
    sparse matrix as it is."""
    if isinstance(A, DenseDiag):
        return _ClarabelCsc(A.data.tolist(), *_dense_diag_pattern(A.k, A.nd, A.n), A.shape)
    if isinstance(A, np.ndarray):
        r, c = A.shape
        return _ClarabelCsc(A.T.ravel().tolist(), *_dense_diag_pattern(r, 0, c), (r, c))
    A = sp.csc_matrix(A)
    A.sort_indices()
    return _ClarabelCsc(A.data.tolist(), A.indices.tolist(), A.indptr.tolist(), A.shape)


@functools.lru_cache(maxsize=1024)
def _dense_diag_pattern(k: int, nd: int, n: int) -> tuple[list, list]:
    """(indices, indptr) of a (k + nd, n) CSC matrix with every entry of its first k rows
    stored and one entry below them in each of its first nd columns (shared: not to be
    modified)."""
    head = np.arange(k)
    indices = np.concatenate([np.hstack([np.tile(head, (nd, 1)), (k + np.arange(nd))[:, None]]).ravel(),
                              np.tile(head, n - nd)])
    indptr = np.concatenate([np.arange(nd + 1) * (k + 1), nd * (k + 1) + np.arange(1, n - nd + 1) * k])
    return indices.tolist(), indptr.tolist()


@functools.lru_cache(maxsize=256)
def _csc_square(n: int, identity: bool) -> _ClarabelCsc:
    """The (n, n) identity or zero matrix for Clarabel (shared: not to be modified)."""
    if identity:
        return _ClarabelCsc([1.0] * n, list(range(n)), list(range(n + 1)), (n, n))
    return _ClarabelCsc([], [], [0] * (n + 1), (n, n))
