"""LP feasibility of a pattern problem (`rows.Rows`) by HiGHS (scipy.optimize.linprog),
and the violation of a point of it.

2D patterns are LPs, and so are the 3D pyramid fallbacks (rows.pyramid_rows). HiGHS's
dual simplex returns a vertex: the polish of mu^c (mu_bracket.py) needs its active set.
"""
from __future__ import annotations

import numpy as np

from hpcwedge.solvers.rows import ZERO_ROW_RTOL, Rows, Status, count, eq_null_space

#: HiGHS options of the pattern LPs (2D) and the pyramid LPs (3D fallback); None given to
#: `lp_feasible`: HiGHS's defaults (feasibility tolerance 1e-7). Presolve stays on: off,
#: the dual simplex ended "Unknown" near mu^c on a random free body (m = 3)
LP_OPTIONS = {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10}
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
#: HiGHS's statuses, as scipy.optimize's linprog and milp report them (`status`), in the
#: package's vocabulary: 0 optimal (a point), 2 infeasible; 1 iteration or time limit,
#: 3 unbounded (no problem here is: a feasibility LP has no objective, the MILP's is
#: bounded), 4 numerical difficulties or other: nothing decided
HIGHS_STATUS = {0: Status.FEASIBLE, 1: Status.UNDECIDED, 2: Status.INFEASIBLE, 3: Status.UNDECIDED,
                4: Status.UNDECIDED}


def lp_feasible(rows: Rows, mu: float, options: dict | None = None, method: str = "highs-ds",
                counts: dict | None = None) -> tuple[Status, np.ndarray | None]:
    """Feasibility of {rows(mu) x (>=,==) 0, sum r_n = 1}: (status, x or None), by
    HiGHS (`method`: "highs-ds", dual simplex, which returns a vertex; "highs-ipm").

    The equalities are eliminated first (x = Z y, Z = rows.Z, mu-independent and
    computed once per rows): HiGHS solves an LP of half the size without equality rows
    (plug2d m = 80, 240 x 160: 25 ms a solve against 257 ms, most of which was HiGHS's
    presolve of the equality rows). A point it returns must meet the unit x-space rows
    to X_SPACE_TOL absolutely, as the x-space LP's tolerance guarantees; one that does
    not (a huge y along a near-recession direction on which sum r_n is a tiny share of
    |y|, within tolerance of the reduced rows only) is decided by the x-space LP instead, and so
    is a problem HiGHS leaves undecided in the eliminated form (counted as "lp_x_space")."""
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
    status, y = _highs(B[keep] / bn[keep, None], n[None, :], Z.shape[1], options, method)
    if status == Status.INFEASIBLE:
        return status, None
    if status == Status.FEASIBLE:
        x = Z @ y
        # sum r_n = 1 over ||norm|| ||x||: the share of x the normalisation sees
        share = 1.0 / max(np.linalg.norm(rows.norm) * np.linalg.norm(x), 1e-300)
        if share * np.sqrt(x.size) >= NORM_SHARE_MIN and \
                max(np.abs(A[E] @ x).max(initial=0.0), (-(A[~E] @ x)).max(initial=0.0)) <= X_SPACE_TOL:
            return status, x
    count(counts, "lp_x_space")
    status, x = _highs(A[~E], np.vstack([A[E], rows.norm[None, :]]), A.shape[1], options, method)
    return status, x


def _highs(A_ge: np.ndarray, A_eq: np.ndarray, d: int, options: dict | None,
           method: str) -> tuple[Status, np.ndarray | None]:
    """{A_ge v >= 0, A_eq v = e_last (the last row is the normalisation)}, v free in R^d."""
    from scipy.optimize import linprog  # here, not at the top: 0.16 s of every rank's start-up
    b_eq = np.zeros(A_eq.shape[0])
    b_eq[-1] = 1.0
    ge = A_ge.shape[0] > 0
    res = linprog(np.zeros(d), A_ub=-A_ge if ge else None, b_ub=np.zeros(A_ge.shape[0]) if ge else None,
                  A_eq=A_eq, b_eq=b_eq, bounds=[(None, None)] * d, method=method, options=options)
    status = HIGHS_STATUS.get(res.status, Status.UNDECIDED)
    return status, res.x if status == Status.FEASIBLE else None


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

