"""Run-time checks of the float decisions, and the exact fallback (README, "Numerical
stress"; scripts/stress.py measures them).

A float enumeration can differ from exact arithmetic where rounding decides a sign:
  - a double-description zero test |a.x| within dd.CLOSE_CALL_FACTOR of its tolerance
    (dd.complementary_rays counts them: stats "close_calls");
  - a new ray computed with catastrophic cancellation (stats "cancellation" below
    dd.CANCELLATION_MIN): its rounding error reaches the zero tolerance;
  - an ill-conditioned stiffness: the parametrisation u = F r carries relative errors of
    about cond(K) eps, which reach the zero tolerance above COND_SUSPECT;
  - ill-conditioned balanced coordinates at the mu (problem.balanced's cond(T), ~ 70 /
    taper^2 on plug2d, taper in units of 10 deg) above COND_T_SUSPECT: at 0.005, 0.003 and
    0.001 deg (cond(T) 2.4e8, 6.6e8, 6e9) the float DD of plug2d rows 2 found 14 wedged rays
    and no lift-off where exact arithmetic has 12 and 4 (two of them lift-offs with r_n ~
    -3e-9 taken as wedged), with no close call seen; at 0.01 deg (5.9e7) it agrees.
Any of them makes the enumeration at that mu *suspect*. A suspect enumeration is redone in
exact rational arithmetic when m <= the scene's compute.exact_fallback_max_m (the answer
is then exact); otherwise it is kept and reported as unresolved. The 2D sign patterns of
the LP branch and bound are suspect when a found pattern's LP point is feasible only to
HiGHS's tolerance (patterns.NEAR_BOUNDARY_TOL), a solve was undecided, or K is
ill-conditioned; they are then taken from the exact rays (SPEC §2), under the same size
limit. mu^c values that are not polished and LP solves that no solver decided are
reported. Everything goes to Result.stats["numerics"] and, when something may be
inexact, to a warning line.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from hpcwedge.contact.problem import ContactProblem, Parametrization, balanced, friction_rows_2d, stiffness_range
from hpcwedge.rays.cones import implied_patterns
from hpcwedge.rays.dd import CANCELLATION_MIN, FLOAT_ZERO_TOL, DDResult, complementary_rays

#: cond(K on range K) above this makes a float enumeration suspect: relative errors of
#: cond * eps in u reach the DD's zero tolerance
COND_SUSPECT = FLOAT_ZERO_TOL / float(np.finfo(float).eps)
#: cond(T) of the balanced coordinates above this makes a float enumeration suspect (module doc)
COND_T_SUSPECT = 1e8


@dataclass
class NumericsReport:
    """What the run-time checks found (the stats["numerics"] entry, see as_dict).

    lam_min, lam_max: problem.stiffness_range(problem); runs: one record per enumerated mu
    ({"mu", "exact", "suspect", and for a float DD "close_calls", "closest",
    "cancellation" (dd stats), "cond_T" (problem.balanced)}); exact_fallback /
    unresolved: the mu values redone exactly / left suspect; patterns: the 2D sign
    patterns' check (recheck_patterns_2d); notes: other findings (mu^c not polished,
    undecided solves, suspect patterns left as they are), each one line; cond_suspect:
    the stiffness condition number above which every float run is suspect."""

    lam_min: float
    lam_max: float
    fallback_max_m: int
    runs: list = field(default_factory=list)
    exact_fallback: list = field(default_factory=list)
    unresolved: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    patterns: dict | None = None
    cond_suspect: float = COND_SUSPECT

    @classmethod
    def of(cls, problem: ContactProblem, fallback_max_m: int) -> "NumericsReport":
        """The record of a problem, before any check has run."""
        return cls(*stiffness_range(problem), fallback_max_m)

    @property
    def cond(self) -> float:
        """cond(K) on range(K) (inf if the smallest eigenvalue there is not positive)."""
        return self.lam_max / self.lam_min if self.lam_min > 0 else float("inf")

    @property
    def scale(self) -> float:
        """The stiffness that weighs u_n against r in the float DD (problem.balanced)."""
        return float(np.sqrt(self.lam_min * self.lam_max)) if self.lam_min > 0 else self.lam_max

    def as_dict(self) -> dict:
        """The stats["numerics"] entry (JSON-ready); flagged: something was redone exactly,
        left unresolved or noted."""
        cond = self.cond
        return {"flagged": bool(self.exact_fallback or self.unresolved or self.notes),
                "stiffness_cond": cond if np.isfinite(cond) else None,      # None: singular
                "exact_fallback": self.exact_fallback,
                "unresolved": self.unresolved, "notes": self.notes, "runs": self.runs,
                "patterns": self.patterns}

    def warnings(self) -> list[str]:
        """One line per finding that leaves the answer possibly inexact."""
        out = []
        if self.unresolved:
            mus = ", ".join(f"{mu:g}" for mu in self.unresolved)
            out.append(f"warning: float enumeration at mu = {mus} made decisions too close to call "
                       f"(stiffness cond {self.cond:.1e}) and m > compute.exact_fallback_max_m = "
                       f"{self.fallback_max_m}: counts may differ from exact arithmetic "
                       "(stats.numerics; rerun with compute.exact = true)")
        out += [f"warning: {n}" for n in self.notes]
        return out


def checked_rays_2d(param: Parametrization, m: int, mu: float, numerics: NumericsReport,
                    exact_param: Callable[[], Parametrization], progress=None) -> tuple[DDResult, Parametrization]:
    """Complementary rays of P(mu) and the parametrisation they are expressed in.

    param exact (param.exact): the exact DD. Otherwise the float DD in balanced
    coordinates (problem.balanced), judged by `settle_rays_2d`. Appends the mu's
    record to numerics."""
    if param.exact:
        return settle_rays_2d(exact_rays(param, m, mu, progress), param, None, m, mu, numerics, exact_param)
    p_mu, cond_T, _ = balanced(param, mu, m, numerics.scale)
    dd = complementary_rays(friction_rows_2d(p_mu, mu, m), m, progress=progress)
    return settle_rays_2d(dd, p_mu, cond_T, m, mu, numerics, exact_param, progress)


def settle_rays_2d(dd: DDResult, p_mu: Parametrization, cond_T: float, m: int, mu: float,
                   numerics: NumericsReport, exact_param: Callable[[], Parametrization], progress=None) -> tuple[DDResult, Parametrization]:
    """A float DD of P(mu) run in the balanced coordinates p_mu (whole, or merged
    over faces): if it is suspect (module doc) and m <= numerics.fallback_max_m,
    the exact DD on exact_param() instead (called at most when needed; the caller
    caches it); suspect beyond that: recorded as unresolved. An exact DD (p_mu
    exact) is taken as it is. Appends the mu's record to numerics; returns (rays,
    the parametrisation they are expressed in)."""
    if p_mu.exact:
        numerics.runs.append({"mu": mu, "exact": True, "suspect": False})
        return dd, p_mu
    st = dd.stats
    suspect = (st["close_calls"] > 0 or st["cancellation"] < CANCELLATION_MIN
               or numerics.cond > numerics.cond_suspect
               or (cond_T is not None and cond_T > COND_T_SUSPECT))
    record = {"mu": mu, "exact": False, "suspect": suspect, "close_calls": st["close_calls"],
              "closest": st["closest"], "cancellation": st["cancellation"], "cond_T": cond_T}
    numerics.runs.append(record)
    if not suspect:
        return dd, p_mu
    if m > numerics.fallback_max_m:
        numerics.unresolved.append(mu)
        return dd, p_mu
    pq = exact_param()
    dd = exact_rays(pq, m, mu, progress)
    record["exact"] = True
    numerics.exact_fallback.append(mu)
    return dd, pq


#: a listed mu this close above a cone's mu^c (relative) has that cone's rays nearly parallel
NEAR_MU_C_RTOL = 1e-9


def note_near_mu_c(numerics: NumericsReport, runs) -> None:
    """Note the float runs (2D rays) whose mu lies within NEAR_MU_C_RTOL above the mu^c of
    one of their cones: there the cone is a sliver whose extreme rays floating point can
    merge with no close call seen (plug2d at tan 10 deg (1 + 1e-11): 1 wedged ray, exact
    arithmetic 8); runs: pipeline Runs with cones and their mu^c."""
    exact = {r["mu"] for r in numerics.runs if r.get("exact")}
    near = [run.mu for run in runs if run.cones and run.mu not in exact
            and any(c.mu_c is not None and run.mu <= c.mu_c * (1 + NEAR_MU_C_RTOL) for c in run.cones)]
    if near:
        numerics.notes.append(f"mu = {', '.join(f'{mu:.17g}' for mu in near)} lies within "
                              f"{NEAR_MU_C_RTOL:g} above a cone's mu^c: its rays there are nearly parallel and "
                              "floating point may merge them (ray counts possibly short; compute.exact = "
                              "true decides them)")


#: a pattern feasible at a mu this far (relative) below its own polished mu^c was feasible to the
#: solver's tolerance only: the polished mu^c (certified to ~1e-15) decides
BELOW_MU_C_RTOL = 1e-12


def drop_below_mu_c(numerics: NumericsReport, runs) -> None:
    """Drop from each run (pipeline Runs) the sign patterns whose polished mu^c lies more than
    BELOW_MU_C_RTOL above the run's mu, with a note naming the mu and the count: the pattern
    problem's point verified to socp.VERIFY_TOL there (plug3d ring 3 at tan 10 deg (1 - 1e-8)
    listed its all-contact pattern, whose certified mu^c is tan 10 deg), but no pattern is
    feasible below its mu^c."""
    dropped = []
    for run in runs:
        if not run.patterns:
            continue
        keep = [p for p in run.patterns if not (p.mu_c is not None and p.mu_c_polished
                                                and run.mu < p.mu_c * (1 - BELOW_MU_C_RTOL))]
        if len(keep) < len(run.patterns):
            dropped.append(f"{len(run.patterns) - len(keep)} at mu = {run.mu:.17g}")
            run.patterns = keep
    if dropped:
        numerics.notes.append(f"sign patterns feasible only to the solver's tolerance below their own "
                              f"certified mu^c, not listed: {'; '.join(dropped)}")


def note_mu_c(numerics: NumericsReport, unpolished: int, undecided: int) -> None:
    """Record mu^c values left unpolished and LP solves no solver decided."""
    if unpolished:
        numerics.notes.append(f"{unpolished} mu^c value(s) not polished: upper bounds, a bisection "
                              "bracket's end (1e-7 relative where its solves were decided; looser where "
                              "solves were undecided, taken as feasible) or a 3D point not certified "
                              "(mu_c_polished = false in the result, marked by show)")
    if undecided:
        numerics.notes.append(f"{undecided} LP solve(s) of the mu^c stage undecided by every solver "
                              "(taken as feasible)")


def exact_rays(pq: Parametrization, m: int, mu: float, progress=None) -> DDResult:
    """The exact DD of P(mu) on an exact parametrisation."""
    return complementary_rays(friction_rows_2d(pq, mu, m, exact=True), m, exact=True, progress=progress)


def recheck_patterns_2d(numerics: NumericsReport, m: int, mus, near: int, undecided: int,
                        undecided_solves: int, exact_param: Callable[[], Parametrization],
                        exact_scene: bool) -> list[set[tuple[int, ...]]] | None:
    """The 2D sign patterns per mu from the exact rays (SPEC §2), when the LP branch and
    bound's are suspect (module doc; near: its LP points feasible only to HiGHS's tolerance,
    undecided: patterns no solver decided, undecided_solves: its solves no solver decided)
    and m <= the fallback limit, or the scene asks for exact arithmetic.
    None: keep the branch and bound's (a suspect one is noted)."""
    near = int(near)
    suspect = bool(near or undecided or undecided_solves or numerics.cond > numerics.cond_suspect)
    numerics.patterns = {"suspect": suspect, "near_boundary": near, "undecided": undecided,
                         "exact": False}
    if not (suspect or exact_scene):
        return None
    if not exact_scene and m > numerics.fallback_max_m:
        numerics.notes.append(f"2D sign patterns: {near} found near the LP tolerance, {undecided} undecided, "
                              f"stiffness cond {numerics.cond:.1e}; m > compute.exact_fallback_max_m = "
                              f"{numerics.fallback_max_m}: not redone in exact arithmetic")
        return None
    numerics.patterns["exact"] = True
    pq = exact_param()
    out = []
    for mu in mus:
        dd = exact_rays(pq, m, mu)
        out.append(implied_patterns(dd.zero[dd.wedged()], m))
    return out
