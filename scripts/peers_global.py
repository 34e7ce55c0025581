#!/usr/bin/env python3
"""The global mu^c by a general-purpose solver (issue 41's peers), one scene, one peer.

The peer decides issue 13's feasibility problem at fixed mu: x in the parametrisation,
u_n >= 0, the friction cones (2D: |r_t| <= mu r_n; 3D: ||r_t|| <= mu r_n, second-order),
sum r_n = 1, a binary z_i per node with r_n,i <= z_i and the indicator z_i = 1 => u_n,i <= 0
(z is the contact set); the global mu^c is the least mu at which it is feasible, found by
bisection on (0, MU_MAX] to BISECT_RTOL relative (the bracket's upper end, as
scripts/bench_global_mu_c.py's "scip_bisect"). Peers:

  scip    SCIP (pyscipopt) on reference.scip_model (its MISOCP / MILP)
  gurobi  Gurobi (gurobipy, 1 thread) on the same model, built here (`gurobi_model`): a
          benchmark-only peer whose pip licence is size-limited (GUROBI_MAX variables and
          constraints; GUROBI_MAX_QUADRATIC variables with the 3D cones); a larger model is
          reported "too large" before it is built

Every solve gets the time left of `--limit` (counted from the start of this process); one
that ends undecided stops the bisection ("timeout", the bracket so far kept). Prints one
JSON object (stdout): status ("ok", "timeout", "too large", "missing"), mu_c (the bracket's
upper end; None without a wedge up to MU_MAX), mu_lo / mu_hi (the bracket), seconds,
milp_solves, milp_nodes (the solver's branch-and-bound nodes, summed), undecided, and the model's n_vars / n_cons.

    PYTHONPATH=. python scripts/peers_global.py {scip,gurobi} SCENE.toml [--limit 200]
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

MU_MAX = 100.0
BISECT_RTOL = 1e-6
#: the pip licence of gurobipy: at most this many variables and this many constraints, and
#: with quadratic constraints (the 3D cones) at most GUROBI_MAX_QUADRATIC variables (measured:
#: plug3d 4 x 8, 223 variables, refused with error 10010)
GUROBI_MAX, GUROBI_MAX_QUADRATIC = 2000, 200
PEERS = ("scip", "gurobi")


class OutOfTime(Exception):
    """A peer's solve ended without deciding (its time limit)."""


class TooLarge(Exception):
    """Gurobi refused the model: larger than its licence allows (error 10010)."""


def model_size(param, m: int) -> tuple[int, int]:
    """(variables, constraints) of the peer model: x (d), z (m) and in 3D the cone's
    (r_n, r_t1, r_t2) per node (3m); u_n >= 0, the friction rows (2D: 2 per node; 3D: 3
    definitions and 1 cone per node), r_n <= z, the indicator (1 per node), sum r_n = 1."""
    dim = param.U.shape[0] // m
    n_vars = param.d + m + (3 * m if dim == 3 else 0)
    n_cons = m * (1 + (2 if dim == 2 else 4) + 1 + 1) + 1
    return n_vars, n_cons


def _linear(gp, row, x):
    nz = np.flatnonzero(row)
    return gp.LinExpr([float(row[j]) for j in nz], [x[j] for j in nz])


def gurobi_model(param, m: int, mu: float, time_limit: float):
    """The peer model in gurobipy at mu (the module doc), one thread, quiet, `time_limit` s
    with its building."""
    import gurobipy as gp
    start = time.perf_counter()
    U, R, d = param.U, param.R, param.d
    dim = U.shape[0] // m
    env = gp.Env(params={"OutputFlag": 0})
    model = gp.Model(env=env)
    model.Params.Threads = 1
    x = model.addVars(d, lb=-gp.GRB.INFINITY, name="x")
    z = model.addVars(m, vtype=gp.GRB.BINARY, name="z")
    for i in range(m):
        un, rn = _linear(gp, U[i], x), _linear(gp, R[i], x)
        model.addConstr(un >= 0)
        if dim == 2:
            rt = _linear(gp, R[m + i], x)
            model.addConstr(mu * rn + rt >= 0)
            model.addConstr(mu * rn - rt >= 0)
        else:
            n_ = model.addVar(lb=0.0)
            t1, t2 = model.addVar(lb=-gp.GRB.INFINITY), model.addVar(lb=-gp.GRB.INFINITY)
            model.addConstr(n_ == rn)
            model.addConstr(t1 == _linear(gp, R[m + i], x))
            model.addConstr(t2 == _linear(gp, R[2 * m + i], x))
            model.addQConstr(t1 * t1 + t2 * t2 <= (mu * mu) * n_ * n_)     # n_ >= 0: a cone
        model.addConstr(rn <= z[i])
        model.addGenConstrIndicator(z[i], True, un <= 0)
    model.addConstr(_linear(gp, R[:m].sum(0), x) == 1)
    model.Params.TimeLimit = max(time_limit - (time.perf_counter() - start), 0.0)
    return model


def gurobi_wedged(param, m: int, mu: float, counts: dict, time_limit: float) -> bool:
    """Gurobi on gurobi_model at mu: feasible? Counts milp_solves and milp_nodes; OutOfTime when it
    ends undecided, TooLarge when the licence refuses the model."""
    import gurobipy as gp
    try:
        model = gurobi_model(param, m, mu, time_limit)
        model.optimize()
    except gp.GurobiError as e:         # the size check missed a limit of the licence
        if e.errno == 10010:
            raise TooLarge(str(e)) from e
        raise
    counts["milp_solves"] += 1
    counts["milp_nodes"] += int(model.NodeCount)
    status = model.Status
    model.dispose()
    if status in (gp.GRB.OPTIMAL, gp.GRB.SUBOPTIMAL):
        return True
    if status == gp.GRB.INFEASIBLE:
        return False
    counts["undecided"] += 1
    raise OutOfTime(f"gurobi status {status}")


def scip_wedged(param, m: int, mu: float, counts: dict, time_limit: float) -> bool:
    """SCIP on reference.scip_model at mu, `time_limit` s: feasible? OutOfTime when undecided."""
    from hpcwedge.reference import scip_status
    status = scip_status(param, m, mu, counts, time_limit)
    if status in ("optimal", "infeasible"):
        return status == "optimal"
    counts["undecided"] += 1
    raise OutOfTime(f"scip status {status}")


def peer_mu_c(peer: str, param, m: int, limit: float, start: float) -> dict:
    """The peer's global mu^c by bisection (the module doc) within `limit` s of `start`
    (time.perf_counter)."""
    counts = {"milp_solves": 0, "milp_nodes": 0, "undecided": 0}
    wedged = gurobi_wedged if peer == "gurobi" else scip_wedged
    lo, hi = 0.0, MU_MAX
    status = "ok"
    try:
        if not wedged(param, m, hi, counts, limit - (time.perf_counter() - start)):
            hi = None
        while hi is not None and hi - lo > BISECT_RTOL * hi:
            mid = 0.5 * (lo + hi)
            if wedged(param, m, mid, counts, limit - (time.perf_counter() - start)):
                hi = mid
            else:
                lo = mid
    except OutOfTime:
        status = "timeout"
    except TooLarge as e:
        return {"status": "too large", "note": str(e), **counts}
    return {"status": status, "mu_c": hi if status == "ok" else None, "mu_lo": lo, "mu_hi": hi, **counts}


def available(peer: str) -> bool:
    """Is the peer's Python package installed?"""
    import importlib.util
    return importlib.util.find_spec("gurobipy" if peer == "gurobi" else "pyscipopt") is not None


def main() -> None:
    start = time.perf_counter()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("peer", choices=PEERS)
    ap.add_argument("scene")
    ap.add_argument("--limit", type=float, default=200.0, help="seconds for the whole run (default 200)")
    args = ap.parse_args()
    if not available(args.peer):
        print(json.dumps({"status": "missing"}))
        return
    from hpcwedge.api import contact_problem
    from hpcwedge.contact.problem import parametrize
    prob = contact_problem(args.scene)
    param, m = parametrize(prob), prob.m
    n_vars, n_cons = model_size(param, m)
    out = {"n_vars": n_vars, "n_cons": n_cons}
    if args.peer == "gurobi" and (max(n_vars, n_cons) > GUROBI_MAX or
                                  (param.U.shape[0] == 3 * m and n_vars > GUROBI_MAX_QUADRATIC)):
        out["status"] = "too large"
    else:
        out.update(peer_mu_c(args.peer, param, m, args.limit, start))
    out["seconds"] = time.perf_counter() - start
    print(json.dumps(out))


if __name__ == "__main__":
    main()
