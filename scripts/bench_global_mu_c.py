#!/usr/bin/env python3
"""2D global mu^c at realistic size (issue 13): ours against MILP peers, in one run.

    PYTHONPATH=. python scripts/bench_global_mu_c.py [--quick] [--rows 5 10 20 40] [--limit 170]
                                                     [--model plug2d|block2d] [--out results/bench_global_mu_c]

Scenes: plug2d rows R (m = 2 R contact nodes, taper 10 deg, free body; global mu^c =
tan(10 deg) analytically), or with --model block2d the plane-stress Q4 plug with R coarse
rows, each element split 2 x 2 (refine 2; m = 2 (R + 1); the same analytic mu^c);
`enumerate = false`, `mu_c = "global"`.
Engines, each in its own process with a time limit (bench_2d.run_script):
  ours         `hpcwedge run`'s route (pipeline.run_scene): in 2D the MILP bracket
               (global_mu_c.global_bracket_milp: milp.wedge_milp by HiGHS, each pattern's
               mu^c certified by mu_critical), tree fallback on doubt
  ours_milp    the same MILP bracket without the tree's dive (global_bracket_milp(dive=0)):
               every step a MILP
  ours_tree    global_mu_c.global_mu_critical(route="tree"): the sign-pattern branch and bound
               with an incumbent (the route before issue 13)
  highs_bisect the MILP of milp.wedge_milp at fixed mu (valid big-M from the
               normalisation sum r_n + s sum u_n = 1), bisection on mu to 1e-6 relative
  scip_bisect  SCIP (pyscipopt) on the MILP of issue 13's text (reference.scip_wedged): x in
               the (r, alpha) form, u_n >= 0, friction, sum r_n = 1, r_n,i <= z_i, indicator
               z_i = 1 => u_n,i <= 0; pure feasibility, bisection on mu to 1e-6 relative
               (reference.bisect; "missing" without pyscipopt)
Counts: ours/ours_tree LPs and tree nodes, MILP solves and branch-and-bound nodes (HiGHS's
mip_node_count, SCIP's getNNodes); counts are the same on every machine, seconds are not
(2 cores shared: read them as +-2x). Error: relative to tan(10 deg).
Writes <out>.csv and <out>.json (with the environment record); prints the table.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import bench_2d  # noqa: E402

ENGINES = ("ours", "ours_milp", "ours_tree", "highs_bisect", "scip_bisect")
TAPER = 10.0
MU_MAX = 100.0
BISECT_RTOL = 1e-6


#: the scene family (main's --model; the workers get it through the environment)
MODEL = os.environ.get("BENCH_GLOBAL_MODEL", "plug2d")


def m_of(rows: int) -> int:
    return 2 * rows if MODEL == "plug2d" else 2 * (rows + 1)


def problem(rows: int):
    """(result of the enumeration-free run, parametrisation, m, numerics scale)."""
    import numpy as np

    from hpcwedge.contact.problem import parametrize, stiffness_range
    from hpcwedge.run.pipeline import run_scene
    res = run_scene(scene(rows, "none"))
    lo, hi = stiffness_range(res.problem)
    return parametrize(res.problem), res.m, float(np.sqrt(lo * hi)) if lo > 0 else hi


def scene(rows: int, mu_c: str):
    from hpcwedge.scene.parse import parse_scene
    model = {"kind": MODEL, "rows": rows, "taper_deg": TAPER}
    if MODEL == "block2d":
        model["refine"] = 2
    return parse_scene({"name": f"{MODEL}-r{rows}", "dim": 2, "model": model,
                        "friction": {"mu": [0.1]}, "compute": {"enumerate": False, "mu_c": mu_c}})


def bisect(decide, hi: float = MU_MAX, rtol: float = BISECT_RTOL) -> float | None:
    """Least mu in (0, hi] at which decide(mu) holds, to rtol (the bracket's upper end;
    reference.bisect); None if decide(hi) fails."""
    from hpcwedge.reference import bisect as bisection
    return bisection(decide, 0.0, hi, rtol) if decide(hi) else None


def worker(engine: str, rows: int) -> dict:
    """One engine on one scene: {"mu_c", "seconds", counts...}."""
    from hpcwedge.mu_c.global_search import global_mu_critical
    from hpcwedge.patterns.tree import BnBStats
    from hpcwedge.reference import scip_wedged
    from hpcwedge.run.pipeline import run_scene
    from hpcwedge.solvers.milp import wedge_milp
    from hpcwedge.solvers.rows import Status
    if engine == "ours":
        t = time.perf_counter()
        res = run_scene(scene(rows, "global"))
        wall = time.perf_counter() - t
        b = res.stats["bnb"]
        return {"mu_c": res.mu_c, "seconds": res.timings["mu_c"], "wall_with_setup": wall,
                "route": b["route"], "lps": b["solves"], "tree_nodes": b["nodes"],
                "milp_solves": b["milp_solves"], "milp_nodes": b["milp_nodes"], "undecided": b["undecided"]}
    param, m, s = problem(rows)
    if engine == "ours_tree":
        st = BnBStats()
        t = time.perf_counter()
        mu, _ = global_mu_critical(param, m, MU_MAX, stats=st, scale=s, route="tree")
        return {"mu_c": mu, "seconds": time.perf_counter() - t, "route": "tree", "lps": st.solves,
                "tree_nodes": st.nodes, "undecided": st.undecided}
    if engine == "ours_milp":
        from functools import partial

        from hpcwedge.mu_c.critical import mu_critical
        from hpcwedge.mu_c.global_search import global_bracket_milp
        st = BnBStats()
        t = time.perf_counter()
        mu = global_bracket_milp(param, m, MU_MAX, partial(mu_critical, param, m, mu_max=MU_MAX, scale=s),
                                 st, s, dive=0)
        return {"mu_c": mu, "seconds": time.perf_counter() - t, "route": "milp", "lps": st.solves,
                "milp_solves": st.extra.get("milp_solves", 0), "milp_nodes": st.extra.get("milp_nodes", 0)}
    counts: dict = {}
    if engine == "highs_bisect":
        def decide(mu):
            ans = wedge_milp(param, m, mu, s)
            counts["milp_solves"] = counts.get("milp_solves", 0) + 1
            counts["milp_nodes"] = counts.get("milp_nodes", 0) + ans.nodes
            if ans.status not in (Status.FEASIBLE, Status.INFEASIBLE):
                counts["undecided"] = counts.get("undecided", 0) + 1
            return ans.status != Status.INFEASIBLE
    elif engine == "scip_bisect":
        try:
            import pyscipopt  # noqa: F401
        except ImportError:
            sys.exit(3)

        def decide(mu):
            return scip_wedged(param, m, mu, counts)
    else:
        raise SystemExit(f"unknown engine {engine}")
    t = time.perf_counter()
    mu = bisect(decide)
    return {"mu_c": mu, "seconds": time.perf_counter() - t, **counts}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="rows 5 and 10, 60 s per engine")
    ap.add_argument("--rows", type=int, nargs="*", default=None)
    ap.add_argument("--engines", nargs="*", default=list(ENGINES))
    ap.add_argument("--limit", type=float, default=None, help="seconds per engine and scene")
    ap.add_argument("--model", default="plug2d", choices=["plug2d", "block2d"])
    ap.add_argument("--out", default=os.path.join(bench_2d.ROOT, "results", "bench_global_mu_c"))
    ap.add_argument("--worker", nargs=2, metavar=("ENGINE", "ROWS"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    global MODEL
    if not args.worker:
        MODEL = os.environ["BENCH_GLOBAL_MODEL"] = args.model
    if args.worker:
        out = worker(args.worker[0], int(args.worker[1]))
        print(bench_2d.MARK + json.dumps(out))
        return
    rows_list = args.rows or ([5, 10] if args.quick else [5, 10, 20, 40])
    limit = args.limit or (60.0 if args.quick else 170.0)
    want = math.tan(math.radians(TAPER))
    records, dead = [], set()
    for rows in rows_list:
        for engine in args.engines:
            if engine in dead:                     # timed out at a smaller size: not again
                records.append({"model": MODEL, "rows": rows, "m": m_of(rows), "engine": engine, "status": "skipped"})
                continue
            status, res, wall, err = bench_2d.run_script(os.path.abspath(__file__),
                                                         ["--worker", engine, str(rows)], limit)
            rec = {"model": MODEL, "rows": rows, "m": m_of(rows), "engine": engine, "status": status, "wall": wall}
            if res is not None:
                rec.update(res)
                mu = res.get("mu_c")
                rec["rel_error"] = None if mu is None else abs(mu - want) / want
            elif err:
                rec["error"] = err
            if status == "timeout":
                dead.add(engine)
            records.append(rec)
            print(line(rec), flush=True)
    bench_2d.write_records(args.out, records, {"model": MODEL, "taper_deg": TAPER, "mu_max": MU_MAX,
                                               "bisect_rtol": BISECT_RTOL, "limit_s": limit, "analytic_mu_c": want},
                           COLUMNS)


def line(r: dict) -> str:
    keys = ("seconds", "rel_error", "route", "lps", "tree_nodes", "milp_solves", "milp_nodes", "undecided")
    return f"m={r['m']:4d} {r['engine']:13s} {r['status']:8s} {bench_2d.fields(r, keys)}"


#: the CSV's columns
COLUMNS = ["model", "rows", "m", "engine", "status", "seconds", "wall", "mu_c", "rel_error", "route", "lps",
           "tree_nodes", "milp_solves", "milp_nodes", "undecided"]


if __name__ == "__main__":
    main()
