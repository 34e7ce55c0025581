"""One Clarabel solve of a conic problem: its form (`ConicProblem`), the settings of each
attempt of the ladder (`settings`, values), the matrix as Clarabel's binding reads it
(`DenseDiag`, `_clarabel_csc`), and the solve itself (`solve`), on a kept solver of the
problem's structure when there is one (`_KeptSolvers`). socp.py builds the pattern SOCPs
and reads the answers.

Every conic problem here has the form  min 1/2 w'Pw + q.w  s.t.  A w + s = b,  s in K,
with K = [zero cone (n_zero) | nonnegative (n_lin) | second-order cones of size 3 (n_soc)].

The ladder (socp.attempts): attempt k uses `settings(k, tight)`. 0: plain; 1: the least-norm
feasible point (P = I; when the plain solve returned a point that does not verify: the
iterates can run off along rigid lift-offs, measured up to ||x|| ~ 1e17; P = I is not the
default because it weakens the infeasibility certificates: 732 of 2,126 failed the Farkas
check on plug3d + 30 random free bodies, none with P = 0); 2: static regularisation 1e-7;
3: Clarabel's defaults (equilibration on).

A feasibility problem (no objective) starts with static regularisation 1e-7 and no iterative
refinement: with Clarabel's 1e-8 the first attempt stopped at NumericalError after one
zero-length step on 37 % of plug3d 3 x 6's SOCPs (62 % at 4 x 6), every one of which 1e-7
decides; refinement adds nothing to a problem without an objective and cost a third of the
solve time (scripts/bench_socp_count.py; issue 13's measurements in docs/benchmarks.md). Its
tolerances are 1e-10: a point Clarabel calls solved must pass socp.VERIFY_TOL, which at the
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

Every solve is bounded: by TIME_LIMIT_S (Clarabel's time_limit; MaxTime is UNDECIDED, which
every caller treats as deciding nothing) and, inside an engine task, by the engine's stop:
Clarabel asks parallel.task_stopping() after every iteration (its termination callback),
and a solve cut short so raises TaskCancelled, so that no caller reads an answer from it
(a stop is served within one interior-point iteration: ~0.1 s at m = 128).
"""
from __future__ import annotations

import contextlib
import functools
import threading
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hpcwedge.parallel.cancel import TaskCancelled, task_scope, task_stopping
from hpcwedge.solvers.rows import Status

#: the attempts of the ladder (module doc), and the one that seeks the least-norm point
ATTEMPTS = 4
LEAST_NORM_ATTEMPT = 1
#: max_step_fraction of a long-step first attempt (Clarabel's default: 0.99; module doc)
LONG_STEP = 0.999
#: Clarabel's time_limit on every solve (seconds). The slowest attempt measured on the
#: largest SOCP tested (plug3d 8 x 16, m = 128; patterns of 70 % contact and all contact,
#: mu 0.1763 / 0.5 / 2, plain and tight) took 2.8 s (the least-norm attempt; 5.6 s once on
#: the shared 2-core machine): the limit is ~10x that, so no answer at a tested size changes
TIME_LIMIT_S = 30.0


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
    # no b here is infinite, so presolve would remove no row; off, a kept solver takes data
    # updates (_KeptSolvers)
    s.presolve_enable = False
    s.time_limit = TIME_LIMIT_S
    # the thread policy (environment.py): "auto" picks faer's LDL for larger KKT systems,
    # which by default runs a thread per core (the bits then depend on the cores a rank
    # may use, and on 2 busy cores the threads spun: plug3d 8 x 16, 12.3 s instead of 7)
    s.max_threads = 1
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


#: Clarabel's statuses, by their names (str of a clarabel.SolverStatus), in the package's
#: vocabulary: FEASIBLE, a point (an optimum where the problem has an objective);
#: INFEASIBLE, a certificate of primal infeasibility; every other status decides nothing
#: (no problem here is unbounded below: DualInfeasible is a numerical answer too)
CLARABEL_STATUS = {
    "Solved": Status.FEASIBLE,
    "PrimalInfeasible": Status.INFEASIBLE,
    "DualInfeasible": Status.UNDECIDED,
    "AlmostSolved": Status.UNDECIDED,
    "AlmostPrimalInfeasible": Status.UNDECIDED,
    "AlmostDualInfeasible": Status.UNDECIDED,
    "MaxIterations": Status.UNDECIDED,
    "MaxTime": Status.UNDECIDED,
    "NumericalError": Status.UNDECIDED,
    "InsufficientProgress": Status.UNDECIDED,
    "CallbackTerminated": Status.UNDECIDED,
    "Unsolved": Status.UNDECIDED,
}


class Solution:
    """What Clarabel returned: its status (CLARABEL_STATUS; a status it does not list is
    UNDECIDED), the status's own name (the key the stats count it under: "Solved",
    "PrimalInfeasible", ...), the primal point w and the dual z (numpy arrays, read from
    Clarabel's answer on first use: a tree node solved without an objective never reads z)."""

    def __init__(self, answer):
        self.name = str(answer.status)
        self.status = CLARABEL_STATUS.get(self.name, Status.UNDECIDED)
        self._answer = answer

    @functools.cached_property
    def x(self) -> np.ndarray:
        return np.asarray(self._answer.x)

    @functools.cached_property
    def z(self) -> np.ndarray:
        return np.asarray(self._answer.z)


def solve(problem: ConicProblem, attempt: int, tight: bool, long_steps: bool = False) -> Solution:
    """One Clarabel solve of `problem` with the settings of `attempt` (long_steps: see
    `settings`): on a kept solver of the same structure when there is one (`_KeptSolvers`),
    else on a new one. Raises TaskCancelled when the engine stops the task mid-solve
    (module doc)."""
    import clarabel
    n = problem.A.shape[1]
    identity = problem.q is None and attempt == LEAST_NORM_ATTEMPT
    opts = settings(attempt, tight, feasibility=problem.q is None, long_steps=long_steps)
    key = _KEPT.key(problem, identity, opts)
    solver = _KEPT.take(key)
    if solver is not None:
        data = _floats(_clarabel_data(problem.A))
        entries = len(data)
        if problem.q is None:
            # the key's settings say "no objective", so the kept solver's q is 0 already
            solver.update(A=data, b=_floats(problem.b))
        else:
            solver.update(A=data, b=_floats(problem.b), q=_floats(problem.q))
        sol = Solution(solver.solve())
        _raise_if_stopped(sol)
        if sol.status == Status.UNDECIDED:
            # a solve that fails on its first step restores Clarabel's "previous iterate",
            # which on a kept solver is the last problem's: again on a new solver
            solver = None
    if solver is None:
        A = _clarabel_csc(problem.A)
        entries = A.nnz
        cones = [clarabel.ZeroConeT(problem.n_zero)]
        if problem.n_lin:
            cones.append(clarabel.NonnegativeConeT(problem.n_lin))
        cones += [clarabel.SecondOrderConeT(3) for _ in range(problem.n_soc)]
        q = np.zeros(n) if problem.q is None else problem.q
        solver = clarabel.DefaultSolver(_csc_square(n, identity), q, A, problem.b, cones, opts)
        solver.set_termination_callback(_stopping)
        sol = Solution(solver.solve())
        _raise_if_stopped(sol)
    if sol.status != Status.UNDECIDED:
        _KEPT.keep(key, solver, entries)
    return sol


def _stopping(info) -> bool:
    """Clarabel's termination callback (after every iteration): the engine is stopping."""
    return task_stopping()


def _raise_if_stopped(sol: Solution) -> None:
    """TaskCancelled for a solve that decided nothing while the engine stops the task (the
    callback ended it, or it failed as the stop came: task_stopping stays True, so either
    way no caller reads it)."""
    if sol.status == Status.UNDECIDED and task_stopping():
        raise TaskCancelled()


class _KeptSolvers(threading.local):
    """Clarabel solvers kept after a solve, by the structure of their problem (cones, A's
    sparsity pattern, P, settings), the least recently used dropped beyond `size` solvers or
    `entries` stored entries of A in all. A problem of a kept structure is solved by a data
    update of A, b and q instead of a new solver, without Clarabel's setup (the symbolic
    factorisation of its KKT system: ~120 of the ~470 us of a tree SOCP at m = 18). The
    answer is a new solver's bit for bit: the same KKT ordering and start, and Clarabel
    reads nothing from an earlier solve but the "previous iterate" it restores when a step
    fails, before the first one of this solve has been saved; so only a decided status
    (FEASIBLE or INFEASIBLE) is taken from a kept solver, any other is solved again on a
    new one (tests/solvers/test_conic.py compares all of them; every SOCP of plug3d 3 x 6's
    tree the same). Only problems whose pattern is a function of their shape are kept
    (DenseDiag, dense arrays), and only under settings without equilibration (a data update
    keeps the first problem's scaling) or presolve (which forbids updates). Process and
    thread state: each MPI rank and each thread has its own solvers.

    Not bit for bit in every case: a kept solver decided a problem on which a new one stops
    at its first step (plug3d 3 x 6, mu = 1.0: a tight attempt 0 with an objective, FEASIBLE
    in 11 iterations against UNDECIDED in 1), which moved a mu^c by 1-2 ulp with the solvers
    kept before it. So every engine task has solvers of its own (`task_solvers`, entered by
    parallel.run_cancellable): its answer depends on its payload only, whatever the rank
    ran before, and the master's solvers are the same serially and under mpirun."""

    def __init__(self, size: int, entries: int):
        self.size, self.entries = size, entries
        self._solvers: dict = {}
        self._stored = 0

    def key(self, problem: ConicProblem, identity: bool, opts) -> tuple | None:
        """The structure of `problem` under `opts` (None: not to be kept)."""
        A = problem.A
        if opts.equilibrate_enable or opts.presolve_enable:
            return None
        if isinstance(A, DenseDiag):
            shape = ("diag", A.k, A.nd, A.n)
        elif isinstance(A, np.ndarray):
            shape = ("dense",) + A.shape
        else:
            return None
        # the settings object itself (hashed by identity; the key keeps it alive)
        return (opts, identity, problem.n_zero, problem.n_lin, problem.n_soc) + shape

    def take(self, key: tuple | None):
        """The kept solver of `key`, no longer kept (None: none)."""
        kept = None if key is None else self._solvers.pop(key, None)
        if kept is None:
            return None
        self._stored -= kept[1]
        return kept[0]

    def keep(self, key: tuple | None, solver, entries: int) -> None:
        """Keep `solver` (of `key`, A with `entries` stored entries) as the most recent."""
        if key is None or entries > self.entries:
            return
        self._solvers[key] = (solver, entries)          # insertion order: the most recent last
        self._stored += entries
        while len(self._solvers) > self.size or self._stored > self.entries:
            self._stored -= self._solvers.pop(next(iter(self._solvers)))[1]


#: the solvers kept for reuse (_KeptSolvers): the structures a tree meets (plug3d 3 x 6 at
#: mu = 0.65: 163 among its 7,219 SOCPs), within ~2^22 entries of A (a few tens of MB)
_KEPT = _KeptSolvers(256, 1 << 22)


@contextlib.contextmanager
def task_solvers():
    """The span of one engine task (registered with parallel.task_scope): no kept solver at
    its start, and the caller's kept solvers back at its end (this thread's)."""
    outer = _KEPT._solvers, _KEPT._stored
    _KEPT._solvers, _KEPT._stored = {}, 0
    try:
        yield
    finally:
        _KEPT._solvers, _KEPT._stored = outer


task_scope(task_solvers)


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
    def of(cls, Dt: np.ndarray, nd: int, mu: float) -> "DenseDiag":
        """The matrix of D = Dt.T (Dt (n, k - 1): D's columns as rows)."""
        n, k = Dt.shape[0], Dt.shape[1] + 1
        template, dense, mus = _dense_diag_layout(k, nd, n)
        data = template.copy()
        data[dense] = Dt.ravel()
        data[mus] = -mu
        return cls(data, k, nd, n)

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


def rmatvec(A, z: np.ndarray) -> np.ndarray:
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


def _floats(v) -> memoryview:
    """v for a data update: a memoryview of float64s, which the binding reads item by item
    like a list, without building the list (plug3d 3 x 6's tree SOCPs: an update of A and b
    36 us against 44 us from tolist)."""
    return memoryview(np.ascontiguousarray(v, dtype=float))


def _clarabel_data(A) -> np.ndarray:
    """The stored entries of a kept structure's A (a DenseDiag or a dense array), as
    `_clarabel_csc` lays them out."""
    return A.data if isinstance(A, DenseDiag) else A.T.ravel()


def _clarabel_csc(A) -> _ClarabelCsc:
    """A ConicProblem's A for Clarabel: a DenseDiag or a dense array with every entry
    stored (scipy's from-dense conversion costs more than the solve here), or a scipy
    sparse matrix as it is."""
    if isinstance(A, DenseDiag):
        return _ClarabelCsc(_clarabel_data(A).tolist(), *_dense_diag_pattern(A.k, A.nd, A.n), A.shape)
    if isinstance(A, np.ndarray):
        r, c = A.shape
        return _ClarabelCsc(_clarabel_data(A).tolist(), *_dense_diag_pattern(r, 0, c), (r, c))
    A = sp.csc_matrix(A)
    A.sort_indices()
    return _ClarabelCsc(A.data.tolist(), A.indices.tolist(), A.indptr.tolist(), A.shape)


@functools.lru_cache(maxsize=1024)
def _dense_diag_layout(k: int, nd: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where a DenseDiag (k, nd, n) keeps its entries in `data`: the entries it holds for any
    D and mu (the first row's 1s and 0s, the diagonal's -1s), the positions of D's entries
    (column by column) and of the diagonal's -mu (shared: read-only)."""
    split = nd * (k + 1)
    template = np.zeros(split + (n - nd) * k)
    head = template[:split].reshape(nd, k + 1)
    head[0::3, 0] = 1.0
    head[:, k] = -1.0
    dense = np.empty((n, k - 1), np.intp)
    dense[:nd] = (np.arange(nd) * (k + 1))[:, None] + 1 + np.arange(k - 1)
    dense[nd:] = (split + np.arange(n - nd) * k)[:, None] + 1 + np.arange(k - 1)
    mus = np.arange(0, nd, 3) * (k + 1) + k
    out = (template, dense.ravel(), mus)
    for a in out:
        a.flags.writeable = False
    return out


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
