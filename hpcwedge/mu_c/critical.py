"""mu^c of one sign pattern (cone), to 1e-9 relative (SPEC §2): the result type `MuC` and
the dispatch by dimension.

2D: mu_bracket.py (bisection on LP feasibility, then the pencil polish). 3D: dinkelbach.py
(Dinkelbach iterations, then the KKT Newton certificate of kkt.py). Both, given a scale, in
coordinates balanced at the mu^c (problem.balanced; 3D: plug3d 2 x 5 at a 0.1 deg taper,
every pattern's mu^c polished in 382 SOCPs, none undecided, against 0 of 41 polished in
4,911 SOCPs, 530 undecided, and the global value 4.6e-9 off in the plain coordinates). Route "bisection" (both): plain bisection to
the scene's mu_c_tol, the upper end of the bracket returned (benchmarks). The global
mu^c over all patterns: global_mu_c.py.

Every iteration calls parallel.task_tick(): inside an engine task a SIGTERM (or the
master's stop) cancels the computation within one solve; the task is redone on resume.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from hpcwedge.contact.problem import Parametrization, balanced
from hpcwedge.mu_c.bracket import Probe, bracket_2d
from hpcwedge.mu_c.dinkelbach import mu_critical_3d
from hpcwedge.parallel.engine import Engine
from hpcwedge.parallel.jobs import TaskJob
from hpcwedge.solvers.feasibility import DEFAULT_OPTIONS, SolverOptions
from hpcwedge.solvers.rows import Rows, pattern_rows, problem_dim

#: with a scale (2D and 3D): mu^c is recomputed in coordinates balanced at it when it lies
#: below mu_hi / REBALANCE (the first coordinates were balanced at mu_hi)
REBALANCE = 10.0
#: ... starting from the bracket mu^c (1 -/+ this) around the first value
REBALANCE_BRACKET = 1e-6


@dataclass
class MuC:
    """mu_c: float or None (infeasible up to mu_max); polished: the pencil (2D) or
    KKT (3D) step verified; solves: LP/SOCP solves; undecided: statuses that decided
    nothing; statuses: how each solve was decided (feasibility.decide counts)."""

    mu_c: float | None
    polished: bool = False
    solves: int = 0
    undecided: int = 0
    statuses: dict = field(default_factory=dict)
    x: np.ndarray | None = None          # 3D polished: the point at mu^c (x-space, sum r_n = 1)


def mu_critical(param: Parametrization, m: int, zero_u: np.ndarray, zero_r: np.ndarray,
                mu_hi: float | None = None, mu_max: float = 100.0,
                method: str = "accurate", tol: float = 1e-6, scale: float | None = None,
                options: SolverOptions = DEFAULT_OPTIONS, mu_floor: float | None = None,
                mu_try: float | None = None, x_try: np.ndarray | None = None) -> MuC:
    """Least mu at which the pattern (zero_u, zero_r) admits a solution with r != 0.

    mu_hi: a mu known feasible (e.g. the run's mu for a cone found there); else
    mu_max is tested first. Returns MuC(None) when infeasible at mu_max.
    mu_floor (2D): a mu at which no wedge exists by a certificate (lower_bound.rigid_bound),
    the bracket's lower end without an LP; mu_try (2D): a guess of a feasible mu just above
    mu^c, asked first (bracket_2d; 3D: not used); x_try (2D): a point (param's coordinates,
    sum r_n = 1) believed feasible at mu_try, checked there instead of an LP. With a scale
    the first coordinates are balanced at mu_try, else mu_hi, else mu_max.
    scale: the stiffness that weighs u_n against r (numerics.NumericsReport.scale). The
    LPs (2D) or SOCPs (3D) then run in the balanced coordinates of problem.balanced at
    mu_hi, and once more at the mu^c found when it lies below mu_hi / REBALANCE
    (scripts/stress.py: plug2d at 0.1 deg, mu^c to 3e-13 instead of 8e-9 relative).
    """
    if problem_dim(param, m) == 3:
        return _mu_critical_3d(param, m, zero_u, zero_r, mu_hi, mu_max, method, tol, scale, options)
    if scale is None:
        return mu_critical_rows(pattern_rows(param, m, zero_u, zero_r), mu_hi, mu_max, method, tol, options=options,
                                mu_floor=mu_floor, mu_try=mu_try, x_try=x_try)

    def solve(ref: float, hi: float | None, lo: float | None = None, guess: float | None = None,
              witness: np.ndarray | None = None) -> MuC:
        p, _, T = balanced(param, ref, m, scale, cond=False)
        return mu_critical_rows(pattern_rows(p, m, zero_u, zero_r), hi, mu_max, method, tol, mu_lo=lo,
                                options=options, mu_floor=mu_floor, mu_try=guess,
                                x_try=None if witness is None else T @ witness)

    ref = mu_try if mu_try is not None else mu_max if mu_hi is None else mu_hi
    out = solve(ref, mu_hi, guess=mu_try, witness=x_try)
    if out.mu_c is None or method != "accurate" or ref / REBALANCE < out.mu_c < ref * REBALANCE:
        return out
    again = solve(out.mu_c, out.mu_c * (1 + REBALANCE_BRACKET), out.mu_c * (1 - REBALANCE_BRACKET))
    if again.mu_c is None or not again.polished:
        # balanced that far above it (ref / mu^c ~ 1e6 and more), the first value can be off
        # by more than the bracket (plug2d at mu_max = 1e6: 2.8e-4 below mu^c): the whole
        # search again, in coordinates balanced at it
        wide = solve(out.mu_c, mu_hi)
        add_counts(wide, again)
        again = wide
    best = again if again.mu_c is not None and (again.polished or not out.polished) else out
    add_counts(best, again if best is out else out)
    return best


def _mu_critical_3d(param: Parametrization, m: int, zero_u, zero_r, mu_hi: float | None, mu_max: float,
                    method: str, tol: float, scale: float | None, options: SolverOptions) -> MuC:
    """mu_critical in 3D: dinkelbach.mu_critical_3d, with a scale in coordinates balanced at
    mu_hi (problem.balanced), and once more at the mu^c found when it lies below mu_hi /
    REBALANCE (as 2D). The point x is returned in param's coordinates."""
    def solve(ref: float | None, hi: float | None) -> MuC:
        p, _, T = (param, None, None) if ref is None else balanced(param, ref, m, scale, cond=False)
        probe = Probe(options)
        out = _result(probe, *mu_critical_3d(p, m, zero_u, zero_r, pattern_rows(p, m, zero_u, zero_r), probe,
                                             hi, mu_max, method, tol))
        if T is not None and out.x is not None:
            out.x = sla.solve_triangular(T, out.x)
        return out

    if scale is None:
        return solve(None, mu_hi)
    ref = mu_max if mu_hi is None else mu_hi
    out = solve(ref, mu_hi)
    if out.mu_c is None or method != "accurate" or out.mu_c * REBALANCE > ref:
        return out
    # the 3D brackets are upper bounds (dinkelbach.bracket_3d): mu^c (1 + bracket) is feasible
    again = solve(out.mu_c, out.mu_c * (1 + REBALANCE_BRACKET))
    best = again if again.mu_c is not None and (again.polished or not out.polished) else out
    add_counts(best, again if best is out else out)
    return best


def add_counts(into, other: MuC) -> None:
    """Add the decisions counted in `other` (solves, undecided, statuses) to `into`'s (a
    MuC, or anything counting them alike: patterns.BnBStats)."""
    into.solves += other.solves
    into.undecided += other.undecided
    for k, v in other.statuses.items():
        into.statuses[k] = into.statuses.get(k, 0) + v


def mu_critical_rows(rows: Rows, mu_hi: float | None = None, mu_max: float = 100.0,
                     method: str = "accurate", tol: float = 1e-6, mu_lo: float | None = None,
                     options: SolverOptions = DEFAULT_OPTIONS, mu_floor: float | None = None,
                     mu_try: float | None = None, x_try: np.ndarray | None = None) -> MuC:
    """mu^c of an LP pattern problem given by its rows (2D patterns; also any
    polyhedral problem of the same form, e.g. a 3D pattern with pyramids):
    mu_bracket.bracket_2d, counted."""
    probe = Probe(options)
    mu_c, polished = bracket_2d(rows, probe, mu_hi, mu_max, method, tol, mu_lo, mu_floor, mu_try, x_try)
    return _result(probe, mu_c, polished)


def _result(probe: Probe, mu_c: float | None, polished: bool, x: np.ndarray | None = None) -> MuC:
    """The MuC of a computation whose decisions `probe` counted."""
    return MuC(mu_c, polished, probe.solves, probe.undecided, probe.statuses, x)


# ---------------------------------------------------------------- the "mu_c" task of the engine


def mu_c_task(solve, payload) -> dict:
    """Task "mu_c": payload (zero_u, zero_r, mu_hi) -> MuC fields (mu_c NaN = None; lps: its
    solves; pyramid_lps: the pyramid LPs among its statuses, "lp_calls"; statuses: all of
    them, JSON bytes)."""
    zero_u, zero_r, mu_hi = payload
    r = solve(np.asarray(zero_u, dtype=bool), np.asarray(zero_r, dtype=bool), mu_hi=mu_hi)
    return {"mu_c": np.nan if r.mu_c is None else float(r.mu_c), "polished": bool(r.polished),
            "lps": int(r.solves), "undecided": int(r.undecided),
            "pyramid_lps": int(r.statuses.get("lp_calls", 0)),
            "statuses": json.dumps(r.statuses, sort_keys=True).encode()}


def run_mu_c(solve, items, engine: Engine | None = None, name: str = "mu_c") -> list:
    """mu^c of every (zero_u, zero_r, mu_hi) in `items`, through the engine (no job when
    items is empty).

    solve: a picklable callable solve(zero_u, zero_r, mu_hi=...) -> MuC,
    e.g. functools.partial(mu_critical, param, m, mu_max=..., method=..., tol=...).
    Returns the MuC list in the order of items, with their statuses (a checkpoint of an
    older version holds only "lp_calls", the pyramid LPs, or none); the job's counters
    (stats.parallel.jobs) get their sums as "status_<status>" and "undecided"."""
    if not items:
        return []
    engine = engine or Engine()
    payloads = [(np.asarray(zu, dtype=bool), np.asarray(zr, dtype=bool), float(mu_hi))
                for zu, zr, mu_hi in items]
    job = engine.run(TaskJob(name, mu_c_task, solve, payloads, kind="mu_c"))
    out = [MuC(mu_c=None if math.isnan(r["mu_c"]) else float(r["mu_c"]), polished=bool(r["polished"]),
               solves=int(r["lps"]), undecided=int(r["undecided"]), statuses=_statuses(r)) for r in job.output()]
    total = MuC(None)
    for r in out:
        add_counts(total, r)
    # set, not added: a resumed job's counters come back from its checkpoint
    job.counters.update({"solves": total.solves, "undecided": total.undecided,
                         **{f"status_{k}": v for k, v in sorted(total.statuses.items())}})
    return out


def _statuses(r: dict) -> dict:
    """A mu_c task's statuses (mu_c_task) as a dict, from a result of any version."""
    if r.get("statuses") is not None:
        text = r["statuses"]
        return json.loads(text.decode() if isinstance(text, bytes) else str(text))
    return {"lp_calls": int(r["pyramid_lps"])} if r.get("pyramid_lps") else {}
