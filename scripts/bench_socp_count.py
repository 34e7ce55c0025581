#!/usr/bin/env python3
"""SOCPs solved by the 3D sign-pattern branch and bound against 2^m (serial).

    PYTHONPATH=. python scripts/bench_socp_count.py [--ring 4 5 6 7] [--mu 0.65 1.0]
        [--branching dynamic static] [--brute-max 12] [--out results/bench_socp_count.json]

plug3d, levels = 2, ring = 4..7 (m = 8, 10, 12, 14). For each (m, mu): the whole
tree (PatternTree.explore from the root): SOCPs (Clarabel problems solved, each
retry of the status policy not counted again), LPs (every HiGHS call: screens and
pyramid fallbacks), tree nodes, nodes decided without a solve, feasible patterns,
wall time; with m <= --brute-max also the brute force (one SOCP per partition,
reference.brute_force_patterns) and whether the two pattern sets agree.
Branching: "symmetric" (what `hpcwedge run` does: dynamic branching over orbits of plug3d's dihedral node symmetry, patterns
expanded over the group afterwards), "dynamic" (PatternTree without a symmetry: on
the free node whose relaxed solution violates complementarity most) and "static"
(the order m-1..0 with steered solves). Column "pruned" stays 0 (no rule prunes a
node without a solve).
"""
from __future__ import annotations

import argparse
import json
import os
import time

from hpcwedge.contact.build import contact_problem
from hpcwedge.contact.problem import parametrize
from hpcwedge.environment import environment
from hpcwedge.patterns.symmetry import node_symmetries
from hpcwedge.patterns.tree import PatternTree
from hpcwedge.reference import brute_force_patterns
from hpcwedge.scene.parse import parse_scene


def plug(levels, ring, taper=10.0, symmetry=False):
    """(parametrisation, m) of plug3d, and its node symmetry group with symmetry=True."""
    sc = parse_scene({"name": "p", "dim": 3, "friction": {"mu": [1.0]},
                      "model": {"kind": "plug3d", "levels": levels, "ring": ring, "taper_deg": taper}})
    prob = contact_problem(sc)
    if symmetry:
        return parametrize(prob), prob.m, node_symmetries(prob.K, 3)
    return parametrize(prob), prob.m


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--levels", type=int, default=2)
    ap.add_argument("--ring", type=int, nargs="+", default=[4, 5, 6, 7])
    ap.add_argument("--mu", type=float, nargs="+", default=[0.65, 1.0])
    ap.add_argument("--branching", nargs="+", default=["symmetric", "dynamic", "static"],
                    choices=["symmetric", "dynamic", "static"])
    ap.add_argument("--brute-max", type=int, default=12)
    ap.add_argument("--out", default="results/bench_socp_count.json")
    args = ap.parse_args()
    rows = []
    print(f"{'branching':>9} {'m':>3} {'mu':>5} {'patterns':>8} {'SOCPs':>6} {'LPs':>6} {'nodes':>6} {'skipped':>7} "
          f"{'pruned':>6} "
          f"{'2^m':>6} {'2^m/SOCPs':>9} {'B&B s':>7} {'brute s':>8} {'same':>5}")
    for ring in args.ring:
        p, m, group = plug(args.levels, ring, symmetry=True)
        for mu, branching in [(mu, b) for mu in args.mu for b in args.branching]:
            tree = PatternTree(p, m, mu, order=list(range(m - 1, -1, -1)) if branching == "static" else None,
                               symmetry=group if branching == "symmetric" else None)
            t = time.perf_counter()
            out = tree.explore(tree.root())
            found = tree.expand(out.found)
            t_bnb = time.perf_counter() - t
            got = sorted(s.contact for s in found)
            st = out.stats
            row = {"branching": branching, "levels": args.levels, "ring": ring, "m": m, "mu": mu, "patterns": len(got),
                   "undecided": len(out.undecided), "socps": st.solves, "lps": st.lps,
                   "nodes": st.nodes, "skipped": st.skipped, "pruned": st.pruned, "partitions": 2 ** m,
                   "group_order": group.order if branching == "symmetric" else 1,
                   "leaves_found": len(out.found),
                   "bnb_seconds": round(t_bnb, 3), "statuses": st.statuses}
            same, tb = "-", float("nan")
            if m <= args.brute_max and branching == args.branching[0]:
                t = time.perf_counter()
                ref = brute_force_patterns(p, m, mu)
                tb = time.perf_counter() - t
                row["brute_seconds"] = round(tb, 3)
                row["brute_equal"] = ref == got
                same = str(ref == got)
            rows.append(row)
            print(f"{branching:>9} {m:3d} {mu:5.3g} {len(got):8d} {st.solves:6d} {st.lps:6d} {st.nodes:6d} {st.skipped:7d} "
                  f"{st.pruned:6d} {2 ** m:6d} {2 ** m / max(st.solves, 1):9.1f} {t_bnb:7.2f} {tb:8.2f} {same:>5}", flush=True)
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    with open(args.out, "w") as f:
        json.dump({"runs": rows, "environment": environment()}, f, indent=1)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
