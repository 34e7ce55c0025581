"""The KKT Newton certificate of a 3D pattern's mu^c (dinkelbach.py's polish).

Newton's method on the KKT system of min mu over the active set read off a point
(smooth cones ||r_t,i|| = mu r_n,i, cones at their apex r_i = 0, active u_n >= 0 rows,
sum r_n = 1), with the multipliers started by least squares. The result is accepted
when the point satisfies every row of the pattern to POLISH3_TOL and the multipliers
have the right signs (λ >= 0 on the cones, >= 0 on the u_n rows, apex multipliers in
the dual cone): then it is a certificate that no point exists below mu* (convexity at
fixed mu), and mu* is exact to rounding. Where the active rows are dependent, signed
multipliers are sought by a small conic problem (conic.py); where no active set gives
both, signed multipliers of one and a verified point of another within BOUNDS_RTOL close
the bracket (_bounds_meet).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hpcwedge.parallel.cancel import task_tick
from hpcwedge.solvers.conic import ConicProblem, solve
from hpcwedge.solvers.feasibility import DEFAULT_OPTIONS, SolverOptions
from hpcwedge.solvers.rows import ConeRows, Status
from hpcwedge.solvers.socp import violation

#: the polished point must satisfy every row to this (relative to ||x||)
POLISH3_TOL = 1e-12
#: a cone whose ||r_i|| is below this (relative) is at its apex in the ratio
APEX_RTOL = 1e-8
#: a multiplier above -SIGN_RTOL * (largest) counts as signed. At a degenerate
#: optimum (a cone active with a zero multiplier) the multipliers are ill-determined;
#: measured down to -4e-7 relative on plug3d 3x4 where the active set was right
SIGN_RTOL = 1e-6
#: _least_lift keeps the inactive u_n rows this far (a factor on the least lift) inside
LIFT_MARGIN = 2.0
#: a signed certificate's mu and a verified point's may close a bracket this narrow (relative)
BOUNDS_RTOL = 1e-12
#: Newton gives up when ||F|| has not fallen below STALL_RATIO times its value STALL_STEPS
#: iterations before. On plug3d 3 x 6 (mu = 1) every one of the 260 runs that never
#: converged ran all 40 iterations at ||F|| ~ 0.03-1 (7.3 of the mu^c stage's ~10 s), while
#: the 371 that converged never kept more than 0.89 of ||F|| over 3 iterations
STALL_STEPS = 3
STALL_RATIO = 0.99


def kkt_polish(rows: ConeRows, x: np.ndarray, mu: float,
               taus: tuple[float, ...] = (1e-6, 1e-4, 1e-8, 1e-3, 1e-2),
               options: SolverOptions = DEFAULT_OPTIONS) -> tuple | None:
    """Newton's method on the KKT system of min mu over the active set at x (module
    doc): (mu*, support, x*, True) verified, or None. support: the cone nodes (indices
    into rows.nodes) with a positive multiplier — below mu* no point loads any of them.
    (mu*, apex nodes, x*, False): a converged point with cones at their apex whose
    multipliers could not be signed (at an apex the constraint qualification can
    fail, and KKT multipliers need not exist at a minimum); the caller settles it
    through the sub-pattern with those nodes unloaded."""
    Z = rows.Z
    w0 = Z.T @ x
    a = rows.rn @ Z                     # (c, p)
    T = rows.rt @ Z                     # (c, 2, p)
    L = rows.lin @ Z                    # (l, p)
    nrm = rows.norm @ Z                 # (p,)
    size = np.linalg.norm(w0)
    rn, rtv = a @ w0, T @ w0
    rt = np.linalg.norm(rtv, axis=1)
    rsize = np.sqrt(rn ** 2 + rt ** 2)
    tried = set()
    unsigned = None
    upper, lower = [], []               # verified points (mu, x); signed certificates (mu, support)
    for tau, apex_tau in [(t, at) for t in taus for at in (APEX_RTOL, t)]:
        task_tick()
        apex = rsize <= apex_tau * max(rsize.max(), 1e-300)
        smooth = ~apex & (rt - mu * rn >= -tau * (mu * np.abs(rn) + rt))
        lin = (L @ w0 <= tau * size) if L.shape[0] else np.zeros(0, bool)
        S, Ap, Lin = np.flatnonzero(smooth), np.flatnonzero(apex), np.flatnonzero(lin)
        # active-set steps: rows whose multiplier came out with the wrong sign (weakly
        # active, degenerate) are dropped and the system solved again; the primal
        # check of every row then tells whether dropping them was right
        for _ in range(len(S) + len(Lin)):
            key = (tuple(S), tuple(Ap), tuple(Lin))
            if key in tried or not len(S):
                break
            tried.add(key)
            # only the span V of the active rows matters to the active system: solve in
            # w = w_perp + V c (elsewhere the Jacobian is singular along every direction
            # that moves only inactive rows)
            act = np.vstack([a[S], T[S].reshape(-1, a.shape[1]), a[Ap], T[Ap].reshape(-1, a.shape[1]),
                             L[Lin], nrm[None, :]])
            _, sv, vt = np.linalg.svd(act, full_matrices=False)
            V = vt[:int((sv > 1e-12 * sv[0]).sum())].T
            w_perp = w0 - V @ (V.T @ w0)
            res = _kkt_newton(a @ V, T @ V, L @ V, nrm @ V, V.T @ w0, mu, S, Ap, Lin, options)
            if res is None:
                break
            c, mu_s, support, signed, drop_s, drop_l = res
            w = _least_lift(L, w_perp, V @ c)
            ok = violation(rows, mu_s, Z @ w) <= POLISH3_TOL
            if not ok:
                w = w_perp + V @ c
                ok = violation(rows, mu_s, Z @ w) <= POLISH3_TOL
            if ok and signed:
                return mu_s, support, Z @ w, True
            if ok and len(Ap) and unsigned is None:
                unsigned = (mu_s, support, Z @ w, False)
            if ok:
                upper.append((mu_s, Z @ w))
            elif signed:
                lower.append((mu_s, support))
            if not (len(drop_s) or len(drop_l)):
                break
            S, Lin = np.setdiff1d(S, drop_s), np.setdiff1d(Lin, drop_l)
    return _bounds_meet(upper, lower) or unsigned


def _least_lift(L: np.ndarray, w_perp: np.ndarray, w_act: np.ndarray) -> np.ndarray:
    """w_act + t w_perp with t in [0, 1] the least (times LIFT_MARGIN) at which every u_n
    row L holds at t's point (1: the point as Newton left it). w_perp moves no active row:
    it holds the inactive rows only, and is often rounding alone (w0 less its projection on
    the active rows' span: eps ||w0||, which at a point of ||x|| ~ 1e4 ||r|| puts more than
    POLISH3_TOL into the reactions: a random free body, m = 8, whose pattern of least mu^c
    went unpolished so). The caller verifies the point (the cones off the active set
    included) and falls back to t = 1."""
    if not L.shape[0]:
        return w_act
    base, lift = L @ w_act, L @ w_perp
    need = base < 0
    if np.any(need & (lift <= 0)):
        return w_act + w_perp
    t = float(np.max(-base[need] / lift[need], initial=0.0)) * LIFT_MARGIN
    return w_act + min(t, 1.0) * w_perp


def _bounds_meet(upper: list, lower: list) -> tuple | None:
    """A certificate from two halves, where no active set gives both: signed multipliers
    of a system whose point misses a dropped row (their stationarity does not depend on
    the point: below their mu no point loads their support) and a verified point of
    another, within BOUNDS_RTOL of each other. At a degenerate optimum (two cones active,
    their gradients dependent to rounding, one multiplier -8e-5 relative) plug3d 3 x 5
    gave 0.9169282418842053 signed, its point 5e-11 outside the dropped cone, and a
    verified point at 0.9169282418842644. (mu, support, x, True) or None."""
    for mu_u, x in sorted(upper, key=lambda t: t[0]):
        for mu_l, support in lower:
            if abs(mu_u - mu_l) <= BOUNDS_RTOL * mu_u:
                return mu_u, support, x, True
    return None


def _kkt_newton(a, T, L, nrm, w0, mu0, S, Ap, Lin, options, iters: int = 40):
    """Newton on F(w, mu, lam, gam, eta) = 0 (see kkt_polish); (w, mu) when it
    converges with multipliers of the right signs, else None. Gives up early when
    ||F|| stalls (STALL_RATIO over STALL_STEPS iterations): a wrong active set, whose
    system has no root."""
    p = len(w0)
    E = np.vstack([a[Ap], T[Ap, 0], T[Ap, 1], L[Lin]]) if (len(Ap) or len(Lin)) else np.zeros((0, p))
    system = _ActiveSystem(a[S], T[S], E, nrm)
    w, mu = w0 / (nrm @ w0), mu0
    _, nt, _, G = system.parts(w, mu)
    if np.any(nt <= 0):
        return None
    root = _newton(system, w, mu, *system.start_multipliers(w, G), iters)
    if root is None:
        return None
    w, mu, lam, gam, eta, F = root
    if np.abs(F).max() > 1e-11 * max(1.0, np.abs(lam).max(), abs(mu)) or not np.isfinite(mu) or mu <= 0:
        return None
    return _signed_root(system, w, mu, lam, gam, S, Ap, Lin, options)


@dataclass(frozen=True)
class _ActiveSystem:
    """The KKT system of one active set (kkt_polish), in the span of its rows: the smooth
    cones' rows aS (nS, p) and TS (nS, 2, p) (||TS_i w|| = mu aS_i w), the equality rows E
    (the apex cones' r_n, r_t1, r_t2, then the active u_n rows) and the row nrm of sum r_n.
    Unknowns (w, mu, lam, gam, eta), n = p + 1 + nS + nE + 1 of them; F = (F1 .. F5)."""

    aS: np.ndarray
    TS: np.ndarray
    E: np.ndarray
    nrm: np.ndarray

    def parts(self, w, mu):
        """(T_i w, ||T_i w||, the unit t_i, the gradients G of g_i = ||T_i w|| - mu aS_i w)."""
        Tw = np.einsum("ckp,p->ck", self.TS, w)
        nt = np.linalg.norm(Tw, axis=1)
        t = Tw / nt[:, None]
        G = np.einsum("ckp,ck->cp", self.TS, t) - mu * self.aS           # (nS, p)
        return Tw, nt, t, G

    def residual(self, w, mu, lam, gam, eta):
        """F at the point, or None where a cone's ||T_i w|| vanishes (F is not smooth there)."""
        aS, E, nrm = self.aS, self.E, self.nrm
        with np.errstate(divide="ignore", invalid="ignore"):
            Tw, nt, t, G = self.parts(w, mu)
        if np.any(nt <= 0):
            return None
        F1 = G.T @ lam + E.T @ gam + eta * nrm
        F2 = 1.0 - lam @ (aS @ w)
        F3 = nt - mu * (aS @ w)
        F4 = E @ w
        F5 = nrm @ w - 1.0
        return np.concatenate([F1, [F2], F3, F4, [F5]])

    def start_multipliers(self, w, G):
        """(lam, gam, eta) by least squares from stationarity at w (G: `parts`' gradients)."""
        p, nS, nE = len(w), len(self.aS), self.E.shape[0]
        M = np.zeros((p + 1, nS + nE + 1))
        M[:p, :nS] = G.T
        M[:p, nS:nS + nE] = self.E.T
        M[:p, -1] = self.nrm
        M[p, :nS] = self.aS @ w
        rhs = np.zeros(p + 1)
        rhs[p] = 1.0
        # sum lam_i r_n,i = 1 as a (heavily weighted) hard row: at a degenerate optimum
        # the cone gradients nearly vanish and plain least squares would shrink lam to 0
        M[p] *= 1e8
        rhs[p] *= 1e8
        y = np.linalg.lstsq(M, rhs, rcond=None)[0]
        return y[:nS], y[nS:nS + nE], y[-1]

    def jacobian(self, w, lam, nt, t, G):
        """dF / d(w, mu, lam, gam, eta) at the point (nt, t, G: `parts` there)."""
        aS, TS, E, nrm = self.aS, self.TS, self.E, self.nrm
        p, nS, nE = len(w), len(aS), E.shape[0]
        n = p + 1 + nS + nE + 1
        J = np.zeros((n, n))
        iw, imu, il, ig, ie = slice(0, p), p, slice(p + 1, p + 1 + nS), slice(p + 1 + nS, p + 1 + nS + nE), n - 1
        # the Hessian of sum lam_i ||T_i w||: sum lam_i / ||T_i w|| T_i^T (I - t_i t_i^T) T_i
        tT = np.einsum("ck,ckp->cp", t, TS)
        s_ = lam / nt
        H = np.einsum("c,ckp,ckq->pq", s_, TS, TS) - (tT.T * s_) @ tT
        J[iw, iw] = H
        J[iw, imu] = -(aS.T @ lam)
        J[iw, il] = G.T
        J[iw, ig] = E.T
        J[iw, ie] = nrm
        r2 = p                                   # row of F2
        J[r2, iw] = -(aS.T @ lam)
        J[r2, il] = -(aS @ w)
        r3 = slice(p + 1, p + 1 + nS)
        J[r3, iw] = G
        J[r3, imu] = -(aS @ w)
        r4 = slice(p + 1 + nS, p + 1 + nS + nE)
        J[r4, iw] = E
        J[n - 1, iw] = nrm
        return J


def _newton(system: _ActiveSystem, w, mu, lam, gam, eta, iters: int):
    """Newton's iterations on `system` from (w, mu, lam, gam, eta): the last point and its F,
    (w, mu, lam, gam, eta, F), or None where a cone's ||T_i w|| vanishes. Stops on a root
    (|F| <= 1e-14 of the unknowns' size), a negligible step, no acceptable trial step
    (_trial_steps), a stall (STALL_RATIO over STALL_STEPS iterations) or after `iters` iterations."""
    p, nS = len(w), len(system.aS)
    iw, imu, il = slice(0, p), p, slice(p + 1, p + 1 + nS)
    ig, ie = slice(p + 1 + nS, p + 1 + nS + system.E.shape[0]), p + 1 + nS + system.E.shape[0]
    F = system.residual(w, mu, lam, gam, eta)
    norms = []
    for _ in range(iters):
        f0 = np.linalg.norm(F)
        norms.append(f0)
        if len(norms) > STALL_STEPS and f0 > STALL_RATIO * norms[-1 - STALL_STEPS]:
            break
        _, nt, t, G = system.parts(w, mu)
        if np.any(nt <= 0):
            return None
        J = system.jacobian(w, lam, nt, t, G)
        for step, ratio in _trial_steps(J, F, f0):
            w1, mu1 = w + step[iw], mu + step[imu]
            lam1, gam1, eta1 = lam + step[il], gam + step[ig], eta + step[ie]
            F_new = system.residual(w1, mu1, lam1, gam1, eta1)
            if F_new is not None and np.linalg.norm(F_new) < ratio * f0:
                break
        else:
            break
        w, mu, lam, gam, eta = w1, mu1, lam1, gam1, eta1
        done = np.abs(F_new).max() <= 1e-14 * max(1.0, np.abs(lam).max(), abs(mu))
        small = np.abs(step).max() <= 1e-15 * max(1.0, np.abs(w).max(), abs(mu))
        F = F_new
        if done or small:
            break
    return w, mu, lam, gam, eta, F


def _signed_root(system: _ActiveSystem, w, mu, lam, gam, S, Ap, Lin, options):
    """_kkt_newton's answer at a root: (w, mu, support, True, [], []) with multipliers of the
    right signs (these or, where the active rows are dependent, others found by
    _signed_multipliers), else (w, mu, apex nodes, False, the smooth cones and u_n rows
    whose multipliers have the wrong sign)."""
    nA = len(Ap)
    # signs: cones lam >= 0; u_n rows: constraint L w >= 0 enters as E^T gam with gam <= 0;
    # apex: (gam_a, gam_t) = -(mu zeta_0, zeta_t) with zeta in the second-order cone
    support = _signed_support(lam, gam, S, Ap, nA, len(Lin), mu)
    if support is None:
        # multipliers are not unique where the active rows are dependent: look for
        # signed ones at the converged point (a small conic feasibility problem)
        _, _, _, G = system.parts(w, mu)
        y = _signed_multipliers(G, system.aS @ w, system.E, system.nrm, nA, len(Lin), mu, options)
        if y is not None:
            support = _signed_support(y[0], y[1], S, Ap, nA, len(Lin), mu)
        if support is None:
            return w, float(mu), np.asarray(Ap, dtype=int), False, S[lam < 0], Lin[gam[3 * nA:] > 0]
    return w, float(mu), support, True, S[:0], Lin[:0]


def _trial_steps(J: np.ndarray, F: np.ndarray, f0: float):
    """The steps a Newton iteration tries on J step = -F, each with the fraction of ||F||
    (f0) it must bring the residual under: the plain Newton step (LU; least squares
    where LU fails on a singular J) to 0.5; then 30 Levenberg-Marquardt steps with
    nu = min(||F||, 1) growing tenfold (Yamashita & Fukushima: a descent step even where
    the system is singular, minimisers of the ratio not isolated; quadratic convergence
    under a local error bound), each to 1."""
    try:
        step = np.linalg.solve(J, -F)
    except np.linalg.LinAlgError:
        step = None
    if step is None or not np.isfinite(step).all():
        step = np.linalg.lstsq(J, -F, rcond=None)[0]
    yield step, 0.5
    JtJ, JtF = J.T @ J, J.T @ F
    nu, eye = min(f0, 1.0), np.eye(J.shape[0])
    for _ in range(30):
        try:
            yield np.linalg.solve(JtJ + nu * eye, -JtF), 1.0
        except np.linalg.LinAlgError:
            return
        nu *= 10.0


def _signed_support(lam, gam, S, Ap, nA, nL, mu, rtol: float = SIGN_RTOL):
    """The support of the multipliers (cone nodes with lam > 0, apex nodes with
    zeta_0 > 0) when all signs are right (to rtol of their size), else None."""
    scale = max(np.abs(lam).max() if len(lam) else 0.0, np.abs(gam).max() if len(gam) else 0.0, 1e-300)
    tol = rtol * scale
    if len(lam) and lam.min() < -tol:
        return None
    if nL and gam[3 * nA:].max() > tol:
        return None
    support = list(S[lam > tol])
    if nA:
        z0 = -gam[:nA] / mu
        zt = -np.stack([gam[nA:2 * nA], gam[2 * nA:3 * nA]], axis=1)
        if np.any(np.linalg.norm(zt, axis=1) - z0 > tol):
            return None
        support += list(Ap[z0 > tol])
    return np.array(sorted(support), dtype=int)


def _signed_multipliers(G, rn, E, nrm, nA, nL, mu, options):
    """Multipliers (lam >= 0, gam) with G^T lam + E^T gam + eta nrm = 0 and
    lam . rn = 1, gam's u_n part <= 0, apex parts -(mu zeta_0, zeta_t), zeta in the
    second-order cone; found by Clarabel, accepted when the equations hold to
    1e-10 relative. None if there are none."""
    nS, p = G.shape
    # variables v = [lam (nS), nu (nL) >= 0, zeta (3 nA), eta]; gam = [-mu z0, -z1, -z2, -nu]
    nv = nS + nL + 3 * nA + 1
    Mg = np.zeros((p, nv))
    Mg[:, :nS] = G.T
    Ea, E1, E2, EL = E[:nA], E[nA:2 * nA], E[2 * nA:3 * nA], E[3 * nA:]
    Mg[:, nS:nS + nL] = -EL.T
    for k in range(nA):
        c = nS + nL + 3 * k
        Mg[:, c] = -mu * Ea[k]
        Mg[:, c + 1] = -E1[k]
        Mg[:, c + 2] = -E2[k]
    Mg[:, -1] = nrm
    row = np.zeros(nv)
    row[:nS] = rn
    Aeq = np.vstack([Mg, row[None, :]])
    beq = np.zeros(p + 1)
    beq[-1] = 1.0
    # cones: zero (p + 1) | lam, nu >= 0 | zeta in SOC(3)
    sel = np.zeros((nS + nL + 3 * nA, nv))
    sel[:nS + nL, :nS + nL] = -np.eye(nS + nL)
    for k in range(nA):
        c = nS + nL + 3 * k
        sel[nS + nL + 3 * k:nS + nL + 3 * k + 3, c:c + 3] = -np.eye(3)
    A = np.vstack([Aeq, sel])
    b = np.concatenate([beq, np.zeros(sel.shape[0])])
    sol = solve(ConicProblem(A, b, p + 1, nS + nL, nA), 0, options.tight)
    if sol.status != Status.FEASIBLE:
        return None
    v = sol.x
    if np.abs(Aeq @ v - beq).max() > 1e-10 * max(1.0, np.abs(v).max()):
        return None
    lam = v[:nS]
    nu = v[nS:nS + nL]
    z = v[nS + nL:nS + nL + 3 * nA].reshape(nA, 3)
    gam = np.concatenate([-mu * z[:, 0], -z[:, 1], -z[:, 2], -nu])
    return lam, gam
