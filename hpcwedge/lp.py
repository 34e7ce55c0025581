"""LP feasibility of a pattern problem (`rows.Rows`) by HiGHS (scipy.optimize.linprog),
and the violation of a point of it.

2D patterns are LPs, and so are the 3D pyramid fallbacks (rows.pyramid_rows). HiGHS's
dual simplex returns a vertex: the polish of mu^c (mu_bracket.py) needs its active set.
"""
from __future__ import annotations

import numpy as np

from .rows import Rows, Status

#: HiGHS options of the pattern LPs (2D) and the pyramid LPs (3D fallback); None given to
#: `lp_feasible`: HiGHS's defaults (feasibility tolerance 1e-7)
LP_OPTIONS = {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10}


def lp_feasible(rows: Rows, mu: float, options: dict | None = None,
                method: str = "highs-ds") -> tuple[Status, np.ndarray | None]:
    """Feasibility of {rows(mu) x (>=,==) 0, sum r_n = 1}: (status, x or None), by
    HiGHS (`method`: "highs-ds", dual simplex, which returns a vertex; "highs-ipm")."""
    A = rows.a0 + mu * rows.a1
    scale = np.linalg.norm(A, axis=1)
    live = scale > 0
    A, E = A[live] / scale[live, None], rows.eq[live]
    d = A.shape[1]
    A_eq = np.vstack([A[E], rows.norm[None, :]])
    b_eq = np.zeros(A_eq.shape[0])
    b_eq[-1] = 1.0
    from scipy.optimize import linprog     # here, not at the top: 0.16 s of every rank's start-up
    res = linprog(np.zeros(d), A_ub=-A[~E] if (~E).any() else None,
                  b_ub=np.zeros((~E).sum()) if (~E).any() else None,
                  A_eq=A_eq, b_eq=b_eq, bounds=[(None, None)] * d, method=method,
                  options=options)
    if res.status == 0:
        return Status.FEASIBLE, res.x
    if res.status == 2:
        return Status.INFEASIBLE, None
    return Status.UNDECIDED, None


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

