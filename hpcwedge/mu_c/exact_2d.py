"""2D mu^c of a sign pattern certified in exact rational arithmetic (python-flint), for runs
whose float coordinates are too ill-conditioned for 1e-9 (the runs whose double description
numerics.py redid exactly: plug2d at a 0.001 deg taper, cond(T) 6e9, polished 2.9e-7 below
tan 0.001 deg).

From a float value mu_f: the rows tight at the pattern's point just above mu_f (the float
LP's vertex; `tight_rows`), with the pattern's equalities, form a square system A_S(mu) that
turns singular at mu^c. Its exact determinant is bisected on its sign to CERT_RTOL; the
bracket [lo, hi] is then certified at both ends (`certified`): at hi a vertex through the
equalities and all tight rows but one satisfies every row exactly (feasible), at lo a
Farkas vector on the rows S proves infeasibility (y >= 0 on the inequalities, A_S^T y =
-sum r_n). hi, a double, is returned: mu^c lies in [lo, hi], within CERT_RTOL of hi.
"""
from __future__ import annotations

import itertools

import flint
import numpy as np

from hpcwedge import exact as xq
from hpcwedge.contact.problem import Parametrization, balanced
from hpcwedge.mu_c.bracket import rows_at
from hpcwedge.rays.numerics import COND_T_SUSPECT
from hpcwedge.solvers.feasibility import decide
from hpcwedge.solvers.rows import Status, pattern_rows

#: width of the certified bracket, relative
CERT_RTOL = 1e-13
#: the determinant's sign change is looked for within mu_f (1 -/+ SEARCH_RTOL)
SEARCH_RTOL = 1e-5
#: the square systems tried: the d - E inequality rows of least slack at the float vertex and
#: these many more, every choice of d - E among them
SPARE_ROWS = 2


def row_labels_2d(zero_u: np.ndarray, zero_r: np.ndarray) -> list[tuple[str, int]]:
    """The 2D pattern rows of rows.pattern_rows, in its order, as (kind, node): "u" u_n,
    "rn" r_n, "rt" r_t (the equalities: contact u_n, gap r_n and r_t), then "u" u_n >= 0,
    "p" mu r_n + r_t >= 0, "m" mu r_n - r_t >= 0."""
    zu, zr = np.flatnonzero(zero_u), np.flatnonzero(zero_r)
    free_u, fr = np.flatnonzero(~np.asarray(zero_u, bool)), np.flatnonzero(~np.asarray(zero_r, bool))
    return ([("u", int(i)) for i in zu] + [("rn", int(i)) for i in zr] + [("rt", int(i)) for i in zr]
            + [("u", int(i)) for i in free_u] + [("p", int(i)) for i in fr] + [("m", int(i)) for i in fr])


def tight_rows(param: Parametrization, m: int, zero_u: np.ndarray, zero_r: np.ndarray, mu_f: float,
               scale: float) -> list[tuple[str, int]] | None:
    """The labels of the inequality rows by increasing relative slack at the float LP's
    vertex at mu_f (1 + SEARCH_RTOL), in coordinates balanced there; None: no vertex."""
    mu = mu_f * (1 + SEARCH_RTOL)
    rows = pattern_rows(balanced(param, mu, m, scale, cond=False)[0], m, zero_u, zero_r)
    d = decide(rows, mu)
    if d.status != Status.FEASIBLE:
        return None
    slack = rows_at(rows, mu) @ d.x / max(float(np.linalg.norm(d.x)), 1e-300)
    ineq = [(abs(s), k, lab) for k, (lab, s, eq) in enumerate(zip(row_labels_2d(zero_u, zero_r), slack, rows.eq))
            if not eq]
    return [lab for _, _, lab in sorted(ineq)]


def _rows(pq: Parametrization, m: int, labels, mu: flint.fmpq) -> list[list]:
    """The exact rows of `labels` at mu (lists of fmpq over x)."""
    U, R, d = pq.Uq, pq.Rq, pq.Uq.ncols()
    out = []
    for kind, i in labels:
        if kind == "u":
            out.append([U[i, j] for j in range(d)])
        elif kind == "rn":
            out.append([R[i, j] for j in range(d)])
        elif kind == "rt":
            out.append([R[m + i, j] for j in range(d)])
        else:
            sign = 1 if kind == "p" else -1
            out.append([mu * R[i, j] + sign * R[m + i, j] for j in range(d)])
    return out


def _matrix(rows: list[list]) -> flint.fmpq_mat:
    return flint.fmpq_mat(len(rows), len(rows[0]), [v for r in rows for v in r])


def _norm(pq: Parametrization, m: int) -> list:
    d = pq.Rq.ncols()
    return [sum((pq.Rq[i, j] for i in range(m)), flint.fmpq(0)) for j in range(d)]


def _det_sign(pq, m, labels, mu: float) -> int:
    det = _matrix(_rows(pq, m, labels, xq.q_scalar(mu))).det()
    return (det > 0) - (det < 0)


def certified(pq: Parametrization, m: int, zero_u: np.ndarray, zero_r: np.ndarray,
              eq_labels, tight, lo: float, hi: float) -> bool:
    """The pattern problem is feasible at hi and infeasible at lo, shown in exact arithmetic
    (module doc); eq_labels, tight: the equality and tight inequality rows (len d together)."""
    every = row_labels_2d(zero_u, zero_r)[_n_eq(zero_u, zero_r):]
    norm = _norm(pq, m)
    d = len(norm)
    hq, lq = xq.q_scalar(hi), xq.q_scalar(lo)
    ineq_hi = _rows(pq, m, every, hq)
    feasible = False
    for drop in range(len(tight)):
        through = eq_labels + tight[:drop] + tight[drop + 1:]
        try:
            x = _matrix(_rows(pq, m, through, hq) + [norm]).solve(flint.fmpq_mat(d, 1, [0] * (d - 1) + [1]))
        except ZeroDivisionError:
            continue
        x = [x[j, 0] for j in range(d)]
        if all(sum((a * b for a, b in zip(r, x)), flint.fmpq(0)) >= 0 for r in ineq_hi):
            feasible = True
            break
    if not feasible:
        return False
    S = _rows(pq, m, eq_labels + tight, lq)
    try:
        y = _matrix(S).transpose().solve(flint.fmpq_mat(d, 1, [-v for v in norm]))
    except ZeroDivisionError:
        return False
    return all(y[k, 0] >= 0 for k in range(len(eq_labels), d))


def _n_eq(zero_u: np.ndarray, zero_r: np.ndarray) -> int:
    """How many of row_labels_2d's rows, the first ones, are equalities."""
    return int(np.sum(zero_u)) + 2 * int(np.sum(zero_r))


def exact_mu_c_2d(pq: Parametrization, param: Parametrization, m: int, zero_u: np.ndarray,
                  zero_r: np.ndarray, mu_f: float, scale: float) -> float | None:
    """mu^c of the 2D pattern (zero_u, zero_r), certified within CERT_RTOL (module doc),
    from the float value mu_f (float parametrisation `param`, stiffness `scale` as for
    mu_critical); pq: the exact parametrisation. None: not certified (no tight square
    system with a sign change near mu_f, or a certificate failed)."""
    zero_u, zero_r = np.asarray(zero_u, bool), np.asarray(zero_r, bool)
    tight = tight_rows(param, m, zero_u, zero_r, mu_f, scale)
    if tight is None:
        return None
    eq_labels = row_labels_2d(zero_u, zero_r)[:_n_eq(zero_u, zero_r)]
    d = pq.Uq.ncols()
    k = d - len(eq_labels)
    for chosen in itertools.combinations(tight[:k + SPARE_ROWS], k) if 0 < k <= len(tight) else ():
        S = eq_labels + list(chosen)
        lo, hi = mu_f * (1 - SEARCH_RTOL), mu_f * (1 + SEARCH_RTOL)
        s_lo, s_hi = _det_sign(pq, m, S, lo), _det_sign(pq, m, S, hi)
        if s_lo == 0 or s_hi == 0 or s_lo == s_hi:
            continue
        while hi - lo > CERT_RTOL * hi:
            mid = 0.5 * (lo + hi)
            if mid in (lo, hi):
                break
            s = _det_sign(pq, m, S, mid)
            if s == 0:
                lo = hi = mid
                break
            if s == s_lo:
                lo = mid
            else:
                hi = mid
        lo, hi = np.nextafter(lo, 0.0), np.nextafter(hi, np.inf)
        if certified(pq, m, zero_u, zero_r, eq_labels, list(chosen), float(lo), float(hi)):
            return float(hi)
    return None


def certify_2d(values: dict, tasks: dict, pq: Parametrization, param: Parametrization, m: int,
               scale: float, notes: list) -> None:
    """Every float 2D mu^c in `values` (MuC by key; tasks: key -> (zero_u, zero_r, mu))
    replaced by its exactly certified value (`exact_mu_c_2d`, polished); one without an
    exact certificate keeps its float value, marked not polished, with a line in `notes`."""
    for key, (zero_u, zero_r, _) in tasks.items():
        value = values[key]
        if value.mu_c is None:
            continue
        exact = exact_mu_c_2d(pq, param, m, zero_u, zero_r, value.mu_c, scale)
        if exact is not None:
            value.mu_c, value.polished = exact, True
            continue
        value.polished = False
        notes.append(f"a mu^c ({value.mu_c:.12g}) of a run redone in exact arithmetic has no exact "
                     "certificate: its float value is kept, not polished")


def exact_certifier(scene, m: int, param: Parametrization, exact_param, scale: float | None):
    """For the global search without an enumeration (global_mu_c.global_mu_critical's
    certify): in 2D on the accurate route, when the scene is exact or its coordinates
    balanced at its first mu are as ill-conditioned as a suspect enumeration's (cond(T) >
    numerics.COND_T_SUSPECT, m <= compute.exact_fallback_max_m: plug2d at 0.001 deg, the
    search's value 2.3e-8 off), a function certifying the least pattern's value exactly;
    else None."""
    if scene.dim != 2 or scene.mu_c_method != "accurate":
        return None
    if not scene.exact and (m > scene.exact_fallback_max_m
                            or balanced(param, scene.mu[0], m, scale)[1] <= COND_T_SUSPECT):
        return None
    return lambda zero_u, zero_r, mu_c: exact_mu_c_2d(exact_param(), param, m, zero_u, zero_r, mu_c, scale)
