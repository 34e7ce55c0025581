#!/usr/bin/env python3
"""SOCPs solved by the 3D sign-pattern branch and bound against 2^m (serial).

    PYTHONPATH=. python scripts/bench_socp_count.py [--ring 4 5 6 7] [--mu 0.65 1.0]
        [--branching dynamic static] [--brute-max 12] [--out results/bench_socp_count.json]

plug3d, levels = 2, ring = 4..7 (m = 8, 10, 12, 14). For each (m, mu): the whole
tree, the product's patterns stage (hpcwedge.solve with compute.mu_c = "none", its
stats.bnb and timings.enumerate; "static": PatternTree.explore from the root, as the
product offers no static order), each in a child process (harness.run_call): SOCPs (Clarabel problems solved, each
retry of the status policy not counted again), LPs (every HiGHS call: screens and
pyramid fallbacks), tree nodes, nodes decided without a solve, feasible patterns,
wall time; with m <= --brute-max also the brute force (one SOCP per partition,
reference.brute_force_patterns) and whether the two pattern sets agree (harness.Checks:
exit status 1 when they do not).
Branching: "symmetric" (what `hpcwedge run` does: dynamic branching over orbits of plug3d's dihedral node symmetry, patterns
expanded over the group afterwards), "dynamic" (PatternTree without a symmetry: on
the free node whose relaxed solution violates complementarity most) and "static"
(the order m-1..0 with steered solves). Column "pruned" stays 0 (no rule prunes a
node without a solve).
"""
from __future__ import annotations

import argparse
import time

from harness import OK, Checks, pattern_hash, run_call, write_json

import hpcwedge as hw

LABEL = {"symmetric": True, "dynamic": False}


def table(levels: int, ring: int, mu: float, symmetry: bool, taper: float = 10.0) -> dict:
    """The scene table of plug3d levels x ring at mu: the patterns only."""
    return {"name": "p", "dim": 3, "friction": {"mu": [mu]},
            "model": {"kind": "plug3d", "levels": levels, "ring": ring, "taper_deg": taper},
            "compute": {"mu_c": "none"}, "run": {"symmetry": symmetry}}


def product_tree(levels: int, ring: int, mu: float, symmetry: bool) -> dict:
    """A case: the patterns stage of hpcwedge.solve; its counters, seconds and patterns."""
    r = hw.solve(hw.Scene.from_dict(table(levels, ring, mu, symmetry)))
    sym = r.stats.get("symmetry") or {}
    reps = sym.get("representatives")
    return {"m": r.m, "bnb": r.stats["bnb"], "statuses": r.stats["socp_statuses"],
            "undecided": r.stats["patterns_undecided"], "seconds": r.timings["enumerate"],
            "group_order": sym.get("order", 1) if symmetry else 1,
            "patterns": [p.contact for p in r.runs[0].patterns],
            "leaves_found": reps[0] if reps else len(r.runs[0].patterns)}


def static_tree(levels: int, ring: int, mu: float) -> dict:
    """A case: the tree in the static order m-1..0 (a study: PatternTree, not offered by the product)."""
    from hpcwedge.nodesets import bits_to_nodes
    from hpcwedge.patterns.tree import PatternTree
    param, m = parametrized(levels, ring)
    tree = PatternTree(param, m, mu, order=list(range(m - 1, -1, -1)))
    t = time.perf_counter()
    out = tree.explore(tree.root())
    seconds = time.perf_counter() - t
    st = out.stats
    return {"m": m, "bnb": {"solves": st.solves, "lps": st.lps, "nodes": st.nodes, "skipped": st.skipped,
                            "pruned": st.pruned}, "statuses": st.statuses, "undecided": len(out.undecided),
            "seconds": seconds, "group_order": 1, "leaves_found": len(out.found),
            "patterns": [list(bits_to_nodes(s.contact, m)) for s in out.found]}


def brute(levels: int, ring: int, mu: float) -> dict:
    """A case: the reference, one SOCP per partition (reference.brute_force_patterns)."""
    from hpcwedge.nodesets import bits_to_nodes
    from hpcwedge.reference import brute_force_patterns
    param, m = parametrized(levels, ring)
    t = time.perf_counter()
    found = brute_force_patterns(param, m, mu)
    return {"seconds": time.perf_counter() - t, "patterns": [list(bits_to_nodes(b, m)) for b in found]}


def parametrized(levels: int, ring: int):
    """(parametrisation, m) of plug3d, for the study and the reference."""
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.contact.problem import parametrize
    prob = contact_problem(hw.Scene.from_dict(table(levels, ring, 1.0, False)))
    return parametrize(prob), prob.m


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--levels", type=int, default=2)
    ap.add_argument("--ring", type=int, nargs="+", default=[4, 5, 6, 7])
    ap.add_argument("--mu", type=float, nargs="+", default=[0.65, 1.0])
    ap.add_argument("--branching", nargs="+", default=["symmetric", "dynamic", "static"],
                    choices=["symmetric", "dynamic", "static"])
    ap.add_argument("--brute-max", type=int, default=12)
    ap.add_argument("--limit", type=float, default=None, help="seconds per case (default: none)")
    ap.add_argument("--out", default="results/bench_socp_count.json")
    args = ap.parse_args()
    rows, checks = [], Checks()
    print(f"{'branching':>9} {'m':>3} {'mu':>5} {'patterns':>8} {'SOCPs':>6} {'LPs':>6} {'nodes':>6} {'skipped':>7} "
          f"{'pruned':>6} "
          f"{'2^m':>6} {'2^m/SOCPs':>9} {'B&B s':>7} {'brute s':>8} {'same':>5}")
    for ring in args.ring:
        for mu, branching in [(mu, b) for mu in args.mu for b in args.branching]:
            rec = run_call(static_tree, args.levels, ring, mu, limit=args.limit) if branching == "static" else \
                run_call(product_tree, args.levels, ring, mu, LABEL[branching], limit=args.limit)
            if rec["status"] != OK:
                rows.append({"branching": branching, "levels": args.levels, "ring": ring, "mu": mu,
                             "status": rec["status"], "seconds": rec["seconds"]})
                print(f"{branching:>9} ring {ring} mu {mu:g}: {rec['status']} after {rec['seconds']} s", flush=True)
                continue
            v = rec["value"]
            m, st, got = v["m"], v["bnb"], v["patterns"]
            row = {"branching": branching, "levels": args.levels, "ring": ring, "m": m, "mu": mu, "patterns": len(got),
                   "undecided": v["undecided"], "socps": st["solves"], "lps": st["lps"],
                   "nodes": st["nodes"], "skipped": st["skipped"], "pruned": st["pruned"], "partitions": 2 ** m,
                   "group_order": v["group_order"], "leaves_found": v["leaves_found"],
                   "bnb_seconds": round(v["seconds"], 3), "statuses": v["statuses"]}
            same, tb = "-", float("nan")
            if m <= args.brute_max and branching == args.branching[0]:
                ref = run_call(brute, args.levels, ring, mu, limit=args.limit)
                if ref["status"] == OK:
                    tb = ref["value"]["seconds"]
                    row["brute_seconds"] = round(tb, 3)
                    row["brute_equal"] = checks.compare(f"{branching} m = {m} mu = {mu:g} against brute force",
                                                        pattern_hash(got), pattern_hash(ref["value"]["patterns"]))
                    same = str(row["brute_equal"])
            rows.append(row)
            print(f"{branching:>9} {m:3d} {mu:5.3g} {len(got):8d} {st['solves']:6d} {st['lps']:6d} {st['nodes']:6d} "
                  f"{st['skipped']:7d} {st['pruned']:6d} {2 ** m:6d} {2 ** m / max(st['solves'], 1):9.1f} "
                  f"{v['seconds']:7.2f} {tb:8.2f} {same:>5}", flush=True)
    write_json(args.out, {"runs": rows})
    print("wrote", args.out)
    return checks.exit_status()


if __name__ == "__main__":
    raise SystemExit(main())
