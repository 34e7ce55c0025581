"""The pattern SOCP for Clarabel: its two forms, the retry ladder of attempts, and the
checks of what Clarabel returns (a point's violation, a Farkas certificate). One solve,
its settings and the problem form are conic.py's.

The pattern SOCP (rows.ConeRows) is a `ConicProblem` built twice: in reaction coordinates
for the first attempt (`reaction_socp`, sparse), in the null space of its equalities for
the retries (`pattern_socp`); Dinkelbach's steps (dinkelbach.py) and the signed KKT
multipliers (kkt.py) are others. The ladder (`attempts`): attempt k is one `solve` with
`settings(k, ...)` (conic.py's module doc); the caller stops it when satisfied.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from typing import Callable, Iterator

import numpy as np

from hpcwedge.contact.problem import ReactionCoordinates, kept_on
from hpcwedge.solvers.conic import ATTEMPTS, LEAST_NORM_ATTEMPT, ConicProblem, DenseDiag, Solution, rmatvec, solve
from hpcwedge.solvers.rows import ZERO_ROW_RTOL, ConeRows, Status, kept_sizes

#: a returned x is feasible when every row holds to VERIFY_TOL * ||x|| (the order of
#: Clarabel's own feasibility tolerance: an optimum on the boundary misses by 1e-9..3e-9;
#: 2D: HiGHS's primal feasibility tolerance is 1e-7)
VERIFY_TOL = 1e-8
#: an infeasibility certificate z holds when ||A^T z|| and the dual-cone violation are
#: <= CERT_TOL * |b^T z| (b^T z < 0 strictly)
CERT_TOL = 1e-7
#: the reaction form poses a friction cone in (r_n, r_t / mu) below this mu, and in
#: (mu r_n, r_t) from it on (reaction_socp)
BALANCE_MU = 0.05
#: the reaction form takes the rigid amplitudes through the orthonormal columns of their u_n
#: block when its singular values spread wider than this (_reaction_layout)
WHITEN_COND = 1e3


def violation(rows: ConeRows, mu: float, x: np.ndarray) -> float:
    """Largest violation of the pattern problem at x (unit rows; each cone's rows
    scaled together), x first scaled to sum r_n = 1 (sum r_n <= 0: inf).
    Equalities and u_n rows are measured relative to ||x||; the friction cones
    relative to the size of the reactions, ||(r_n, r_t)|| over the cone nodes —
    not to ||x||, which a rigid lift-off (r = 0, u_n > 0) can make arbitrarily
    large without changing any reaction."""
    x = _normalised(rows, x)
    return math.inf if x is None else _violation(rows, mu, x)


def verified(rows: ConeRows, mu: float, x: np.ndarray, tol: float = VERIFY_TOL) -> np.ndarray | None:
    """x scaled to sum r_n = 1 when its `violation` is <= tol, else None."""
    x = _normalised(rows, x)
    return x if x is not None and _violation(rows, mu, x) <= tol else None


def _normalised(rows: ConeRows, x: np.ndarray) -> np.ndarray | None:
    """x / sum r_n (None: sum r_n <= 0 or not finite)."""
    nr = float(rows.norm @ x)
    return x / nr if math.isfinite(nr) and nr > 0 else None


def _violation(rows: ConeRows, mu: float, x: np.ndarray) -> float:
    """`violation` at an x with sum r_n = 1."""
    size = max(math.sqrt(x @ x), 1e-300)
    eq, lin, cone = rows.at(x)
    v = 0.0
    if eq.size:
        v = max(v, float(np.abs(eq).max()) / size)
    if lin.size:
        v = max(v, -float(lin.min()) / size)
    if cone.size:
        c2 = cone * cone
        rt = np.sqrt(c2[1] + c2[2])
        rsize = max(math.sqrt(float(c2.sum())), 1e-300)
        v = max(v, float((rt - mu * cone[0]).max()) / (max(mu, 1.0) * rsize))
    return v


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
    cones]; w = (the cone nodes' (r_n, r_t1 / g, r_t2 / g) on `cols`, beta' with beta =
    beta_map beta', None: beta itself). lin_nodes / lin_scale: the node of each lin row
    and the norm it was scaled by."""

    problem: ConicProblem
    rows: ConeRows
    cols: np.ndarray
    lin_nodes: np.ndarray
    lin_scale: np.ndarray
    g: float
    beta_map: np.ndarray | None
    #: the rows of `problem` after sum r_n = 1, as rows of the layout's [E; U_n]: row
    #: `order[j]` divided by `row_scale[j]` (negative: a lin row, -u_n)
    order: np.ndarray | None = None
    row_scale: np.ndarray | None = None
    mu: float = 0.0

    def _unscaled(self, v: np.ndarray) -> np.ndarray:
        """v (one entry per column of `cols`) with its tangential entries times g."""
        if self.g != 1.0:
            v = v.copy()
            v.reshape(-1, 3)[:, 1:] *= self.g
        return v

    def to_x(self, w: np.ndarray) -> np.ndarray:
        """The x-space point of w."""
        form, k = self.rows.reactions, len(self.cols)
        r = np.zeros(form.B.shape[0])
        r[self.cols] = self._unscaled(w[:k])
        beta = w[k:] if self.beta_map is None else self.beta_map @ w[k:]
        return form.to_x(r, beta)

    def objective(self, c: np.ndarray) -> np.ndarray:
        """q with q . w = c . x (c x-space)."""
        B = self.rows.reactions.B
        c = self.rows.reactions.pullback(c)
        c_beta = c[B.shape[1]:] if self.beta_map is None else self.beta_map.T @ c[B.shape[1]:]
        return np.concatenate([self._unscaled((B @ c[:B.shape[1]])[self.cols]), c_beta])

    def farkas(self, z: np.ndarray) -> np.ndarray | None:
        """A certificate z of this problem in the layout of `pattern_socp` (the same
        multipliers, rescaled to its rows), or None when the two keep other lin rows."""
        rows, p = self.rows, self.problem
        if not np.array_equal(self.lin_nodes, rows.lin_nodes):
            return None
        lin = z[p.n_zero:p.n_zero + p.n_lin] * rows.lin_scale / self.lin_scale
        # this problem's cone rows are (mu r_n, r_t) / g
        cones = (z[p.n_zero + p.n_lin:].reshape(-1, 3) * (rows.scale[:, None] / self.g)).ravel()
        return np.concatenate([z[:1], lin, cones])


def farkas_decisions(first: ReactionSOCP, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The decisions a Farkas certificate z of first.problem rests on: (contact, gap) masks
    (m,), subsets of the pattern's zero_u and zero_r. The same multipliers prove every
    pattern infeasible that keeps these decisions, whatever it does with the other nodes:
    a contact node left out has its u_n row's multiplier y_i <= 0 (that of a lin row,
    -u_n >= 0, of the same functional), a gap node left out has the functional h_i that the
    rows' multipliers put on its reactions w_i (columns as in `problem`) in the dual of its
    friction cone, h_n >= mu' ||h_t|| (a cone multiplier (h_n / mu', h_t) cancels it). The
    residual A^T z on the columns both patterns keep is the same; the inequalities are
    checked without a margin (a decision on the boundary is kept)."""
    lay = _reaction_layout(first.rows.reactions, first.rows.zero_u.shape[0])
    z = z / -z[0]                                # b = e_0: b^T z = -1
    y = np.zeros(lay.rest.shape[0])
    y[first.order] = z[1:1 + first.order.size] / first.row_scale
    h = lay.rest.T @ y
    h[lay.cols[:, 0]] += z[0]
    h = h[lay.cols]                              # (m, 3), tangential columns as posed: r_t / g
    if first.g != 1.0:
        h[:, 1:] *= first.g
    k = lay.equilibrium.size
    contact = first.rows.zero_u & (y[k:] > 0)
    gap = first.rows.zero_r & ~(h[:, 0] >= first.mu * np.hypot(h[:, 1], h[:, 2]))
    return contact, gap


def reaction_socp(rows: ConeRows, mu: float) -> ReactionSOCP:
    """The pattern SOCP at mu in x' = (r, beta) (problem.ReactionCoordinates): the gap
    nodes' reactions dropped, every cone a coordinate cone (one entry per row), the
    u_n rows and equilibrium dense: a KKT system a third the work of `pattern_socp`'s
    dense null-space form (plug3d 3 x 6: Clarabel 0.64 against 1.13 ms per SOCP, the same
    answers on all 6,791 of the enumeration's SOCPs), and no SVD. Dense rows unit-scaled,
    rows that vanish on the kept columns dropped (as rows.kept_rows does).

    Balanced where the scales are far apart: below BALANCE_MU each friction cone is posed
    in (r_n, r_t / mu), of the size of r_n, and where the u_n block of the rigid amplitudes
    is ill-conditioned (WHITEN_COND) they enter through its orthonormal columns. A small
    taper does both: r_t ~ mu r_n, and plug3d's axial translation moves u_n by ~taper^2
    (that block's singular values 0.30 .. 0.012 at 10 deg, .. 1.2e-6 at 0.1 deg). There the
    plain form left first attempts non-definitive (plug3d 3 x 6 at 0.1 deg, mu = 1.5
    tan(taper): 339 of 719 tree SOCPs, 593 pyramid LPs, 21 s; balanced: none, 0.4 s). Not
    everywhere: at mu = 0.18 (the global search of plug3d 3 x 6 at 10 deg) r_t / mu left 100
    of the settling tree's 657 first attempts AlmostSolved (4 without it), and at 10 deg the
    two changes, which leave the interior-point path the same in exact arithmetic, only
    moved the branching (plug3d 4 x 6 at mu = 0.65: 67,311 tree SOCPs against 60,187).
    """
    lay = _reaction_layout(rows.reactions, rows.zero_u.shape[0])
    nodes = rows.nodes
    g = float(mu) if 0.0 < mu < BALANCE_MU else 1.0
    cols, rest, size, kept = _gap_columns(lay, rows.zero_r.tobytes(), g)
    is_eq = np.concatenate([lay.equilibrium, rows.zero_u])
    eq = (kept & is_eq).nonzero()[0]
    lin = (kept & ~is_eq).nonzero()[0]
    order = np.concatenate([eq, lin])
    scale = size[order]
    scale[len(eq):] *= -1.0                     # a lin row is -u_n: s = -A w = u_n >= 0
    A = DenseDiag.of(rest.T[:, order] / scale, 3 * len(nodes), mu / g)
    b = np.zeros(A.shape[0])
    b[0] = 1.0
    problem = ConicProblem(A, b, 1 + len(eq), len(lin), len(nodes))
    return ReactionSOCP(problem, rows, cols, lin - lay.equilibrium.size, size[lin], g, lay.beta_map,
                        order, scale, mu / g)


@functools.lru_cache(maxsize=64)
def _gap_columns(lay: _ReactionLayout, zero_r: bytes, g: float) -> tuple[np.ndarray, ...]:
    """What `reaction_socp` cuts from `lay` for the gap set zero_r (the bytes of its mask;
    shared by a node and its contact children, kept for the next few nodes) at the
    tangential scale g: the columns of the cone nodes' reactions, the rows [equilibrium;
    u_n of every node] on those (tangential columns times g) and the rigid amplitudes'
    columns (`rest`), each row's norm and whether it is kept (read-only)."""
    nodes = (~np.frombuffer(zero_r, bool)).nonzero()[0]
    cols = lay.cols[nodes].ravel()
    rest = lay.rest.take(np.concatenate([cols, lay.beta]), axis=1)
    if g != 1.0:
        rest[:, 3 * np.arange(len(nodes))[:, None] + np.array([1, 2])] *= g
    size = np.sqrt(np.einsum("ij,ij->i", rest, rest))
    out = (cols, rest, size, kept_sizes(size))
    for a in out:
        a.flags.writeable = False
    return out


@dataclass(frozen=True, eq=False)
class _ReactionLayout:
    """What `reaction_socp` cuts every pattern's problem from (one per parametrisation and
    m): rest [E 0; U_n] (E rows + m, n + n_beta); cols (m, 3) the columns of each node's
    (r_n, r_t1, r_t2); beta the rigid amplitudes' columns, in the basis beta = beta_map beta'
    (None: beta itself; else one in which their U_n block is orthonormal: reaction_socp's doc);
    equilibrium: True per E row."""

    rest: np.ndarray
    cols: np.ndarray
    beta: np.ndarray
    equilibrium: np.ndarray
    beta_map: np.ndarray | None


def beta_whitening(form: ReactionCoordinates, m: int) -> np.ndarray | None:
    """The map W (nb, nb) of the reaction form's rigid amplitudes, beta = W beta', under which
    the u_n block's beta columns are orthonormal (WHITEN_COND); None: kept as they are."""
    return _reaction_layout(form, m).beta_map


def _reaction_layout(form: ReactionCoordinates, m: int) -> _ReactionLayout:
    """_ReactionLayout of (form, m), computed once (kept on `form`)."""
    def build() -> _ReactionLayout:
        k, n = form.E.shape
        rest = np.zeros((k + m, form.U.shape[1]))
        rest[:k, :n] = form.E
        rest[k:] = form.U[:m]
        beta_map = None
        if n < form.U.shape[1]:
            # E has no beta entries: the U_n block V diag(sv) W^T -> V (sv clipped, so that
            # an amplitude that moves no u_n keeps its small column instead of a huge map)
            _, sv, Wt = np.linalg.svd(rest[k:, n:])
            sv = np.concatenate([sv, np.zeros(Wt.shape[0] - sv.size)])
            if sv[0] > WHITEN_COND * sv[-1]:
                beta_map = Wt.T / np.maximum(sv, ZERO_ROW_RTOL * max(sv[0], 1e-300))
                rest[k:, n:] = rest[k:, n:] @ beta_map
        return _ReactionLayout(rest, np.arange(3 * m).reshape(3, m).T.copy(),
                               np.arange(n, form.U.shape[1]), np.ones(k, bool), beta_map)
    return kept_on(form, f"_reaction_layout_{m}", build)


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
    """One attempt at the pattern SOCP, read: status (conic.CLARABEL_STATUS) and name
    (Clarabel's, the stats' key); x: the point (x-space, FEASIBLE); certified: whether the
    certificate passed `certificate_ok` (INFEASIBLE), `farkas` that certificate with its
    rows laid out as in `pattern_socp` (computed when asked: z and its `layout`); positive:
    FEASIBLE with an objective whose verified dual proves it > 0 on the feasible set."""

    attempt: int
    status: Status
    name: str
    x: np.ndarray | None = None
    certified: bool | None = None
    positive: bool = False
    z: np.ndarray | None = None
    layout: Callable[[np.ndarray], np.ndarray | None] | None = None

    @property
    def farkas(self) -> np.ndarray | None:
        return self.layout(self.z) if self.certified else None


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
    if sol.status == Status.FEASIBLE:
        positive = False
        if steered is not None:
            # the optimal dual z (A^T z + q = 0, z in K*) with b^T z < 0 is a Farkas
            # certificate of {A w + s = b, q . w = 0}: check it like any other
            positive = certificate_ok(plain.A, plain.b, sol.z, plain.n_zero, plain.n_lin, q=steered.q)
        return Outcome(attempt, sol.status, sol.name, x=to_x(sol.x), positive=positive)
    if sol.status == Status.INFEASIBLE:
        certified = certificate_ok(plain.A, plain.b, sol.z, plain.n_zero, plain.n_lin)
        return Outcome(attempt, sol.status, sol.name, certified=certified, z=sol.z, layout=farkas)
    return Outcome(attempt, sol.status, sol.name)


def certificate_ok(A, b, z, n_zero, n_lin, q: np.ndarray | None = None) -> bool:
    """Farkas check of {A w + s = b, s in K} infeasible, rows laid out [zero cone
    (n_zero) | nonnegative (n_lin) | second-order cones of size 3]: with z scaled to
    b^T z = -1, ||A^T z||_inf and z's distance from the dual cone (K* = K here; free
    on the zero cone) must be <= CERT_TOL, i.e. no point w with ||w||_1 below about
    1 / CERT_TOL is feasible. q: the check of {q . w = 0, A w + s = b} instead, the
    multiplier of the extra row 1 (an optimal dual z of min q . w over the set, for
    which A^T z + q = 0)."""
    bz = float(b @ z)
    if not math.isfinite(bz) or bz >= 0:
        return False
    z = z / -bz
    ATz = rmatvec(A, z)
    if q is not None:
        ATz += q / -bz
    if np.abs(ATz).max() > CERT_TOL:
        return False
    if n_lin and z[n_zero:n_zero + n_lin].min() < -CERT_TOL:
        return False
    zc = z[n_zero + n_lin:].reshape(-1, 3)
    if len(zc):
        c2 = zc * zc
        if (np.sqrt(c2[:, 1] + c2[:, 2]) - zc[:, 0]).max() > CERT_TOL:
            return False
    return True
