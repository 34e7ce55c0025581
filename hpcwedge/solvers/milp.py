"""The 2D wedge MILP (HiGHS through highspy, lp.highs_run_watched): is there a wedged configuration at
mu, one MILP over the whole pattern space (the global mu^c's MILP route, global_mu_c.py).
A stop is served within ~0.5 s: HiGHS runs in a thread of its own, watched (lp.highs_run_watched)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hpcwedge.contact.problem import Parametrization, blocks
from hpcwedge.solvers.lp import highs_instance, highs_lp, highs_run_watched, stdout_silenced
from hpcwedge.solvers.rows import Status

#: a MILP optimum sum(r_n) below this (the normalisation makes it a share in [0, 1]) is
#: no wedged configuration: HiGHS's MIP feasibility tolerance is 1e-6
MILP_WEDGE_TOL = 1e-5
#: branch-and-bound nodes one MILP may take (then UNDECIDED: global_bracket_milp hands the
#: search to the tree, whatever the machine's speed). plug2d at a 0 deg taper, m = 26, where
#: elasticity sets mu^c (0.8836): the route's MILPs took 67, 2,126 and 6,029 nodes, then
#: 126,145 (339 s) a 1 % step lower, with ~200 such steps to go; its tree route: 117 s
MILP_NODE_LIMIT = 10_000
#: HiGHS options of `wedge_milp` (presolve off: plug2d m = 40 at mu = 100, 1.8 s against
#: 4.4 s with it)
MILP_OPTIONS: dict = {"presolve": "off", "mip_max_nodes": MILP_NODE_LIMIT}
#: seconds one MILP may run by default (then UNDECIDED: global_bracket_milp hands the search
#: to the tree); a stop interrupts it sooner
MILP_TIME_LIMIT_S = 600.0


@dataclass(frozen=True)
class WedgeMilp:
    """Answer of `wedge_milp`: status FEASIBLE (a wedged configuration, pattern
    zero_u = contact, zero_r = gap), INFEASIBLE (none: the optimum share of sum r_n is
    below MILP_WEDGE_TOL) or UNDECIDED (HiGHS stopped short); value: that optimum;
    nodes: HiGHS's branch-and-bound nodes."""

    status: Status
    value: float
    nodes: int
    zero_u: np.ndarray | None = None
    zero_r: np.ndarray | None = None


def wedge_milp(param: Parametrization, m: int, mu: float, scale: float = 1.0,
               time_limit: float | None = MILP_TIME_LIMIT_S) -> WedgeMilp:
    """Is there a 2D wedged configuration at mu (mu = inf: r_t free)? One MILP, solved by
    HiGHS, over x in R^d and binaries z (z_i = 1: node i may carry
    r_n, u_n,i = 0):

        maximise sum r_n  s.t.  u_n >= 0, mu r_n +- r_t >= 0 (mu = inf: r_n >= 0),
        sum r_n + s sum u_n = 1,  r_n,i <= z_i,  s u_n,i <= 1 - z_i.

    The normalisation is positive on the cone P \\ {0} (r = 0 leaves a rigid lift-off with
    u_n >= 0, u_n != 0: the lineality is factored out), so it bounds r_n,i <= 1 and
    s u_n,i <= 1 on the cone's section: both big-M constants (1) are valid, none cuts a
    solution off. A trivial lift-off has sum r_n = 0; a wedged configuration exists iff
    the optimum is > 0. s > 0 weighs u_n against r (numerics.NumericsReport.scale).
    time_limit (seconds, None: none): HiGHS stopped there answers UNDECIDED; a stop
    (parallel.cancel) interrupts it and raises TaskCancelled."""
    U, R = param.U, param.R
    Un, (Rn, Rt) = blocks(U, m, 2)[0], blocks(R, m, 2)
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
    h = highs_instance(MILP_OPTIONS, time_limit, polled=False)
    h.passModel(highs_lp(A, lo, hi, np.concatenate([np.full(d, -np.inf), np.zeros(m)]),
                         np.concatenate([np.full(d, np.inf), np.ones(m)]), c, integrality))
    with stdout_silenced():
        status = highs_run_watched(h)
    nodes = int(h.getInfo().mip_node_count)
    if status == Status.INFEASIBLE:     # P(mu) = {0} (a supported body below mu^c): no wedge
        return WedgeMilp(Status.INFEASIBLE, 0.0, nodes)
    if status != Status.FEASIBLE:
        return WedgeMilp(Status.UNDECIDED, math.nan, nodes)
    x = np.array(h.getSolution().col_value)
    value = float(-h.getInfo().objective_function_value)
    if value < MILP_WEDGE_TOL:
        return WedgeMilp(Status.INFEASIBLE, value, nodes)
    zu = x[d:] > 0.5
    return WedgeMilp(Status.FEASIBLE, value, nodes, zu, ~zu)

