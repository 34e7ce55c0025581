#!/usr/bin/env python3
"""The 3D search near mu^c and on bodies where elasticity sets mu^c (issue 41): counts and times.

    PYTHONPATH=. python scripts/bench_near_critical.py [--quick] [--limit 300] [--label after]
                                                       [--only enumerate|global] [--out results/bench_near_critical]

Every row is one `hpcwedge run` route (pipeline.run_scene) in its own process
(bench_2d.run_script, killed at --limit seconds: status "timeout"), serial, `run.symmetry = false`:
  enumerate  all feasible sign patterns (`mu_c = "none"`) of plug3d LEVELS x RING at mu: 4 x 8 at
             mu = 0.2 (1.13 mu^c), 6 x 8 and 8 x 8 at 1.1 mu^c (the free plug's mu^c is
             tan(taper) = tan 10 deg): seconds, tree nodes, SOCPs, patterns, SOCPs per pattern
  global     the global mu^c (`enumerate = false`, `mu_c = "global"`) of tests/instances.py's
             curved_neck LEVELS x RING (seed 0: a flaring neck, random bar stiffness, jittered
             ring; elasticity sets its mu^c: 0.37 at m = 32, 7x tan 3 deg, the wall's angle at
             its foot): 4 x 8, 6 x 8, 8 x 8 (m = 32, 48, 64): seconds, nodes, SOCPs, bound solves (the
             certified lower bound's conic programs), mu^c, certified (global_mu_critical's own
             test: every pattern's mu^c polished, none unsettled; a tree solve that decides
             nothing keeps its subtree and an undecided leaf gets its certified mu^c, so
             `undecided` counts work, not doubt about the answer)
--peers scip gurobi: the curved necks of PEER_NECKS (m = 16, 18: sizes the peers can finish)
get our global row and each peer's (scripts/peers_global.py in its own process, the same
--limit: the feasibility MISOCP with binary contact flags, bisection on mu to 1e-6; engine = the
peer): status, seconds, mu_c (the bracket's upper end), mu_lo / mu_hi, milp_solves, milp_nodes,
and rel_error = (peer - ours) / ours against our certified mu^c of the same run (negative:
the peer says wedged below the least mu at which any pattern is, its tolerances at work).
An enumeration cut by --limit is run once more as `probe` (the same tree, PatternTree with
`hpcwedge run`'s options, explored in budgets of PROBE_BUDGET nodes until 0.8 * --limit wall
seconds have passed): how far it got (nodes, SOCPs, patterns so far, and `decided`: the share of
the 2^m patterns below no open subtree, an open subtree at depth d weighing 2^-d, as the run's
progress line). --quick: 4 x 8 only.
Counts are the same on every machine; seconds are CPU seconds of the worker
(2 shared cores: read them as +-2x). --label tags the rows (e.g. "before" / "after" a change);
the rows already in <out>.json of other labels, tasks or bodies are kept (--probe-only: the
probes alone). Writes <out>.csv and <out>.json (with the environment record); prints the table.
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

TAN_TAPER = math.tan(math.radians(10.0))
#: (levels, ring, mu) of the enumerations
ENUMERATE = ((4, 8, 0.2), (6, 8, 1.1 * TAN_TAPER), (8, 8, 1.1 * TAN_TAPER))
#: (levels, ring) of the curved necks' global mu^c
GLOBAL = ((4, 8), (6, 8), (8, 8))
NECK_SEED = 0
#: (levels, ring) of the necks that the peers are measured on (--peers)
PEER_NECKS = ((2, 8), (3, 6))
#: seconds a peer's process gets beyond the limit (its bisection stops itself at the limit)
PEER_GRACE = 30.0
#: tree nodes per explore call of a probe
PROBE_BUDGET = 200


def plug_scene(levels: int, ring: int, mu: float):
    from hpcwedge.scene.parse import parse_scene
    return parse_scene({"name": f"plug3d-{levels}x{ring}", "dim": 3,
                        "model": {"kind": "plug3d", "levels": levels, "ring": ring},
                        "friction": {"mu": [mu]}, "compute": {"mu_c": "none"}, "run": {"symmetry": False}})


def neck_scene(levels: int, ring: int):
    sys.path.insert(0, os.path.join(bench_2d.ROOT, "tests"))
    from instances import curved_neck

    from hpcwedge.scene.parse import parse_scene
    data = curved_neck(levels, ring, NECK_SEED)
    data.update(friction={"mu": [0.01]}, compute={"enumerate": False, "mu_c": "global"})
    return parse_scene(data)


def worker(task: str, levels: int, ring: int, mu: float) -> dict:
    from hpcwedge.run.pipeline import run_scene
    scene = plug_scene(levels, ring, mu) if task == "enumerate" else neck_scene(levels, ring)
    t, c = time.perf_counter(), time.process_time()
    res = run_scene(scene)
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    bnb = res.stats["bnb"]
    out = {"m": res.m, "nodes": bnb.get("nodes"), "socps": bnb.get("solves"), "skipped": bnb.get("skipped"),
           "lps": bnb.get("lps"), "undecided": bnb.get("undecided"), "seconds": cpu, "wall_in_process": wall}
    if task == "enumerate":
        pats = res.runs[0].patterns
        out["patterns"] = len(pats)
        out["socps_per_pattern"] = out["socps"] / max(len(pats), 1)
        out["contact_sets"] = sorted(len(p.contact) for p in pats)[:8]
    else:
        out["mu_c"] = res.mu_c
        out["bound_solves"] = bnb.get("bound_solves")
        out["certified"] = (bnb.get("unsettled", 0) == 0
                            and res.stats.get("mu_c_unpolished", 0) == 0)
    return out


def probe(levels: int, ring: int, mu: float, seconds: float) -> dict:
    """An enumeration's tree (symmetry off, the tree options of `hpcwedge run`) explored
    depth first in budgets of PROBE_BUDGET nodes until `seconds` have passed (wall clock: the
    run is killed by wall clock): its counts so far, the share of the tree decided, its CPU
    seconds and whether it finished (the counts do not depend on the budget)."""
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.contact.problem import parametrize
    from hpcwedge.patterns.tree import BnBStats, PatternTree
    prob = contact_problem(plug_scene(levels, ring, mu))
    tree, stats, found = PatternTree(parametrize(prob), prob.m, mu), BnBStats(), 0
    t, c = time.perf_counter(), time.process_time()
    stack = [(tree.root(), None)]
    while stack and time.perf_counter() - t < seconds:
        node, x = stack.pop()
        out = tree.explore(node, PROBE_BUDGET, x=x)
        stats.add(out.stats)
        found += len(out.found)
        stack += list(zip(out.open, out.open_x))[::-1]
    return {"m": prob.m, "nodes": stats.nodes, "socps": stats.solves, "skipped": stats.skipped,
            "undecided": stats.undecided, "patterns": found, "finished": not stack,
            "decided": 1.0 - sum(math.ldexp(1.0, -node.depth) for node, _ in stack),
            "seconds": time.process_time() - c, "wall_in_process": time.perf_counter() - t}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="4 x 8 only")
    ap.add_argument("--limit", type=float, default=300.0, help="seconds per run")
    ap.add_argument("--label", default="current", help="tag of this run's rows")
    ap.add_argument("--probe-only", action="store_true", help="only the probes of the enumerations beyond m = 32")
    ap.add_argument("--only", choices=("enumerate", "global"), help="only the rows of this task")
    ap.add_argument("--out", default=os.path.join(bench_2d.ROOT, "results", "bench_near_critical"))
    ap.add_argument("--peers", nargs="+", choices=("scip", "gurobi"), default=[],
                    help="these peers and ours on the necks of PEER_NECKS (only those rows)")
    ap.add_argument("--worker", nargs=4, metavar=("TASK", "LEVELS", "RING", "MU"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        task, levels, ring, mu = args.worker[0], int(args.worker[1]), int(args.worker[2]), float(args.worker[3])
        out = probe(levels, ring, mu, 0.8 * args.limit) if task == "probe" else worker(task, levels, ring, mu)
        print(bench_2d.MARK + json.dumps(out))
        return
    plan = [("enumerate", lv, rg, mu) for lv, rg, mu in ENUMERATE[:1 if args.quick else None]]
    plan += [("global", lv, rg, 0.0) for lv, rg in GLOBAL[:1 if args.quick else None]]
    if args.probe_only:
        plan = [("probe", lv, rg, mu) for lv, rg, mu in ENUMERATE[1:]]
    if args.only:
        plan = [row for row in plan if row[0] == args.only]
    records = _previous(args.out)
    if args.peers:
        for levels, ring in PEER_NECKS:
            ours = _run(args, records, "global", levels, ring, 0.0)
            for peer in args.peers:
                _run_peer(args, records, peer, levels, ring, ours.get("mu_c"))
        plan = []
    for task, levels, ring, mu in plan:
        rec = _run(args, records, task, levels, ring, mu)
        if task == "enumerate" and rec["status"] == "timeout":
            _run(args, records, "probe", levels, ring, mu)
    bench_2d.write_records(args.out, records, {"limit_s": args.limit, "neck_seed": NECK_SEED}, COLUMNS)


def _run(args, records: list[dict], task: str, levels: int, ring: int, mu: float) -> dict:
    """One row: the worker run in its own process, its record put in place of the one of the
    same label, task and body in `records`, printed."""
    records[:] = [r for r in records if (r.get("label"), r.get("task"), r.get("levels"), r.get("ring"), r.get("engine"))
                  != (args.label, task, levels, ring, None)]
    argv = ["--limit", str(args.limit), "--worker", task, str(levels), str(ring), repr(mu)]
    rec = bench_2d.run_record(os.path.abspath(__file__), argv, args.limit, label=args.label, task=task,
                              body="plug3d" if task != "global" else f"neck-s{NECK_SEED}", levels=levels,
                              ring=ring, m=levels * ring, mu=mu if task != "global" else None)
    records.append(rec)
    print(line(rec), flush=True)
    return rec


def _run_peer(args, records: list[dict], peer: str, levels: int, ring: int, ours: float | None) -> dict:
    """A peer's global row on the neck LEVELS x RING (module doc), in place of the one of the
    same label, body and engine in `records`, printed."""
    import tempfile

    from harness import OK, python_command, run_command
    records[:] = [r for r in records if (r.get("label"), r.get("task"), r.get("levels"), r.get("ring"), r.get("engine"))
                  != (args.label, "global", levels, ring, peer)]
    rec = {"label": args.label, "task": "global", "engine": peer, "body": f"neck-s{NECK_SEED}",
           "levels": levels, "ring": ring, "m": levels * ring, "mu": None}
    with tempfile.TemporaryDirectory() as tmp:
        scene = os.path.join(tmp, "neck.toml")
        with open(scene, "w") as f:
            f.write(_neck_toml(levels, ring))
        env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
        got = run_command(python_command(os.path.join(HERE, "peers_global.py"), peer, scene, "--limit", str(args.limit)),
                          limit=args.limit + PEER_GRACE, env=env)
    rec.update(status=got["status"], wall=got["seconds"])
    if got["status"] == OK:
        out = json.loads(got["stdout"].strip().splitlines()[-1])
        rec.update({k: out.get(k) for k in ("status", "mu_c", "mu_lo", "mu_hi", "milp_solves", "milp_nodes",
                                            "undecided", "n_vars", "n_cons", "seconds")})
        if rec.get("mu_c") is not None and ours:
            rec["rel_error"] = (rec["mu_c"] - ours) / ours
    records.append(rec)
    print(line(rec), flush=True)
    return rec


def _neck_toml(levels: int, ring: int) -> str:
    """neck_scene's scene as a TOML file's text (for the peers' script)."""
    sys.path.insert(0, os.path.join(bench_2d.ROOT, "tests"))
    from instances import curved_neck

    from hpcwedge.scene.parse import Scene
    data = curved_neck(levels, ring, NECK_SEED)
    data.update(friction={"mu": [0.01]}, compute={"enumerate": False, "mu_c": "global"})
    return Scene.from_dict(data).text


def _previous(out: str) -> list[dict]:
    """The records of an earlier run in <out>.json (none if there is no such file)."""
    try:
        with open(out + ".json") as f:
            return list(json.load(f).get("records", []))
    except (OSError, ValueError):
        return []


def line(r: dict) -> str:
    keys = ("mu", "finished", "patterns", "nodes", "socps", "socps_per_pattern", "lps", "bound_solves", "undecided",
            "mu_c", "certified", "seconds")
    keys += ("mu_lo", "mu_hi", "rel_error", "milp_nodes") if r.get("engine") else ()
    return (f"{r['label']:8s} {r['task']:9s} {r.get('engine', 'ours'):6s} {r['body']:8s} m={r['m']:3d} {r['status']:7s} "
            f"{bench_2d.fields(r, keys, 6)}")


#: the CSV's columns
COLUMNS = ["label", "task", "engine", "body", "levels", "ring", "m", "mu", "status", "patterns", "nodes", "socps", "skipped",
           "socps_per_pattern", "lps", "bound_solves", "undecided", "finished", "decided", "mu_c", "certified", "seconds",
           "wall", "mu_lo", "mu_hi", "rel_error", "milp_solves", "milp_nodes"]


if __name__ == "__main__":
    main()
