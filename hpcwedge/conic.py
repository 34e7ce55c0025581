"""The one builder of pattern feasibility problems, and the status policy.

A (partial) sign pattern is two boolean masks over the m nodes:
zero_u (u_n,i = 0: contact) and zero_r (r_i = 0: gap). A node in neither is
free (u_n >= 0, r_n >= 0, no complementarity: the branch-and-bound relaxation);
a node in both has u_n = r_n = 0. Every problem is normalised by sum(r_n) = 1.

In 2D the problem is an LP (HiGHS dual simplex, which returns a vertex — the
polish of mu^c needs its active set). mu = inf drops the friction rows
(r_t free): the relaxation that decides "no wedge at any mu".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog

from .problem import Parametrization

FEASIBLE, INFEASIBLE, UNDECIDED = "feasible", "infeasible", "undecided"


@dataclass(frozen=True)
class Rows:
    """Homogeneous constraint rows (a0 + mu * a1) . x  (>= 0 or == 0), unit-scaled at
    build time; `eq` marks equalities. `norm` is the row of sum(r_n)."""

    a0: np.ndarray
    a1: np.ndarray
    eq: np.ndarray
    norm: np.ndarray


def pattern_rows(param: Parametrization, m: int, zero_u: np.ndarray, zero_r: np.ndarray,
                 friction: bool = True) -> Rows:
    """Rows of the 2D pattern problem, x in R^d:
    u_n,i == 0 (zero_u), r_n,i == r_t,i == 0 (zero_r), u_n,i >= 0 (others),
    mu r_n,i +- r_t,i >= 0 (nodes not in zero_r; with friction=False: r_n,i >= 0)."""
    U, R = param.U, param.R
    Un, Rn, Rt = U[:m], R[:m], R[m:2 * m]
    z = np.zeros_like(Un)
    a0, a1, eq = [], [], []

    def add(r0, r1, is_eq):
        a0.append(r0)
        a1.append(r1)
        eq.append(np.full(len(r0), is_eq))

    add(Un[zero_u], z[zero_u], True)
    add(Rn[zero_r], z[zero_r], True)
    add(Rt[zero_r], z[zero_r], True)
    add(Un[~zero_u], z[~zero_u], False)
    fr = ~zero_r
    if friction:
        add(Rt[fr], Rn[fr], False)
        add(-Rt[fr], Rn[fr], False)
    else:
        add(Rn[fr], z[fr], False)
    A0, A1, E = np.vstack(a0), np.vstack(a1), np.concatenate(eq)
    return Rows(a0=A0, a1=A1, eq=E, norm=Rn.sum(axis=0))


def lp_feasible(rows: Rows, mu: float) -> tuple[str, np.ndarray | None]:
    """Feasibility of {rows(mu) x (>=,==) 0, sum r_n = 1}: (status, x or None)."""
    A = rows.a0 + mu * rows.a1
    scale = np.linalg.norm(A, axis=1)
    live = scale > 0
    A, E = A[live] / scale[live, None], rows.eq[live]
    d = A.shape[1]
    A_eq = np.vstack([A[E], rows.norm[None, :]])
    b_eq = np.zeros(A_eq.shape[0])
    b_eq[-1] = 1.0
    res = linprog(np.zeros(d), A_ub=-A[~E] if (~E).any() else None,
                  b_ub=np.zeros((~E).sum()) if (~E).any() else None,
                  A_eq=A_eq, b_eq=b_eq, bounds=[(None, None)] * d, method="highs-ds")
    if res.status == 0:
        return FEASIBLE, res.x
    if res.status == 2:
        return INFEASIBLE, None
    return UNDECIDED, None
