"""LP feasibility of a pattern problem (`rows.Rows`) by HiGHS (highspy), and the violation
of a point of it; every HiGHS call of the package is made here (`highs_run`): bounded by a
time limit and interruptible by a stop (parallel.cancel).

2D patterns are LPs, and so are the 3D pyramid fallbacks (rows.pyramid_rows). HiGHS's
dual simplex returns a vertex: the polish of mu^c (mu_bracket.py) needs its active set.
"""
from __future__ import annotations

import atexit
import contextlib
import os
import sys
import time

import numpy as np

from hpcwedge.contact.problem import Parametrization, blocks
from hpcwedge.dense import dense_call
from hpcwedge.parallel.cancel import TaskCancelled, task_stopping
from hpcwedge.solvers.rows import ZERO_ROW_RTOL, Rows, Status, count, eq_null_space

#: HiGHS options of the pattern LPs (2D) and the pyramid LPs (3D fallback); None given to
#: `lp_feasible`: HiGHS's defaults (feasibility tolerance 1e-7). Presolve stays on: off,
#: the dual simplex ended "Unknown" near mu^c on a random free body (m = 3)
LP_OPTIONS = {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10}
#: the HiGHS solver of each `lp_feasible` method: dual simplex (a vertex) or interior point
#: (with crossover)
LP_METHODS = {"simplex": {"solver": "simplex", "simplex_strategy": 1}, "ipm": {"solver": "ipm"}}
#: the eliminated LP again after the dual simplex left it undecided: HiGHS's primal simplex
#: (plug2d m = 160, a bisection LP of mu^c: dual "Unknown" after 499 iterations, primal
#: infeasible in 250; the x-space LP that decided it instead took 3 s)
PRIMAL = {"simplex_strategy": 4}
#: seconds one HiGHS LP may run (`lp_feasible`); one that hits it is UNDECIDED. The MILP has
#: its own (milp.wedge_milp): both are interruptible by a stop besides
LP_TIME_LIMIT_S = 120.0
#: absolute violation of the unit x-space rows (sum r_n = 1) that a point of the eliminated
#: LP may keep (lp_feasible): the x-space LP's own feasibility tolerance. At 1e-9 a point
#: with ||x|| ~ 8e6 (equality rows 4.5e-10 off through rounding alone) passed 3e-8 below a
#: random free body's mu^c under OpenBLAS's Haswell kernels; the solution there has ||x|| 16
X_SPACE_TOL = LP_OPTIONS["primal_feasibility_tolerance"]
#: a point of the eliminated LP whose normalisation share 1 / (||norm|| ||x||), times sqrt(d),
#: is below this is decided by the x-space LP: a near-recession point passes the rows to
#: tolerance yet lies far from the answer (a random free body, d = 6, 4e-9 below its mu^c
#: under OpenBLAS's Haswell kernels: ||x|| 1.2e6 against 16 for the solution, share x
#: sqrt(d) 3e-5; the least of plug2d's solutions, m = 20 and 160: 1.5e-3 and 4e-3)
NORM_SHARE_MIN = 1e-2
#: a point whose unit rows all hold to this, relative to |x|, is taken whatever its
#: normalisation share (lp_feasible, pattern_lp.point_holds, TreeLp): rounding, not a near-recession
#: direction met to tolerance (a random free body's margin point: |x| 1.2e3, share 7e-3,
#: rows to 1e-16; block2d m = 160, tree nodes near mu^c: |x| ~ 750, share 2e-3, rows to 1e-15)
ROUNDING_RTOL = 1e-13


def point_accepted(worst: float, x: np.ndarray, norm: np.ndarray) -> bool:
    """The one rule by which every LP route takes a point x (lp_feasible, TreeLp,
    pattern_lp.point_holds): `worst`, its largest violation of the unit x-space rows and of
    sum r_n = 1 (`norm` . x = 1), is at most X_SPACE_TOL, and either its normalisation
    share 1 / (||norm|| ||x||) times sqrt(d) is at least NORM_SHARE_MIN or worst is at most
    ROUNDING_RTOL ||x|| (rounding, not a near-recession direction met to tolerance)."""
    size = float(np.linalg.norm(x))
    share = 1.0 / max(float(np.linalg.norm(norm)) * size, 1e-300)
    return bool(worst <= X_SPACE_TOL and (share * np.sqrt(x.size) >= NORM_SHARE_MIN or worst <= ROUNDING_RTOL * size))


#: HiGHS's model statuses (HighsModelStatus names) in the package's vocabulary: kOptimal a
#: point (a feasibility LP has no objective, the MILP's is bounded), kInfeasible none; every
#: other one (time or iteration limit, interrupt, unbounded or infeasible, unknown, errors):
#: nothing decided
HIGHS_STATUS = {"kOptimal": Status.FEASIBLE, "kInfeasible": Status.INFEASIBLE}
#: a stop interrupts a HiGHS call that has run this long (seconds); a shorter call ends, and
#: the caller's own check stops the task between calls (a tree then hands back its open nodes)
INTERRUPT_AFTER_S = 0.1
#: |A^T y|_1 of an accepted dual ray of a warm model (TreeLp, PatternLp), relative to the
#: bound it proves (y_norm)
FARKAS_RTOL = 1e-9
_banner_shown = False
_call_started = 0.0


def highs_instance(options: dict, time_limit: float | None, polled: bool = True):
    """A silent HiGHS instance with `options` (HiGHS's names), `time_limit` seconds per run
    (None: none), and a stop (parallel.cancel.task_stopping) interrupting its simplex,
    interior point and branch and bound past INTERRUPT_AFTER_S (HiGHS polls them every few
    iterations / nodes)."""
    global _banner_shown
    import highspy
    if not _banner_shown:               # the first instance prints HiGHS's banner on stdout
        with stdout_silenced():
            h = highspy.Highs()
        _banner_shown = True
    else:
        h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    for k, v in options.items():
        h.setOptionValue(k, v)
    h.run_limit_s = time_limit          # highs_run re-arms it: HiGHS's clock adds up over runs
    if time_limit is not None:
        h.setOptionValue("time_limit", float(time_limit))
    if polled:
        for cb in (h.cbSimplexInterrupt, h.cbIpmInterrupt, h.cbMipInterrupt):
            cb += _interrupt_on_stop
    return h


def _interrupt_on_stop(event) -> None:
    if time.monotonic() - _call_started >= INTERRUPT_AFTER_S and task_stopping():
        event.interrupt()


def _arm_time_limit(h) -> None:
    """The instance's time limit (highs_instance's) from now: HiGHS compares time_limit with
    the instance's run time summed over all its runs, so a model kept warm would otherwise
    stop every run at once after time_limit seconds in all."""
    limit = getattr(h, "run_limit_s", None)
    if limit is not None:
        h.setOptionValue("time_limit", h.getRunTime() + float(limit))


def highs_run(h) -> Status:
    """Run HiGHS on its model: its status in the package's vocabulary (HIGHS_STATUS). A stop
    (parallel.cancel) interrupts a run past INTERRUPT_AFTER_S; an undecided run while the task
    is stopping raises TaskCancelled here (interrupted, or no answer anyway)."""
    global _call_started
    _call_started = time.monotonic()
    _arm_time_limit(h)
    h.run()
    status = HIGHS_STATUS.get(h.getModelStatus().name, Status.UNDECIDED)
    if status == Status.UNDECIDED and task_stopping():
        raise TaskCancelled()
    return status


#: HiGHS runs a stop left behind (highs_run_watched): the process's exit waits for them
_left_running: list = []


@atexit.register
def _join_left_running() -> None:
    while _left_running:
        _left_running.pop().wait()


def release_left_running() -> None:
    """Do not wait at exit for the HiGHS runs a stop left behind: for an exit by os._exit,
    which ends their threads with the process (an interpreter's normal exit must wait)."""
    _left_running.clear()


def highs_run_watched(h, grace_s: float = 0.3) -> Status:
    """highs_run for a long call (the MILP, made by highs_instance(..., polled=False)): HiGHS
    runs in a thread of its own while this one polls task_stopping() every 0.1 s. HiGHS's own
    interrupt points can lie seconds apart (presolve, root heuristics), so a stop asks HiGHS to
    stop and, when it has not within grace_s, leaves its thread behind (the task is being
    dropped, the instance is never used again; a normal exit waits for HiGHS's next interrupt
    point, the command line's exit after a stop does not) and raises TaskCancelled."""
    h.HandleUserInterrupt = True
    _arm_time_limit(h)
    # highspy's solver thread locks are class attributes: while a run a stop left behind goes
    # on (cancelled, up to its next interrupt point), no instance may start one
    _join_left_running()
    h.startSolve()
    while not h.wait(0.1)[0]:
        if task_stopping():
            h.cancelSolve()
            if not h.wait(grace_s)[0]:
                _left_running.append(h)     # joined at exit: a C++ thread must end before it
            raise TaskCancelled()
    status = HIGHS_STATUS.get(h.getModelStatus().name, Status.UNDECIDED)
    if status == Status.UNDECIDED and task_stopping():
        raise TaskCancelled()
    return status


def highs_lp(A: np.ndarray, lower: np.ndarray, upper: np.ndarray, col_lower: np.ndarray,
             col_upper: np.ndarray, cost: np.ndarray | None = None, integrality: np.ndarray | None = None):
    """The HiGHS model {min cost.v : lower <= A v <= upper, col_lower <= v <= col_upper}
    (A dense (k, d), row-wise; +-inf bounds allowed; integrality (d,): 1 integer)."""
    import highspy
    inf = highspy.kHighsInf
    k, d = A.shape
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = d, k
    lp.col_cost_ = np.zeros(d) if cost is None else np.asarray(cost, float)
    lp.col_lower_, lp.col_upper_ = np.clip(col_lower, -inf, inf), np.clip(col_upper, -inf, inf)
    lp.row_lower_, lp.row_upper_ = np.clip(lower, -inf, inf), np.clip(upper, -inf, inf)
    nz = A != 0
    lp.a_matrix_.format_ = highspy.MatrixFormat.kRowwise
    lp.a_matrix_.num_col_, lp.a_matrix_.num_row_ = d, k
    lp.a_matrix_.start_ = np.concatenate([[0], np.cumsum(nz.sum(axis=1))]).astype(np.int32)
    lp.a_matrix_.index_ = np.nonzero(nz)[1].astype(np.int32)
    lp.a_matrix_.value_ = A[nz]
    if integrality is not None:
        lp.integrality_ = [highspy.HighsVarType.kInteger if i else highspy.HighsVarType.kContinuous
                           for i in integrality]
    return lp


def lp_feasible(rows: Rows, mu: float, options: dict | None = None, method: str = "simplex",
                counts: dict | None = None, deadline: float | None = None) -> tuple[Status, np.ndarray | None]:
    """Feasibility of {rows(mu) x (>=,==) 0, sum r_n = 1}: (status, x or None), by
    HiGHS (`method`, LP_METHODS: "simplex", dual simplex, which returns a vertex; "ipm";
    options: HiGHS's names), each call at most LP_TIME_LIMIT_S (then UNDECIDED), and none
    past `deadline` (time.monotonic(); None: no deadline): UNDECIDED.

    The equalities are eliminated first (x = Z y, Z = rows.Z, mu-independent and
    computed once per rows): HiGHS solves an LP of half the size without equality rows
    (plug2d m = 80, 240 x 160: 25 ms a solve against 257 ms, most of which was HiGHS's
    presolve of the equality rows). A point it returns must meet the unit x-space rows
    to X_SPACE_TOL absolutely, as the x-space LP's tolerance guarantees, with a normalisation
    share of at least NORM_SHARE_MIN or every row met to ROUNDING_RTOL |x|; one that does
    not (a huge y along a near-recession direction on which sum r_n is a tiny share of
    |y|, within tolerance of the reduced rows only) is decided by the x-space LP instead, and so
    is a problem HiGHS leaves undecided in the eliminated form (counted as "lp_x_space"; the
    dual simplex's undecided ones first by the primal simplex, PRIMAL, counted "lp_primal")."""
    A = rows.a0 + mu * rows.a1
    scale = np.linalg.norm(A, axis=1)
    live = scale > 0
    A, E = A[live] / scale[live, None], rows.eq[live]
    Z = rows.Z
    if Z is None:                        # an equality row depends on mu: eliminate at this mu
        Z = eq_null_space(A[E], A.shape[1])
    n = rows.norm @ Z
    if Z.shape[1] == 0 or np.abs(n).max() <= ZERO_ROW_RTOL * np.linalg.norm(rows.norm):
        return Status.INFEASIBLE, None   # sum r_n vanishes on the equalities' null space
    # a row nearly in the span of the equalities keeps a short reduced row: unit-scaled, so
    # that HiGHS's tolerance bounds it relative to what is left of it; rows that vanish on
    # the null space hold identically
    B = A[~E] @ Z
    bn = np.linalg.norm(B, axis=1)
    keep = bn > ZERO_ROW_RTOL
    status, y = _highs(B[keep] / bn[keep, None], n[None, :], Z.shape[1], options, method, deadline=deadline)
    if status == Status.UNDECIDED and method == "simplex" and _before(deadline):
        count(counts, "lp_primal")      # the dual simplex gave up ("Unknown"): the primal one
        status, y = _highs(B[keep] / bn[keep, None], n[None, :], Z.shape[1], {**(options or {}), **PRIMAL},
                           method, deadline=deadline)
    if status == Status.INFEASIBLE:
        return status, None
    if status == Status.FEASIBLE:
        x = Z @ y
        worst = max(np.abs(A[E] @ x).max(initial=0.0), (-(A[~E] @ x)).max(initial=0.0), abs(rows.norm @ x - 1.0))
        if point_accepted(worst, x, rows.norm):
            return status, x
    if not _before(deadline):
        return Status.UNDECIDED, None
    count(counts, "lp_x_space")
    status, x = _highs(A[~E], np.vstack([A[E], rows.norm[None, :]]), A.shape[1], options, method, watched=True,
                       deadline=deadline)
    return status, x


def _before(deadline: float | None) -> bool:
    return deadline is None or time.monotonic() < deadline


def _highs(A_ge: np.ndarray, A_eq: np.ndarray, d: int, options: dict | None,
           method: str, watched: bool = False, deadline: float | None = None) -> tuple[Status, np.ndarray | None]:
    """{A_ge v >= 0, A_eq v = e_last (the last row is the normalisation)}, v free in R^d, in at
    most LP_TIME_LIMIT_S and not past `deadline` (then UNDECIDED).
    watched: run by highs_run_watched (the x-space LP: at m = 320 a dense cold solve of ~30 s
    whose presolve has no interrupt point; a SIGTERM waited 18 s for it)."""
    limit = LP_TIME_LIMIT_S if deadline is None else min(LP_TIME_LIMIT_S, deadline - time.monotonic())
    if limit <= 0:
        return Status.UNDECIDED, None
    b_eq = np.zeros(A_eq.shape[0])
    b_eq[-1] = 1.0
    k = A_ge.shape[0]
    lower = np.concatenate([np.zeros(k), b_eq])
    upper = np.concatenate([np.full(k, np.inf), b_eq])
    h = highs_instance({**LP_METHODS[method], **(options or {})}, limit, polled=not watched)
    h.passModel(highs_lp(np.vstack([A_ge, A_eq]), lower, upper, np.full(d, -np.inf), np.full(d, np.inf)))
    status = highs_run_watched(h) if watched else highs_run(h)
    return status, np.array(h.getSolution().col_value) if status == Status.FEASIBLE else None


class TreeLp:
    """The 2D pattern LPs of one tree (a parametrisation, m nodes, 0 < mu < inf) kept warm in
    one HiGHS model over x in R^d: rows u_n,i (m), mu r_n,i + r_t,i and mu r_n,i - r_t,i
    (2m), sum r_n (1), each unit-scaled. A pattern is row bounds only: u_n,i = 0 (contact)
    or >= 0; a gap node's two friction rows = 0 (r_n,i = r_t,i = 0, as mu > 0), else >= 0;
    sum r_n = 1. `solve` changes the bounds the pattern changes and re-solves by the dual
    simplex (no presolve, LP_OPTIONS' tolerances and time limit) from the root pattern's
    final basis, always the same one: a node's answer and point depend on the node alone,
    not on the nodes solved before it, so a tree split into tasks in any way (or resumed)
    finds the same points, counts and patterns. chain=True (a dive that one process runs
    from its start: global_search's bracket dives): each solve starts where the last one
    ended, after a checked answer (block2d m = 320 at depth: 0.08 s a node against 0.57 s);
    the points then depend on the nodes solved before.

    An answer is taken only with its proof checked here: a point meeting every row to
    X_SPACE_TOL with a normalisation share (lp_feasible) of at least NORM_SHARE_MIN (or every
    row met to ROUNDING_RTOL |x|, as pattern_lp.point_holds); an
    infeasibility by HiGHS's dual ray y (a Farkas certificate: y >= 0 on the inequality
    rows, y_norm > 0 (y . bounds), |A^T y|_1 <= FARKAS_RTOL y_norm: no x with
    |x|_inf < 1 / FARKAS_RTOL meets the rows). Anything else is UNDECIDED:
    the caller decides the pattern by `lp_feasible` (counted "warm_unsure")."""

    FARKAS_RTOL = FARKAS_RTOL

    def __init__(self, param: Parametrization, m: int, mu: float, chain: bool = False):
        if not 0.0 < mu < np.inf:
            raise ValueError(f"TreeLp: 0 < mu < inf, got {mu}")
        self.chain, self._restart = chain, True
        Un, (Rn, Rt) = blocks(param.U, m, 2)[0], blocks(param.R, m, 2)
        A = np.vstack([Un, mu * Rn + Rt, mu * Rn - Rt])
        A = A / np.maximum(np.linalg.norm(A, axis=1, keepdims=True), 1e-300)
        self.A, self.norm, self.m = np.vstack([A, Rn.sum(axis=0)]), Rn.sum(axis=0), m
        self.upper = np.concatenate([np.full(3 * m, np.inf), [1.0]])
        self._h = self._start = None

    def __getstate__(self):             # a tree sent to another rank takes no live HiGHS along
        return {**self.__dict__, "_h": None, "_start": None, "_restart": True}   # rebuilt on the next solve

    def _highs(self):
        if self._h is None:
            lower = np.concatenate([np.zeros(3 * self.m), [1.0]])
            d = self.A.shape[1]
            self.upper = np.concatenate([np.full(3 * self.m, np.inf), [1.0]])    # the root pattern's
            self._h = highs_instance({**LP_METHODS["simplex"], **LP_OPTIONS, "presolve": "off"}, LP_TIME_LIMIT_S)
            self._h.passModel(highs_lp(self.A, lower, self.upper, np.full(d, -np.inf), np.full(d, np.inf)))
            highs_run(self._h)              # the root pattern (every node free): its final basis starts every solve
            self._start = self._h.getBasis()
        return self._h

    def solve(self, zero_u: np.ndarray, zero_r: np.ndarray,
              counts: dict | None = None) -> tuple[Status, np.ndarray | None]:
        """The pattern (zero_u, zero_r) (m,): (status, x normalised to sum r_n = 1 or None);
        UNDECIDED: no proof checked (class doc)."""
        h = self._highs()
        upper = np.concatenate([np.where(zero_u, 0.0, np.inf), np.tile(np.where(zero_r, 0.0, np.inf), 2), [1.0]])
        changed = np.flatnonzero(upper != self.upper).astype(np.int32)
        if changed.size:
            import highspy
            h.changeRowsBounds(changed.size, changed, np.zeros(changed.size),
                               np.clip(upper[changed], 0.0, highspy.kHighsInf))
            self.upper = upper
        if self._restart or not self.chain:
            h.clearSolver()             # no simplex state of earlier solves (edge weights, perturbations)
            h.setBasis(self._start)
        status = highs_run(h)
        self._restart = True
        if status == Status.FEASIBLE:
            x = np.array(h.getSolution().col_value)
            if self._point_holds(x):
                count(counts, "warm_feasible")
                self._restart = False
                return status, x
        elif status == Status.INFEASIBLE and self._ray_holds(h):
            count(counts, "warm_infeasible")
            self._restart = False
            return status, None
        count(counts, "warm_unsure")
        return Status.UNDECIDED, None

    def _point_holds(self, x: np.ndarray) -> bool:
        v = self.A @ x
        eq = self.upper == 0.0
        worst = max(np.abs(v[eq]).max(initial=0.0), (-v[:-1][~eq[:-1]]).max(initial=0.0), abs(v[-1] - 1.0))
        return point_accepted(worst, x, self.norm)

    def _ray_holds(self, h) -> bool:
        """HiGHS's dual ray, either sign, proves {rows} empty (class doc)."""
        return farkas_holds(h, self.A, np.concatenate([self.upper[:-1] != 0.0, [False]]), FARKAS_RTOL)


def farkas_holds(h, A: np.ndarray, ge: np.ndarray, rtol: float) -> bool:
    """HiGHS's dual ray y of the model {A v (>= 0 where ge, == 0 elsewhere), last row = 1},
    either sign, proves it empty: z >= 0 on the rows ge (a negative entry zeroed: still a valid
    combination), z_last > 0 and |A^T z|_1 <= rtol z_last, so no v with |v|_inf < 1 / rtol
    meets the rows."""
    _, has, y = h.getDualRay()
    if not has:
        return False
    y = np.asarray(y, float)
    for sign in (1.0, -1.0):
        z = sign * y
        z[ge] = np.maximum(z[ge], 0.0)
        if z[-1] > 0 and np.abs(A.T @ z).sum() <= rtol * z[-1]:
            return True
    return False


def image_point(E: np.ndarray, G: np.ndarray, rank_rtol: float = 1e-9) -> np.ndarray | None:
    """A point x of {E x = 0, G x >= 0, sum G x = 1} (E (e, d), G (g, d)) found in the image
    coordinates b = G x: (0, b) must lie in the range of M = [E; G], i.e. N^T (0, b) = 0 for a
    basis N of M's left null space (singular values below rank_rtol times the largest) — an LP
    in b >= 0 with only those rows and sum b = 1, where M is nearly square (the all-contact
    pattern without friction: [U_n; R_n], m = 160: 1 row, against a dense 320 x 320 LP). Its
    vertex is solved again on its support in double precision; x = M^+ (0, b), the least-norm
    preimage; None: HiGHS found no point. The caller checks x against its rows (`point_holds`)."""
    M = np.vstack([E, G])
    # numpy's SVD through dense_call: a signal is served during it (m = 1,280: ~7 s)
    U, sv, Vt = dense_call(np.linalg.svd, M, full_matrices=True)
    r = int((sv > rank_rtol * sv[0]).sum()) if sv.size else 0
    N = U[:, r:]                               # left null space (2m - r columns)
    Nb, k, g = N[E.shape[0]:], N.shape[1], G.shape[0]
    A = np.vstack([Nb.T, np.ones((1, g))])
    h = highs_instance({**LP_METHODS["simplex"], **LP_OPTIONS}, LP_TIME_LIMIT_S)
    h.passModel(highs_lp(A, np.concatenate([np.zeros(k), [1.0]]), np.concatenate([np.zeros(k), [1.0]]),
                         np.zeros(g), np.full(g, np.inf)))
    if highs_run(h) != Status.FEASIBLE:
        return None
    b = np.maximum(np.array(h.getSolution().col_value), 0.0)
    S = np.flatnonzero(b > 0)
    if S.size == k + 1:                        # a vertex: its support solved exactly
        with np.errstate(all="ignore"):
            try:
                bs = np.linalg.solve(A[:, S], np.concatenate([np.zeros(k), [1.0]]))
            except np.linalg.LinAlgError:
                bs = None
        if bs is not None and np.all(bs >= 0):
            b = np.zeros(g)
            b[S] = bs
    v = np.concatenate([np.zeros(E.shape[0]), b])
    return Vt[:r].T @ ((U[:, :r].T @ v) / sv[:r])


def lp_violation(rows: Rows, mu: float, x: np.ndarray) -> float:
    """Largest violation of the LP pattern problem at x: |a.x| of the equalities and
    max(0, -a.x) of the inequalities, on the rows at mu scaled to unit norm, relative to
    ||x||. A HiGHS point of a feasible problem meets its rows to its tolerance
    (LP_OPTIONS); a larger violation than rounding means feasible only to that tolerance."""
    A = rows.a0 + mu * rows.a1
    scale = np.linalg.norm(A, axis=1)
    live = scale > 0
    v = (A[live] @ x) / (scale[live] * max(np.linalg.norm(x), 1e-300))
    eq = rows.eq[live]
    return float(max(np.abs(v[eq]).max(initial=0.0), (-v[~eq]).max(initial=0.0)))



@contextlib.contextmanager
def stdout_silenced():
    """File descriptor 1 to /dev/null for the block: HiGHS prints its banner and some debug
    lines ("HighsMipSolverData::transformNewIntegerFeasibleSolution ...") with printf, past
    its output_flag, and stdout carries `hpcwedge run --json`. C's stdio buffer is flushed
    before fd 1 comes back, so nothing of it reaches the real stdout later."""
    import ctypes
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
        yield
    finally:
        try:
            ctypes.CDLL(None).fflush(None)
        except (OSError, AttributeError):
            pass
        os.dup2(saved, 1)
        os.close(saved)
