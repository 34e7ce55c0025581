"""The LP of one pattern problem at any mu, kept warm in one HiGHS model (`PatternLp`): the
2D mu^c computations (mu_c/bracket.py) solve the same pattern at many mu.

Besides feasibility, the model answers the largest margin t of the mu-rows at mu (max t with
(a0 + mu a1) . x >= t w on them, w > 0): a point of positive margin is feasible at its own ratio
mu(x) = max over the mu-rows of -a0.x / a1.x < mu, the step of a generalised Dinkelbach
iteration (`dinkelbach_hi` in bracket.py).
"""
from __future__ import annotations

import numpy as np

from hpcwedge.dense import dense_call
from hpcwedge.solvers.lp import (
    FARKAS_RTOL,
    LP_METHODS,
    LP_OPTIONS,
    LP_TIME_LIMIT_S,
    NORM_SHARE_MIN,
    farkas_holds,
    highs_instance,
    highs_lp,
    highs_run,
    point_accepted,
)
from hpcwedge.solvers.rows import ZERO_ROW_RTOL, Rows, Status, count


class PatternLp:
    """The LP of one pattern problem (`Rows` whose equalities do not depend on mu) at any
    0 < mu < inf, kept warm in one HiGHS model: a change of mu changes one coefficient per
    mu-row and re-solves by the dual simplex from the last basis (no presolve, LP_OPTIONS'
    tolerances, LP_TIME_LIMIT_S). The model is lp_feasible's eliminated LP (x = Z y) with
    each distinct a1 Z y as a variable w and the margin t: a row reads
    (a0 Z y + mu |a1 Z| w) / s - t / s >= 0 (s: its norm at the first mu solved; t on the
    mu-rows only, fixed at 0 but in `margin`), w = a1 Z y / |a1 Z|, n . y = 1 last. Its
    answers depend on the sequence of calls (one mu^c computation: fixed by the pattern),
    never on other patterns.

    A feasibility answer is taken only with its proof checked here: a point x = Z y passing
    lp_feasible's checks (`point_holds`), or a dual ray proving the model empty
    (lp.farkas_holds, `ray_rtol`). Anything else is UNDECIDED: the caller decides by
    `feasibility.decide` (counted "pattern_lp_unsure")."""

    def __init__(self, rows: Rows):
        if rows.Z is None:
            raise ValueError("PatternLp: the equality rows depend on mu")
        self.rows, Z = rows, rows.Z
        B0, B1 = dense_call(np.matmul, rows.a0[~rows.eq], Z), dense_call(np.matmul, rows.a1[~rows.eq], Z)
        # rows that vanish on the equalities' null space hold identically
        keep = np.linalg.norm(B0, axis=1) + np.linalg.norm(B1, axis=1) > ZERO_ROW_RTOL
        self.B0, self.B1 = B0[keep], B1[keep]
        self.n = rows.norm @ Z
        s1 = np.linalg.norm(self.B1, axis=1)
        self.mu_rows = np.flatnonzero(s1 > ZERO_ROW_RTOL * max(s1.max(initial=0.0), 1e-300))
        W, self.w_of = np.unique(self.B1[self.mu_rows], axis=0, return_inverse=True)
        self.W = W / np.linalg.norm(W, axis=1, keepdims=True)
        self.s1 = s1[self.mu_rows]
        self._h = self._scale = self._mu = None
        #: a dual ray is accepted when it proves no point of |v|_inf below 10 times the
        #: largest norm of a point lp_feasible accepts (share >= NORM_SHARE_MIN): near mu^c a
        #: ray's y_norm shrinks with the distance to it (plug2d m = 160, 2e-3 below mu^c:
        #: |A^T y|_1 / y_norm = 3e-9, rounding of y ~ 1 alone), FARKAS_RTOL fails there
        x_max = np.sqrt(rows.a0.shape[1]) / (NORM_SHARE_MIN * max(np.linalg.norm(rows.norm), 1e-300))
        self.ray_rtol = max(FARKAS_RTOL, 0.1 / x_max)

    def _model(self, mu: float):
        import highspy
        k, p = self.B0.shape
        q = self.W.shape[0]
        floor = ZERO_ROW_RTOL * (np.linalg.norm(self.B0, axis=1) + mu * np.linalg.norm(self.B1, axis=1))
        self._scale = np.maximum(np.linalg.norm(self.B0 + mu * self.B1, axis=1), floor)
        A = np.zeros((k + q + 1, p + q + 1))
        A[:k, :p] = self.B0 / self._scale[:, None]
        A[k:k + q, :p], A[k:k + q, p:p + q] = self.W, -np.eye(q)
        A[-1, :p] = self.n
        A[self.mu_rows, p + self.w_of] = self._coefficients(mu)
        A[self.mu_rows, -1] = -1.0 / self._scale[self.mu_rows]
        lower = np.concatenate([np.zeros(k + q), [1.0]])
        upper = np.concatenate([np.full(k, highspy.kHighsInf), np.zeros(q), [1.0]])
        h = highs_instance({**LP_METHODS["simplex"], **LP_OPTIONS, "presolve": "off"}, LP_TIME_LIMIT_S)
        h.passModel(highs_lp(A, lower, upper, np.concatenate([np.full(p + q, -np.inf), [0.0]]),
                             np.concatenate([np.full(p + q, np.inf), [0.0]])))
        self._h, self._A, self._mu = h, A, mu
        return h

    def _coefficients(self, mu: float) -> np.ndarray:
        return mu * self.s1 / self._scale[self.mu_rows]

    def _at(self, mu: float):
        """The model with its mu-rows at mu (0 < mu < inf)."""
        if not 0.0 < mu < np.inf:
            raise ValueError(f"PatternLp: 0 < mu < inf, got {mu}")
        h = self._h if self._h is not None else self._model(mu)
        if mu != self._mu:
            p = self.B0.shape[1]
            c = self._coefficients(mu)
            for row, col, v in zip(self.mu_rows, p + self.w_of, c):
                h.changeCoeff(int(row), int(col), float(v))
            self._A[self.mu_rows, p + self.w_of] = c
            self._mu = mu
        return h

    def _x(self, h) -> np.ndarray:
        return self.rows.Z @ np.array(h.getSolution().col_value)[:self.B0.shape[1]]

    def solve(self, mu: float, counts: dict | None = None) -> tuple[Status, np.ndarray | None]:
        """Feasibility at mu (0 < mu < inf): (status, x or None) as lp_feasible's; UNDECIDED:
        no proof checked (class doc)."""
        h = self._at(mu)
        status = highs_run(h)
        if status == Status.FEASIBLE:
            x = self._x(h)
            if point_holds(self.rows, mu, x):
                count(counts, "pattern_lp_feasible")
                return status, x
        elif status == Status.INFEASIBLE:
            ge = np.zeros(self._A.shape[0], bool)
            ge[:self.B0.shape[0]] = True
            if farkas_holds(h, self._A[:, :-1], ge, self.ray_rtol) or self.ray_proves_empty(h.getDualRay()[2]):
                count(counts, "pattern_lp_infeasible")
                return status, None
        count(counts, "pattern_lp_unsure")
        return Status.UNDECIDED, None

    def ray_proves_empty(self, y) -> bool:
        """A dual ray y of the model at its current mu (t fixed at 0), HiGHS's or any (k + q + 1,)
        vector, proves it empty in x-space: z = y, then y projected on the null space of the
        transposed rows of its support (the exact ray of HiGHS's basis: its residual is rounding,
        HiGHS's is ~1e-10), either with z's rows >= 0 clipped at 0, z_last > 0 and
        |g_y + W^T g_w|_2 <= ray_rtol z_last for g = A^T z. Any point of the rows has w = W y,
        so z_last <= g . v = (g_y + W^T g_w) . y <= |..|_2 |x|_2 (Z orthonormal): no point with
        |x|_2 below 10 times the largest lp_feasible accepts (rounding of g: far below the 10)."""
        y = np.asarray(y, float)
        if y.size != self._A.shape[0] or y[-1] == 0.0:
            return False
        y = y if y[-1] > 0 else -y
        A, (k, p) = self._A[:, :-1], self.B0.shape
        for z in (y, _null_projection(A, y)):
            if z is None:
                continue
            z[:k] = np.maximum(z[:k], 0.0)
            g = A.T @ z
            if z[-1] > 0 and np.linalg.norm(g[:p] + self.W.T @ g[p:]) <= self.ray_rtol * z[-1]:
                return True
        return False

    def margin(self, mu: float, weight: np.ndarray | None = None) -> tuple[float, np.ndarray] | None:
        """(t, x): a point x of the rows with sum r_n = 1 of largest margin t on the mu-rows
        at mu, (a0 + mu a1) . x >= t a1 . weight (weight: a point (d,), e.g. the last one;
        None: (a0 + mu a1) . x >= t), unchecked (the caller checks x where it uses it); None:
        HiGHS found no optimum. The model goes back to feasibility (t = 0) after."""
        import highspy
        h = self._at(mu)
        t = self._A.shape[1] - 1
        c = -np.ones(self.mu_rows.size) if weight is None else -(self.B1[self.mu_rows] @ (self.rows.Z.T @ weight))
        c = c / self._scale[self.mu_rows]
        for row, v in zip(self.mu_rows, c):
            h.changeCoeff(int(row), t, float(v))
        self._A[self.mu_rows, t] = c
        h.changeColBounds(t, -highspy.kHighsInf, highspy.kHighsInf)
        h.changeColCost(t, -1.0)
        try:
            status = highs_run(h)
            sol = np.array(h.getSolution().col_value) if status == Status.FEASIBLE else None
        finally:
            h.changeColCost(t, 0.0)
            h.changeColBounds(t, 0.0, 0.0)
        return None if sol is None else (float(sol[-1]), self.rows.Z @ sol[:self.B0.shape[1]])


def _null_projection(A: np.ndarray, y: np.ndarray) -> np.ndarray | None:
    """y (rows of A,) projected on the null space of A_S^T, S the support of y (|y_i| above
    1e-13 max|y|), by a full QR of A_S; None when A_S has no more rows than columns."""
    S = np.flatnonzero(np.abs(y) > 1e-13 * np.abs(y).max())
    if S.size <= A.shape[1]:
        return None
    Q = dense_call(np.linalg.qr, A[S], mode="complete")[0]
    N = Q[:, A.shape[1]:]
    z = np.zeros_like(y)
    z[S] = N @ (N.T @ y[S])
    return z


def point_holds(rows: Rows, mu: float, x: np.ndarray) -> bool:
    """Whether x meets `rows` at mu (its unit rows and sum r_n = 1) by lp.point_accepted,
    the rule of every LP route."""
    A = rows.a0 + mu * rows.a1
    scale = np.linalg.norm(A, axis=1)
    live = scale > 0
    v, eq = (A[live] @ x) / scale[live], rows.eq[live]
    worst = max(np.abs(v[eq]).max(initial=0.0), (-v[~eq]).max(initial=0.0), abs(rows.norm @ x - 1.0))
    return point_accepted(worst, x, rows.norm)


def ratio(rows: Rows, x: np.ndarray) -> float:
    """The least mu at which x meets the mu-rows (a1 != 0, inequalities): max over them of
    -a0.x / a1.x (0 when every one holds at mu = 0; inf when one with a1.x <= 0 fails). Values
    within 1e-12 of the row's norm times |x| count as 0 (rounding: a row with a1.x = 0)."""
    rowsel = ~rows.eq & np.any(rows.a1 != 0, axis=1)
    a0, a1 = rows.a0[rowsel], rows.a1[rowsel]
    a0x, a1x = a0 @ x, a1 @ x
    tiny = 1e-12 * (np.linalg.norm(a0, axis=1) + np.linalg.norm(a1, axis=1)) * np.linalg.norm(x)
    if np.any((a1x <= tiny) & (a0x < -tiny)):
        return np.inf
    pos = a1x > tiny
    return float(max(0.0, (-a0x[pos] / a1x[pos]).max(initial=0.0)))
