"""The one builder of pattern feasibility problems, and the status policy.

A (partial) sign pattern is two boolean masks over the m nodes:
zero_u (u_n,i = 0: contact) and zero_r (r_i = 0: gap). A node in neither is
free (u_n >= 0, r_n >= 0, no complementarity: the branch-and-bound relaxation);
a node in both has u_n = r_n = 0. Every problem is normalised by sum(r_n) = 1.

2D: the problem is an LP (`Rows`; HiGHS dual simplex, which returns a vertex —
the polish of mu^c needs its active set). mu = inf drops the friction rows
(r_t free): the relaxation that decides "no wedge at any mu".

3D: the problem is an SOCP (`ConeRows`) in x in R^d:

    eq x = 0                 u_n,i = 0 (contact), r_i = 0 (gap)
    lin x >= 0               u_n,i >= 0 (every node not in contact)
    ||rt_i x|| <= mu rn_i x  every node not in gap (implies r_n,i >= 0)
    norm x = 1               sum r_n = 1

solved by Clarabel in the coordinates w of the null space of `eq` (x = Z w: the
pattern equalities are eliminated once, by an SVD, so the solver never meets
dependent equality rows). With friction=False (r_t free) it is the LP
{eq, lin, r_n >= 0} (a `Rows`).

Status policy (3D, `socp_feasible`), every outcome counted:
  1. Clarabel, default tolerances. Solved -> the returned x is verified (every
     row to VERIFY_TOL relative to the size of x); PrimalInfeasible -> its
     certificate is verified (A^T z = 0, b^T z < 0, z in the dual cone, to
     CERT_TOL). A verified answer is definitive.
  2. Anything else (Almost*, MaxIterations, NumericalError, InsufficientProgress,
     or a verification that failed): Clarabel again with other settings
     (static regularisation; then Clarabel's defaults with equilibration).
  3. Still unsure: LPs on polyhedral pyramids of the friction cones with
     k = 16, 64, 256 facets per node — inner (inscribed: feasible ⇒ feasible,
     its x verified on the circular cones) and outer (circumscribed:
     infeasible ⇒ infeasible).
  4. Still unsure: UNDECIDED (callers keep the subtree / report the pattern as
     undecided; nothing is pruned on doubt).

`feasible(rows, mu)` dispatches on the problem type; patterns.py and
mu_critical.py call only it.
"""
from __future__ import annotations

import contextlib
import functools
import math
import os
import sys
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .problem import Parametrization

FEASIBLE, INFEASIBLE, UNDECIDED = "feasible", "infeasible", "undecided"

#: relative size under which a constraint row is taken as identically zero
ZERO_ROW_RTOL = 1e-12
#: rank decision on the unit-scaled pattern equalities
EQ_RANK_RTOL = 1e-10
#: a returned x is feasible when every row holds to VERIFY_TOL * ||x|| (the order of
#: Clarabel's own feasibility tolerance: an optimum on the boundary misses by 1e-9..3e-9;
#: 2D: HiGHS's primal feasibility tolerance is 1e-7)
VERIFY_TOL = 1e-8
#: an infeasibility certificate z holds when ||A^T z|| and the dual-cone violation are
#: <= CERT_TOL * |b^T z| (b^T z < 0 strictly)
CERT_TOL = 1e-7
#: HiGHS options of the 2D pattern LPs (None: HiGHS's defaults, feasibility tolerance 1e-7)
LP_OPTIONS = {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10}
#: facets per node of the polyhedral pyramids, tried in turn
PYRAMID_SIDES = (16, 64, 256)


def pyramid_sides_for(spread: float) -> tuple[int, ...]:
    """The pyramid levels worth trying at a mu known to lie within `spread`
    (relative) of mu^c (a bisection's midpoint: half the bracket width over mu).
    The inscribed and circumscribed k-pyramids differ from the circular cones by a
    factor cos(pi/k) on mu, so their critical values bracket mu^c no tighter than
    that: a level decides a point nearer to mu^c than its gap 1 - cos(pi/k) only
    where its facets happen to touch the optimum. Levels with a gap above
    `spread` are left out (a 256-facet pyramid costs ~0.1-1 s of HiGHS on an 18-node
    problem, and measured on plug3d 3 x 6 none decided anything inside the mu^c
    bisection)."""
    return tuple(k for k in PYRAMID_SIDES if 1.0 - math.cos(math.pi / k) <= spread)


@dataclass(frozen=True)
class Rows:
    """Homogeneous constraint rows (a0 + mu * a1) . x  (>= 0 or == 0), unit-scaled at
    build time; `eq` marks equalities. `norm` is the row of sum(r_n)."""

    a0: np.ndarray
    a1: np.ndarray
    eq: np.ndarray
    norm: np.ndarray


@dataclass(frozen=True)
class ConeRows:
    """The 3D pattern SOCP (module doc). eq (E, d), lin (L, d): unit rows;
    rn (c, d), rt (c, 2, d): the cone nodes `nodes`, each node's three rows scaled
    by one common factor; norm (d,): sum r_n. Z (d, p): orthonormal basis of the
    null space of eq (the solver's coordinates, x = Z w). lin_nodes (L,): the node
    of each lin row."""

    eq: np.ndarray
    lin: np.ndarray
    rn: np.ndarray
    rt: np.ndarray
    norm: np.ndarray
    nodes: np.ndarray
    Z: np.ndarray
    lin_nodes: np.ndarray

    @property
    def d(self) -> int:
        return self.eq.shape[1]


def problem_dim(param: Parametrization, m: int) -> int:
    """2 or 3, from the parametrisation's row count (dim * m)."""
    return param.U.shape[0] // m


def _unit(A: np.ndarray) -> np.ndarray:
    """Rows scaled to unit norm; rows that are identically zero (relative to the
    largest) dropped."""
    A = A[_kept(A)]
    return A / np.linalg.norm(A, axis=1, keepdims=True)


def _kept(A: np.ndarray) -> np.ndarray:
    """The rows of A that `_unit` keeps (boolean mask)."""
    s = np.linalg.norm(A, axis=1)
    return s > ZERO_ROW_RTOL * max(s.max(initial=0.0), 1e-300)


def pattern_rows(param: Parametrization, m: int, zero_u: np.ndarray, zero_r: np.ndarray,
                 friction: bool = True) -> Rows | ConeRows:
    """The pattern problem in x in R^d: 2D -> `Rows` (LP); 3D -> `ConeRows` (SOCP),
    or `Rows` (LP) when friction=False."""
    if problem_dim(param, m) == 3:
        return _pattern_rows_3d(param, m, np.asarray(zero_u, bool), np.asarray(zero_r, bool), friction)
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


def _pattern_rows_3d(param, m, zu, zr, friction):
    U, R = param.U, param.R
    Un, Rn, Rt1, Rt2 = U[:m], R[:m], R[m:2 * m], R[2 * m:3 * m]
    norm = Rn.sum(axis=0)
    eq = _unit(np.vstack([Un[zu], Rn[zr], Rt1[zr], Rt2[zr]]))
    lin = _unit(Un[~zu])
    lin_nodes = np.flatnonzero(~zu)[_kept(Un[~zu])]
    fr = ~zr
    if not friction:
        rn = _unit(Rn[fr])
        A0 = np.vstack([eq, lin, rn])
        E = np.concatenate([np.ones(len(eq), bool), np.zeros(len(lin) + len(rn), bool)])
        return Rows(a0=A0, a1=np.zeros_like(A0), eq=E, norm=norm)
    nodes = np.flatnonzero(fr)
    rn, rt = Rn[fr], np.stack([Rt1[fr], Rt2[fr]], axis=1)
    sc = _cone_scale(Rn, Rt1, Rt2)[fr]
    if eq.shape[0]:
        _, s, vt = np.linalg.svd(eq)
        rank = int((s > EQ_RANK_RTOL * s[0]).sum())
        Z = vt[rank:].T
    else:
        Z = np.eye(param.d)
    return ConeRows(eq=eq, lin=lin, rn=rn / sc[:, None], rt=rt / sc[:, None, None], norm=norm,
                    nodes=nodes, Z=Z, lin_nodes=lin_nodes)


def _cone_scale(Rn: np.ndarray, Rt1: np.ndarray, Rt2: np.ndarray) -> np.ndarray:
    """The common factor of each node's (r_n, r_t1, r_t2) rows in the SOCP."""
    sc = np.sqrt((Rn ** 2).sum(1) + (Rt1 ** 2).sum(1) + (Rt2 ** 2).sum(1))
    sc[sc == 0] = 1.0
    return sc


# ----------------------------------------------------------------------- dispatch
def feasible(rows: Rows | ConeRows, mu: float, counts: dict | None = None) -> tuple[str, np.ndarray | None]:
    """Feasibility of the pattern problem at mu: (status, x or None), x normalised
    to sum r_n = 1. 2D / LP -> HiGHS; 3D -> the SOCP status policy (module doc).
    `counts` (optional) accumulates how each problem was decided."""
    if isinstance(rows, Rows):
        status, x = lp_feasible(rows, mu, LP_OPTIONS)
        _count(counts, "lp_" + status)
        if status == UNDECIDED:          # HiGHS's simplex gave up: its interior point method
            status, x = lp_feasible(rows, mu, LP_OPTIONS, method="highs-ipm")
            _count(counts, "lp_retry_ipm_" + status)
        return status, x
    return socp_feasible(rows, mu, counts)


def _count(counts, key, n=1):
    if counts is not None:
        counts[key] = counts.get(key, 0) + n


#: solver tolerances: "default" or "tight" (HiGHS feasibility 1e-10; Clarabel feasibility and gap
#: 1e-10 on every attempt) — set by `solver_tolerances`, for benchmarks of run time against error
_TOLERANCES = {"mode": "default"}


def solver_tolerances(mode: str) -> None:
    """Every later LP and SOCP at the solvers' "default" tolerances or "tight" ones."""
    if mode not in ("default", "tight"):
        raise ValueError(f"solver tolerances: 'default' or 'tight', got {mode!r}")
    _TOLERANCES["mode"] = mode
    _SETTINGS.clear()


def lp_feasible(rows: Rows, mu: float, options: dict | None = None,
                method: str = "highs-ds") -> tuple[str, np.ndarray | None]:
    """Feasibility of {rows(mu) x (>=,==) 0, sum r_n = 1}: (status, x or None), by
    HiGHS (`method`: "highs-ds", dual simplex, which returns a vertex; "highs-ipm")."""
    if options is None and _TOLERANCES["mode"] == "tight":
        options = _LP_TIGHT
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
        return FEASIBLE, res.x
    if res.status == 2:
        return INFEASIBLE, None
    return UNDECIDED, None


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


# ----------------------------------------------------------------------- 3D: SOCP
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


def _settings(attempt: int, tight: bool = False):
    """Clarabel settings of attempts 0..3 (see ATTEMPTS); tight: for an optimisation
    (objective given). The rows are unit-scaled
    already, and Ruiz equilibration on top of that measured worse: on plug3d
    (m = 10, all 1,024 partitions, mu = 0.55 / 0.65 / 1.0) 7 % non-definitive
    statuses with it, none without."""
    import clarabel
    s = clarabel.DefaultSettings()
    s.verbose = False
    if attempt < 3:
        s.equilibrate_enable = False
    if attempt == 2:
        s.static_regularization_constant = 1e-7
        s.max_iter = 400
    if tight or _TOLERANCES["mode"] == "tight":
        # an optimum (the branch and bound's steered solves) lies on the boundary,
        # where the default 1e-8 tolerances left cone rows 1e-8..4e-8 short of
        # VERIFY_TOL relative to the reactions (66 of 945 solves on plug3d, mu = 1)
        s.tol_feas = s.tol_gap_abs = s.tol_gap_rel = 1e-10
    return s


#: attempt k: (settings k, least-norm objective P = I?). 0: plain; 1: the least-norm
#: feasible point (when the plain solve returned a point that does not verify: the
#: iterates can run off along rigid lift-offs, measured up to ||x|| ~ 1e17; P = I
#: is not the default because it weakens the infeasibility certificates: 732 of
#: 2,126 failed the Farkas check on plug3d + 30 random free bodies, none with
#: P = 0); 2: static regularisation 1e-7; 3: Clarabel's defaults (equilibration on)
ATTEMPTS = 4
LEAST_NORM_ATTEMPT = 1
_SETTINGS: dict = {}


@dataclass
class Decision:
    """One feasibility decision. status: FEASIBLE / INFEASIBLE / UNDECIDED; x: a
    verified point (sum r_n = 1) when feasible; positive: the objective given to
    `decide` is proven > 0 on the whole feasible set (by a verified dual), i.e. the
    problem with the extra equality objective . x = 0 is infeasible."""

    status: str
    x: np.ndarray | None = None
    positive: bool = False
    #: INFEASIBLE by a verified Clarabel certificate: that certificate (its rows laid
    #: out as in _socp_data), for `infeasible_core`
    farkas: np.ndarray | None = None


def _socp_data(rows: ConeRows, mu: float):
    """Clarabel data in w (x = Z w): rows [sum r_n = 1 | lin | cones]; A w + s = b."""
    import clarabel
    Z = rows.Z
    blocks = [(rows.norm @ Z)[None, :], -(rows.lin @ Z)]
    cones = [clarabel.ZeroConeT(1)]
    if rows.lin.shape[0]:
        cones.append(clarabel.NonnegativeConeT(rows.lin.shape[0]))
    for i in range(rows.rn.shape[0]):
        blocks.append(-np.vstack([mu * rows.rn[i], rows.rt[i]]) @ Z)
        cones.append(clarabel.SecondOrderConeT(3))
    A = np.vstack(blocks)
    b = np.zeros(A.shape[0])
    b[0] = 1.0
    return A, b, cones


def _clarabel(rows: ConeRows, mu: float, attempt: int = 0, objective: np.ndarray | None = None):
    """One Clarabel solve. Returns (status name, x or the Farkas certificate z or None,
    certificate ok (PrimalInfeasible) or None, positive): positive when an objective
    was given and the dual proves it > 0."""
    import clarabel
    A, b, cones = _socp_data(rows, mu)
    p = rows.Z.shape[1]
    q = np.zeros(p) if objective is None else rows.Z.T @ objective
    P = _csc_eye(p) if objective is None and attempt == LEAST_NORM_ATTEMPT else _csc_zero(p)
    key = (attempt, objective is not None)
    if key not in _SETTINGS:
        _SETTINGS[key] = _settings(attempt, tight=objective is not None)
    sol = clarabel.DefaultSolver(P, q, _csc_dense(A), b, cones, _SETTINGS[key]).solve()
    name = str(sol.status)
    n_lin = rows.lin.shape[0]
    if name == "Solved":
        positive = False
        if objective is not None:
            # the optimal dual z (A^T z + q = 0, z in K*) with b^T z < 0 is a Farkas
            # certificate of {A w + s = b, q . w = 0}: check it like any other
            positive = _certificate_ok(np.vstack([q[None, :], A]), np.concatenate([[0.0], b]),
                                       np.concatenate([[1.0], np.asarray(sol.z)]), 2, n_lin)
        return name, rows.Z @ np.asarray(sol.x), None, positive
    if name == "PrimalInfeasible":
        z = np.asarray(sol.z)
        return name, z, _certificate_ok(A, b, z, 1, n_lin), False
    return name, None, None, False


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


def _certificate_ok(A, b, z, n_zero, n_lin) -> bool:
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


def pyramid_rows(rows: ConeRows, sides: int, inner: bool, phase: np.ndarray | None = None) -> Rows:
    """LP rows of the pattern problem with every friction cone replaced by a pyramid of
    `sides` facets: inscribed (inner) or circumscribed (outer). phase (c,): per cone
    node, the angle in the (t1, t2) plane of one facet normal (default: half a
    facet off the t1 axis)."""
    c = rows.rn.shape[0]
    base = 2 * np.pi * np.arange(sides) / sides
    ph = np.full(c, np.pi / sides) if phase is None else np.asarray(phase, float)
    th = ph[:, None] + base[None, :]                                  # (c, k)
    dirs = np.stack([np.cos(th), np.sin(th)], axis=2)                 # (c, k, 2)
    f0 = -np.einsum("cka,cad->ckd", dirs, rows.rt).reshape(-1, rows.d)   # -(t . r_t)
    f1 = np.repeat((math.cos(math.pi / sides) if inner else 1.0) * rows.rn, sides, axis=0)
    d = rows.d
    a0 = np.vstack([rows.eq, rows.lin, f0])
    a1 = np.vstack([np.zeros((rows.eq.shape[0] + rows.lin.shape[0], d)), f1])
    eq = np.concatenate([np.ones(rows.eq.shape[0], bool), np.zeros(a0.shape[0] - rows.eq.shape[0], bool)])
    return Rows(a0=a0, a1=a1, eq=eq, norm=rows.norm)


_LP_TIGHT = {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10}


def socp_feasible(rows: ConeRows, mu: float, counts: dict | None = None) -> tuple[str, np.ndarray | None]:
    """The 3D status policy (module doc): (FEASIBLE, x) | (INFEASIBLE, None) | (UNDECIDED, None)."""
    d = decide(rows, mu, counts)
    return d.status, d.x


def decide(rows: Rows | ConeRows, mu: float, counts: dict | None = None,
           objective: np.ndarray | None = None, pyramid_sides: tuple[int, ...] = PYRAMID_SIDES) -> Decision:
    """`feasible` with an optional objective (x-space vector; 3D only, ignored for LPs)
    to minimise over the feasible set: the branch and bound passes the next node's
    u_n row, so that the returned x lies on u_n = 0 when the contact child is feasible
    (the skip-solve rule then takes it), and `positive` proves the contact child
    infeasible when it is not. pyramid_sides: the levels of the pyramid LP
    fallback (step 3 of the status policy), e.g. pyramid_sides_for(spread)."""
    if isinstance(rows, Rows):
        status, x = feasible(rows, mu, counts)
        return Decision(status, x)
    if rows.Z.shape[1] == 0 or np.abs(rows.norm @ rows.Z).max() <= ZERO_ROW_RTOL * np.linalg.norm(rows.norm):
        _count(counts, "eq_infeasible")          # sum r_n vanishes on the pattern's subspace
        return Decision(INFEASIBLE)
    for attempt in range(ATTEMPTS):
        # retries are plain feasibility problems (an optimum on the boundary is the
        # first thing to miss a verification)
        name, x, cert, positive = _clarabel(rows, mu, attempt, objective if attempt == 0 else None)
        tag = f"retry{attempt}_" if attempt else ""
        _count(counts, tag + name)
        if cert is not None:
            if cert:
                return Decision(INFEASIBLE, farkas=x)
            _count(counts, tag + "certificate_failed")
        elif x is not None:
            if violation(rows, mu, x) <= VERIFY_TOL:
                return Decision(FEASIBLE, x / (rows.norm @ x), positive)
            _count(counts, tag + "verify_failed")
    for sides in pyramid_sides:
        status, x = lp_feasible(pyramid_rows(rows, sides, inner=True), mu, _LP_TIGHT)
        _count(counts, "lp_calls")
        if status == FEASIBLE and violation(rows, mu, x) <= VERIFY_TOL:
            _count(counts, "pyramid_inner_feasible")
            return Decision(FEASIBLE, x / (rows.norm @ x))
        status, _ = lp_feasible(pyramid_rows(rows, sides, inner=False), mu, _LP_TIGHT)
        _count(counts, "lp_calls")
        if status == INFEASIBLE:
            _count(counts, "pyramid_outer_infeasible")
            return Decision(INFEASIBLE)
    _count(counts, "undecided")
    return Decision(UNDECIDED)


# ----------------------------------------------------------------------- 3D: infeasible cores
@dataclass(frozen=True)
class NodeRows:
    """Every node's rows of the pattern SOCP in x-space, scaled as `pattern_rows`
    scales them: un (m, d) unit u_n rows (zero rows stay zero); cone (m, 3, d) the
    (r_n, r_t1, r_t2) rows over one common factor per node (mu not applied);
    norm (d,) sum r_n."""

    un: np.ndarray
    cone: np.ndarray
    norm: np.ndarray


def node_rows(param: Parametrization, m: int) -> NodeRows:
    U, R = param.U, param.R
    Un, Rn, Rt1, Rt2 = U[:m], R[:m], R[m:2 * m], R[2 * m:3 * m]
    un = np.zeros_like(Un)
    keep = _kept(Un)
    un[keep] = Un[keep] / np.linalg.norm(Un[keep], axis=1, keepdims=True)
    cone = np.stack([Rn, Rt1, Rt2], axis=1) / _cone_scale(Rn, Rt1, Rt2)[:, None, None]
    return NodeRows(un=un, cone=cone, norm=Rn.sum(axis=0))


def infeasible_core(nr: NodeRows, rows: ConeRows, mu: float, zu: np.ndarray, zr: np.ndarray,
                    z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The part of the pattern (zu, zr) that a verified Clarabel certificate z of its
    infeasibility at mu really uses: masks (core_u <= zu, core_r <= zr) such that
    every pattern fixing at least core_u to contact and core_r to gap is
    infeasible at mu (and at any smaller mu).

    Node-wise, a certificate is a multiplier lam_i of u_n,i (>= 0 unless i is in
    contact, where it is free) and zeta_i of (mu r_n, r_t1, r_t2)_i (in the second-
    order cone unless i is in gap, where it is free) with

        norm + sum_i lam_i un_i + sum_i zeta_i . C_i(mu) = 0       (x-space)

    (then sum r_n = 1 and the constraints give 0 = 1 + (>= 0)). z gives lam and zeta
    for the free nodes; least squares gives the multipliers of the pattern's
    equalities. A fixed node whose multiplier already has the sign (lies in the
    cone) of a free node is left out of the core; so are those whose multiplier is
    cleaned to that (clipped at 0 / projected onto the cone) within half of
    CERT_TOL in total. The cleaned certificate is checked like Clarabel's own
    (residual <= CERT_TOL with sum r_n's multiplier 1); if it fails, the core is
    the whole pattern (what the solve proved anyway)."""
    whole = (zu.copy(), zr.copy())
    m, d = nr.un.shape
    if not np.isfinite(z).all() or z[0] >= 0:
        return whole
    z = z / -z[0]
    L = rows.lin.shape[0]
    C = nr.cone * np.array([mu, 1.0, 1.0])[None, :, None]        # (m, 3, d) at mu
    lam, zeta = np.zeros(m), np.zeros((m, 3))
    lam[rows.lin_nodes] = z[1:1 + L]
    zeta[rows.nodes] = z[1 + L:].reshape(-1, 3)
    # multipliers of the pattern's equalities: least squares on their rows
    cu, cr = np.flatnonzero(zu), np.flatnonzero(zr)
    h = nr.norm + nr.un.T @ lam + np.einsum("ik,ikd->d", zeta, C)
    M = np.vstack([nr.un[cu], C[cr].reshape(-1, d)])
    if M.shape[0]:
        nu = np.linalg.lstsq(M.T, -h, rcond=None)[0]
        lam[cu] = nu[:len(cu)]
        zeta[cr] = nu[len(cu):].reshape(-1, 3)

    def residual(lam, zeta):
        return np.abs(nr.norm + nr.un.T @ lam + np.einsum("ik,ikd->d", zeta, C)).max()

    if residual(lam, zeta) > CERT_TOL / 2:
        return whole
    # what each fixed node's multiplier lacks to be a free node's (its cleaning cost:
    # the rows are unit-sized, C's at most max(mu, 1))
    lam_c = np.maximum(lam, 0.0)
    zeta_c = _soc_project(zeta)
    cost = np.zeros(m)
    cost[cu] = lam_c[cu] - lam[cu]                                  # >= 0: the clip
    cost[cr] = max(mu, 1.0) * np.linalg.norm(zeta[cr] - zeta_c[cr], axis=1)
    fixed = np.concatenate([cu, cr])
    kind = np.concatenate([np.zeros(len(cu), bool), np.ones(len(cr), bool)])
    order = np.argsort(cost[fixed], kind="stable")
    spent = np.cumsum(cost[fixed][order])
    out = spent <= CERT_TOL / 2
    core_u, core_r = zu.copy(), zr.copy()
    for j in order[out]:
        i = fixed[j]
        if kind[j]:
            core_r[i] = False
            zeta[i] = zeta_c[i]
        else:
            core_u[i] = False
            lam[i] = lam_c[i]
    if residual(lam, zeta) > CERT_TOL:
        return whole
    return core_u, core_r


def _soc_project(v: np.ndarray) -> np.ndarray:
    """Rows of v (k, 3) projected onto the second-order cone {||v[1:]|| <= v[0]}."""
    t, w = v[:, 0], v[:, 1:]
    nw = np.linalg.norm(w, axis=1)
    out = v.copy()
    below = nw <= -t                              # in the polar cone: to 0
    out[below] = 0.0
    mid = (nw > np.abs(t))
    a = (t[mid] + nw[mid]) / 2
    out[mid, 0] = a
    out[mid, 1:] = w[mid] * (a / nw[mid])[:, None]
    return out


# ----------------------------------------------------------------------- 2D: MILP
#: a MILP optimum sum(r_n) below this (the normalisation makes it a share in [0, 1]) is
#: no wedged configuration: HiGHS's MIP feasibility tolerance is 1e-6
MILP_WEDGE_TOL = 1e-5
#: scipy.optimize.milp options of `wedge_milp` (HiGHS's presolve off: plug2d m = 40 at
#: mu = 100, 1.8 s against 4.4 s with it)
MILP_OPTIONS: dict = {"presolve": False}


@dataclass(frozen=True)
class WedgeMilp:
    """Answer of `wedge_milp`: status FEASIBLE (a wedged configuration, pattern
    zero_u = contact, zero_r = gap), INFEASIBLE (none: the optimum share of sum r_n is
    below MILP_WEDGE_TOL) or UNDECIDED (HiGHS stopped short); value: that optimum;
    nodes: HiGHS's branch-and-bound nodes."""

    status: str
    value: float
    nodes: int
    zero_u: np.ndarray | None = None
    zero_r: np.ndarray | None = None


def wedge_milp(param: Parametrization, m: int, mu: float, scale: float = 1.0,
               time_limit: float | None = None) -> WedgeMilp:
    """Is there a 2D wedged configuration at mu (mu = inf: r_t free)? One MILP, solved by
    HiGHS (scipy.optimize.milp), over x in R^d and binaries z (z_i = 1: node i may carry
    r_n, u_n,i = 0):

        maximise sum r_n  s.t.  u_n >= 0, mu r_n +- r_t >= 0 (mu = inf: r_n >= 0),
        sum r_n + s sum u_n = 1,  r_n,i <= z_i,  s u_n,i <= 1 - z_i.

    The normalisation is positive on the cone P \\ {0} (r = 0 leaves a rigid lift-off with
    u_n >= 0, u_n != 0: the lineality is factored out), so it bounds r_n,i <= 1 and
    s u_n,i <= 1 on the cone's section: both big-M constants (1) are valid, none cuts a
    solution off. A trivial lift-off has sum r_n = 0; a wedged configuration exists iff
    the optimum is > 0. s > 0 weighs u_n against r (numerics.Numerics.scale)."""
    from scipy.optimize import Bounds, LinearConstraint, milp
    U, R = param.U, param.R
    Un, Rn, Rt = U[:m], R[:m], R[m:2 * m]
    d = param.d
    zero = np.zeros((m, m))
    eye = np.eye(m)
    if math.isinf(mu):
        fr = Rn
    else:
        fr = np.vstack([mu * Rn + Rt, mu * Rn - Rt])
    fr = fr / np.maximum(np.linalg.norm(fr, axis=1, keepdims=True), 1e-300)
    un = Un / np.maximum(np.linalg.norm(Un, axis=1, keepdims=True), 1e-300)
    A = np.vstack([np.hstack([un, zero]), np.hstack([fr, np.zeros((len(fr), m))]),
                   np.hstack([Rn.sum(0) + scale * Un.sum(0), np.zeros(m)])[None, :],
                   np.hstack([Rn, -eye]), np.hstack([scale * Un, eye])])
    k = m + len(fr)
    lo = np.concatenate([np.zeros(k), [1.0], np.full(m, -np.inf), np.full(m, -np.inf)])
    hi = np.concatenate([np.full(k, np.inf), [1.0], np.zeros(m), np.ones(m)])
    c = np.concatenate([-Rn.sum(0), np.zeros(m)])
    integrality = np.concatenate([np.zeros(d), np.ones(m)])
    bounds = Bounds(np.concatenate([np.full(d, -np.inf), np.zeros(m)]),
                    np.concatenate([np.full(d, np.inf), np.ones(m)]))
    options = dict(MILP_OPTIONS)
    if time_limit is not None:
        options["time_limit"] = time_limit
    with _stdout_silenced():
        res = milp(c, constraints=LinearConstraint(A, lo, hi), integrality=integrality, bounds=bounds,
                   options=options)
    nodes = int(getattr(res, "mip_node_count", 0) or 0)
    if res.status == 2:                 # P(mu) = {0} (a supported body below mu^c): no wedge
        return WedgeMilp(INFEASIBLE, 0.0, nodes)
    if res.status != 0 or res.x is None:
        return WedgeMilp(UNDECIDED, math.nan, nodes)
    value = float(-res.fun)
    if value < MILP_WEDGE_TOL:
        return WedgeMilp(INFEASIBLE, value, nodes)
    zu = res.x[d:] > 0.5
    return WedgeMilp(FEASIBLE, value, nodes, zu, ~zu)


@contextlib.contextmanager
def _stdout_silenced():
    """File descriptor 1 to /dev/null for the block: HiGHS's MIP solver prints some debug lines
    ("HighsMipSolverData::transformNewIntegerFeasibleSolution ...") with printf, past its
    output_flag, and stdout carries `hpcwedge run --json`. C's stdio buffer is flushed
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
