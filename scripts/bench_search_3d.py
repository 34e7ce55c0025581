#!/usr/bin/env python3
"""The 3D sign-pattern search on a body without symmetry (issue 13): counts and times.

    PYTHONPATH=. python scripts/bench_search_3d.py [--quick] [--full] [--no-peers] [--limit 600]
                                                   [--out results/bench_search_3d]

Scenes: plug3d LEVELS x RING (m = LEVELS * RING contact nodes), `run.symmetry = false`
(a generic body: no orbit saves a solve), each in its own process (bench_2d.run_script)
through `hpcwedge run`'s route (pipeline.run_scene), enumerations both as `ours` (the
default tree) and as `screens` (`run.screens = true`: LP screens before the deep SOCPs):
  enumerate  all feasible sign patterns at mu = 0.65 (`mu_c = "none"`): 2 x 6, 3 x 5, 3 x 6,
             and with --full 4 x 6 (about 4 minutes)
  global     the global mu^c (`enumerate = false`, `mu_c = "global"`, mu = 0.3): 2 x 6, 3 x 6,
             and with --full 4 x 6 and 4 x 8 (m = 32, about 2.5 minutes)
The peer (`engine = "scip"`; bench extras, "missing" without pyscipopt; --no-peers: none), SCIP
on issue 13's indicator MISOCP (reference.scip_model: friction as second-order cones, z_i = 1
=> u_n,i <= 0, r_n,i <= z_i, sum r_n = 1):
  enumerate  every feasible contact set by a no-good loop (reference.scip_patterns; its set's
             hash compares with ours): 2 x 6, 3 x 5, with --full 3 x 6
  global     bisection on mu in (0, 0.3] to 1e-6 relative (reference.scip_wedged): 2 x 6,
             3 x 6, with --full 4 x 6
Per row: the patterns (their set's hash, to compare runs), tree nodes, SOCPs, SOCPs per
feasible pattern, LPs (screens and pyramid fallbacks), undecided, the share of SOCPs that Clarabel's first attempt settled
(`first_attempt`: the SOCPs that needed no retry over all SOCPs, from the result's solver
statuses), CPU and wall seconds. Counts are the same on every machine; seconds are not
(2 shared cores: read them as +-2x). --quick: 2 x 6 only.
Writes <out>.csv and <out>.json (with the environment record); prints the table.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import bench_2d  # noqa: E402

ENUMERATE = ((2, 6), (3, 5), (3, 6))
GLOBAL = ((2, 6), (3, 6))
FULL = ((4, 6),)
FULL_GLOBAL = ((4, 6), (4, 8))
SCIP_ENUMERATE, SCIP_FULL_ENUMERATE = ((2, 6), (3, 5)), ((3, 6),)
SCIP_GLOBAL, SCIP_FULL_GLOBAL = ((2, 6), (3, 6)), ((4, 6),)
#: the peer's bisection: relative width of its final bracket
BISECT_RTOL = 1e-6
MU_ENUMERATE = 0.65
MU_GLOBAL = 0.3


def scene(task: str, levels: int, ring: int, screens: bool = False):
    from hpcwedge.scene.parse import parse_scene
    enum = task == "enumerate"
    return parse_scene({"name": f"plug3d-{levels}x{ring}", "dim": 3,
                        "model": {"kind": "plug3d", "levels": levels, "ring": ring},
                        "friction": {"mu": [MU_ENUMERATE if enum else MU_GLOBAL]},
                        "compute": {"enumerate": enum, "mu_c": "none" if enum else "global"},
                        "run": {"symmetry": False, "screens": screens}})


def first_attempt(statuses: dict) -> tuple[int, int]:
    """(SOCPs settled by Clarabel's first attempt, SOCPs): an attempt's Clarabel status is
    counted under its CamelCase name, "retry<k>_" prefixed from the second attempt on."""
    first = sum(v for k, v in statuses.items() if k[:1].isupper())
    retried = sum(v for k, v in statuses.items() if k.startswith("retry1_") and k[7:8].isupper())
    return first - retried, first


def patterns_hash(contacts) -> str:
    """The hash of a set of contact sets (each a sorted tuple of node indices)."""
    return hashlib.sha1(repr(sorted(tuple(c) for c in contacts)).encode()).hexdigest()[:12]


def scip_worker(task: str, levels: int, ring: int) -> dict:
    """The SCIP peer on the scene's parametrisation (the program's own condensation)."""
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.contact.problem import parametrize
    from hpcwedge.reference import bisect, scip_patterns, scip_wedged
    prob = contact_problem(scene(task, levels, ring))
    param, m = parametrize(prob), prob.m
    counts: dict = {}
    t, c = time.perf_counter(), time.process_time()
    out = {"m": m}
    if task == "enumerate":
        found = scip_patterns(param, m, MU_ENUMERATE, counts)
        if found is not None:
            contacts = [tuple(i for i in range(m) if b >> i & 1) for b in found]
            out.update(patterns=len(contacts), patterns_hash=patterns_hash(contacts))
    else:
        out["mu_c"] = bisect(lambda mu: scip_wedged(param, m, mu, counts), 0.0, MU_GLOBAL, BISECT_RTOL)
    out.update(seconds=time.process_time() - c, wall_in_process=time.perf_counter() - t,
               milp_solves=counts.get("milp_solves", 0), milp_nodes=counts.get("milp_nodes", 0),
               undecided=counts.get("undecided", 0))
    return out


def worker(task: str, levels: int, ring: int, screens: bool = False) -> dict:
    from hpcwedge.run.pipeline import run_scene
    t, c = time.perf_counter(), time.process_time()
    res = run_scene(scene(task, levels, ring, screens))
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    bnb = res.stats["bnb"]
    statuses = res.stats.get("socp_statuses") or {}
    out = {"m": res.m, "nodes": bnb.get("nodes"), "socps": bnb.get("solves"), "lps": bnb.get("lps"),
           "undecided": bnb.get("undecided"),
           "seconds": cpu, "wall_in_process": wall}
    if task == "enumerate":
        pats = [tuple(p.contact) for p in res.runs[0].patterns]
        out["patterns"] = len(pats)
        out["patterns_hash"] = patterns_hash(pats)
        out["socps_per_pattern"] = out["socps"] / max(len(pats), 1)
        good, total = first_attempt(statuses)
        out["first_attempt"] = good / total if total else None
    else:
        out["mu_c"] = res.mu_c
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2 x 6 only")
    ap.add_argument("--full", action="store_true", help="also 4 x 6 (m = 24)")
    ap.add_argument("--no-peers", action="store_true", help="ours only (no SCIP runs)")
    ap.add_argument("--limit", type=float, default=600.0, help="seconds per run")
    ap.add_argument("--out", default=os.path.join(bench_2d.ROOT, "results", "bench_search_3d"))
    ap.add_argument("--worker", nargs=4, metavar=("ENGINE", "TASK", "LEVELS", "RING"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        engine, task, levels, ring = args.worker[0], args.worker[1], int(args.worker[2]), int(args.worker[3])
        out = scip_worker(task, levels, ring) if engine == "scip" else worker(task, levels, ring, engine == "screens")
        print(bench_2d.MARK + json.dumps(out))
        return
    plan = [(e, "enumerate", lr) for lr in (ENUMERATE[:1] if args.quick else ENUMERATE + (FULL if args.full else ()))
            for e in ("ours", "screens")]
    plan += [("ours", "global", lr) for lr in (GLOBAL[:1] if args.quick else GLOBAL + (FULL_GLOBAL if args.full else ()))]
    if not args.no_peers:
        plan += [("scip", "enumerate", lr) for lr in
                 (SCIP_ENUMERATE[:1] if args.quick else SCIP_ENUMERATE + (SCIP_FULL_ENUMERATE if args.full else ()))]
        plan += [("scip", "global", lr) for lr in
                 (SCIP_GLOBAL[:1] if args.quick else SCIP_GLOBAL + (SCIP_FULL_GLOBAL if args.full else ()))]
    try:
        import pyscipopt  # noqa: F401
        have_scip = True
    except ImportError:
        have_scip = False
    records = []
    for engine, task, (levels, ring) in plan:
        rec = {"engine": engine, "task": task, "levels": levels, "ring": ring, "m": levels * ring}
        if engine == "scip" and not have_scip:
            records.append(dict(rec, status="missing"))
            print(line(records[-1]), flush=True)
            continue
        rec = bench_2d.run_record(os.path.abspath(__file__), ["--worker", engine, task, str(levels), str(ring)],
                                  args.limit, **rec)
        records.append(rec)
        print(line(rec), flush=True)
    bench_2d.write_records(args.out, records, {"mu_enumerate": MU_ENUMERATE, "mu_global": MU_GLOBAL, "limit_s": args.limit}, COLUMNS)


def line(r: dict) -> str:
    keys = ("patterns", "patterns_hash", "nodes", "socps", "socps_per_pattern", "lps", "first_attempt", "milp_solves",
            "milp_nodes", "undecided", "mu_c", "seconds")
    return f"{r['engine']:7s} {r['task']:9s} m={r['m']:3d} {r['status']:7s} {bench_2d.fields(r, keys, 4)}"


#: the CSV's columns
COLUMNS = ["engine", "task", "levels", "ring", "m", "status", "patterns", "patterns_hash", "nodes", "socps",
           "socps_per_pattern", "lps", "first_attempt", "milp_solves", "milp_nodes", "undecided", "mu_c", "seconds",
           "wall"]


if __name__ == "__main__":
    main()
