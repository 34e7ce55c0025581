"""The one decision policy: is a pattern problem feasible at mu? (`decide`)

2D / LP (`rows.Rows`): HiGHS's dual simplex (lp.py); if it gives up, its interior point
method.

3D (`rows.ConeRows`), every outcome counted:
  1. Clarabel, default tolerances (socp.py). Solved -> the returned x is verified (every
     row to socp.VERIFY_TOL relative to the size of x); PrimalInfeasible -> its
     certificate is verified (A^T z = 0, b^T z < 0, z in the dual cone, to
     socp.CERT_TOL). A verified answer is definitive.
  2. Anything else (Almost*, MaxIterations, NumericalError, InsufficientProgress,
     or a verification that failed): the next attempts of socp's ladder (the least-norm
     point; static regularisation; Clarabel's defaults with equilibration).
  3. Still unsure: LPs on polyhedral pyramids of the friction cones with
     k = 16, 64, 256 facets per node — inner (inscribed: feasible ⇒ feasible,
     its x verified on the circular cones) and outer (circumscribed:
     infeasible ⇒ infeasible), PYRAMID_BUDGET_S seconds for all of them.
  4. Still unsure: UNDECIDED (callers keep the subtree / report the pattern as
     undecided; nothing is pruned on doubt).

Solver options are a value (`SolverOptions`) handed down by the caller.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from hpcwedge.parallel.cancel import task_tick
from hpcwedge.solvers.lp import LP_OPTIONS, lp_feasible
from hpcwedge.solvers.rows import ZERO_ROW_RTOL, ConeRows, Rows, Status, count, pyramid_rows
from hpcwedge.solvers.socp import pattern_attempts, verified

#: facets per node of the polyhedral pyramids, tried in turn
PYRAMID_SIDES = (16, 64, 256)
#: seconds the pyramid LPs of one decision may take in all (then UNDECIDED, counted as
#: "pyramid_budget_spent"): at m = 64 the 256-facet pyramid is an LP of 16,384 dense rows that
#: HiGHS worked on for minutes (plug3d 8 x 8 near mu^c; the curved neck 8 x 8's settling tree),
#: and an undecided node only keeps its subtree
PYRAMID_BUDGET_S = 10.0


@dataclass(frozen=True)
class SolverOptions:
    """tolerances: "default", or "tight" (Clarabel's feasibility and gap tolerances 1e-10
    on every attempt; the LPs always run at LP_OPTIONS' 1e-10) — for benchmarks of run
    time against error. long_steps: Clarabel's first attempt takes long interior-point
    steps (conic.settings), for problems away from their mu^c (TREE_OPTIONS)."""

    tolerances: str = "default"
    long_steps: bool = False

    def __post_init__(self):
        if self.tolerances not in ("default", "tight"):
            raise ValueError(f"solver tolerances: 'default' or 'tight', got {self.tolerances!r}")

    @property
    def tight(self) -> bool:
        return self.tolerances == "tight"


#: the options of every run (the product never changes them)
DEFAULT_OPTIONS = SolverOptions()
#: the options of the enumeration tree's solves (patterns.PatternTree)
TREE_OPTIONS = SolverOptions(long_steps=True)


@dataclass
class Decision:
    """One feasibility decision. status; x: a verified point (sum r_n = 1) when feasible;
    positive: the objective given to `decide` is proven > 0 on the whole feasible set (by
    a verified dual), i.e. the problem with the extra equality objective . x = 0 is
    infeasible."""

    status: Status
    x: np.ndarray | None = None
    positive: bool = False


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


def decide(rows: Rows | ConeRows, mu: float, options: SolverOptions = DEFAULT_OPTIONS,
           counts: dict | None = None, *, objective: np.ndarray | None = None,
           pyramid_sides: tuple[int, ...] = PYRAMID_SIDES) -> Decision:
    """Feasibility of the pattern problem at mu (module doc), x normalised to sum r_n = 1.
    counts (optional) accumulates how each problem was decided. objective (x-space, 3D only,
    ignored for LPs): minimised over the feasible set: the branch and bound passes the next
    node's u_n row, so that the returned x lies on u_n = 0 when the contact child is
    feasible (the skip-solve rule then takes it), and `positive` proves the contact child
    infeasible when it is not. pyramid_sides: the levels of the pyramid LP fallback (step 3),
    e.g. pyramid_sides_for(spread)."""
    if isinstance(rows, Rows):
        status, x = lp_feasible(rows, mu, LP_OPTIONS, counts=counts)
        count(counts, "lp_" + status)
        if status == Status.UNDECIDED:          # HiGHS's simplex gave up: its interior point method
            status, x = lp_feasible(rows, mu, LP_OPTIONS, method="ipm", counts=counts)
            count(counts, "lp_retry_ipm_" + status)
        return Decision(status, x)
    if rows.nodes.size == 0:
        count(counts, "eq_infeasible")          # every node in gap: sum r_n = 0
        return Decision(Status.INFEASIBLE)
    # retries are plain feasibility problems (an optimum on the boundary is the first thing
    # to miss a verification)
    for o in pattern_attempts(rows, mu, options.tight, objective, options.long_steps):
        tag = f"retry{o.attempt}_" if o.attempt else ""
        count(counts, tag + o.name)
        if o.certified is not None:
            if o.certified:
                return Decision(Status.INFEASIBLE)
            count(counts, tag + "certificate_failed")
        elif o.x is not None:
            x = verified(rows, mu, o.x)
            if x is not None:
                return Decision(Status.FEASIBLE, x, o.positive)
            count(counts, tag + "verify_failed")
        if o.attempt == 0 and (rows.Z.shape[1] == 0 or np.abs(rows.norm @ rows.Z).max()
                               <= ZERO_ROW_RTOL * np.linalg.norm(rows.norm)):
            # before the retries in the null space of the equalities: sum r_n vanishes there
            count(counts, "eq_infeasible")
            return Decision(Status.INFEASIBLE)
    deadline = time.monotonic() + PYRAMID_BUDGET_S
    for sides in pyramid_sides:
        task_tick()              # a fine pyramid's LPs take up to a second or so: a stop acts here
        if time.monotonic() >= deadline:
            count(counts, "pyramid_budget_spent")
            break
        status, x = lp_feasible(pyramid_rows(rows, sides, inner=True), mu, LP_OPTIONS, counts=counts,
                                deadline=deadline)
        count(counts, "lp_calls")
        x = verified(rows, mu, x) if status == Status.FEASIBLE else None
        if x is not None:
            count(counts, "pyramid_inner_feasible")
            return Decision(Status.FEASIBLE, x)
        status, _ = lp_feasible(pyramid_rows(rows, sides, inner=False), mu, LP_OPTIONS, counts=counts,
                                deadline=deadline)
        count(counts, "lp_calls")
        if status == Status.INFEASIBLE:
            count(counts, "pyramid_outer_infeasible")
            return Decision(Status.INFEASIBLE)
    count(counts, "undecided")
    return Decision(Status.UNDECIDED)
