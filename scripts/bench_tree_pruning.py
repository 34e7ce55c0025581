#!/usr/bin/env python3
"""What could prune the 3D pattern tree near mu^c (issue 41): counts of one tree, no timings.

    PYTHONPATH=. python scripts/bench_tree_pruning.py [--levels 4 --ring 8 --mu 0.2]
                                                      [--nodes 0] [--out results/bench_tree_pruning]

The tree of plug3d LEVELS x RING at mu (PatternTree with `hpcwedge run`'s options, symmetry off)
explored depth first for --nodes tree nodes (0: to the end). Per SOCP: its status and how many
nodes it fixes (contact, gap). Per infeasible SOCP: its reaction-form Farkas certificate
(solved once more, attempt 0) and the fixings it rests on (socp.farkas_decisions: a nogood),
and whether a nogood learnt earlier anywhere in the tree (one store for the whole tree: an upper
bound on what any split-invariant store can prune) already held at that node. A nogood can prune
only infeasible nodes: the feasible relaxations below a pattern's ancestors are the floor of any
such rule. Writes <out>.json (with the environment record); prints a summary.
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import bench_2d  # noqa: E402
import harness  # noqa: E402
from bench_near_critical import plug_scene  # noqa: E402


def measure(levels: int, ring: int, mu: float, nodes: int | None) -> dict:
    """The counts of the module doc for one tree."""
    import numpy as np

    from hpcwedge.contact.build import contact_problem
    from hpcwedge.contact.problem import parametrize
    from hpcwedge.patterns.tree import PatternTree
    from hpcwedge.solvers.conic import solve
    from hpcwedge.solvers.rows import Status, pattern_rows
    from hpcwedge.solvers.socp import certificate_ok, farkas_decisions, reaction_socp

    prob = contact_problem(plug_scene(levels, ring, mu))
    param, m = parametrize(prob), prob.m
    by_fixed, sizes, store = collections.Counter(), collections.Counter(), []
    counts = collections.Counter()

    class Recording(PatternTree):
        def _solve(self, node, mu_, stats):
            held = any(c & ~node.contact == 0 and g & ~node.gap == 0 for c, g in store)
            dec = super()._solve(node, mu_, stats)
            by_fixed[f"{dec.status}_{node.contact.bit_count()}_{node.gap.bit_count()}"] += 1
            counts[str(dec.status)] += 1
            if dec.status != Status.INFEASIBLE:
                counts["nogood_held_at_feasible"] += held          # must stay 0
                return dec
            counts["nogood_would_prune"] += held
            first = reaction_socp(pattern_rows(param, m, *node.masks(m)), mu_)
            sol = solve(first.problem, 0, False)
            p = first.problem
            if sol.status != Status.INFEASIBLE or not certificate_ok(p.A, p.b, sol.z, p.n_zero, p.n_lin):
                counts["no_certificate"] += 1
                return dec
            contact, gap = farkas_decisions(first, np.asarray(sol.z))
            sizes[f"{int(contact.sum())}_{int(gap.sum())}"] += 1
            counts["fixed_total"] += node.contact.bit_count() + node.gap.bit_count()
            counts["nogood_total"] += int(contact.sum() + gap.sum())
            store.append((sum(1 << int(i) for i in contact.nonzero()[0]),
                          sum(1 << int(i) for i in gap.nonzero()[0])))
            return dec

    tree = Recording(param, m, mu)
    out = tree.explore(tree.root(), nodes or None)
    return {"levels": levels, "ring": ring, "m": m, "mu": mu, "node_budget": nodes, "nodes": out.stats.nodes,
            "socps": out.stats.solves, "skipped": out.stats.skipped, "patterns": len(out.found),
            "finished": not out.open, "counts": dict(counts), "solves_by_status_contact_gap": dict(by_fixed),
            "nogood_sizes_contact_gap": dict(sizes)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, default=4)
    ap.add_argument("--ring", type=int, default=8)
    ap.add_argument("--mu", type=float, default=0.2)
    ap.add_argument("--nodes", type=int, default=0, help="tree nodes to explore (0: all)")
    ap.add_argument("--out", default=os.path.join(bench_2d.ROOT, "results", "bench_tree_pruning"))
    args = ap.parse_args()
    rec = measure(args.levels, args.ring, args.mu, args.nodes)
    harness.write_records(args.out, [rec], csv_file=False)
    c = rec["counts"]
    print(f"plug3d {args.levels} x {args.ring} mu {args.mu}: {rec['nodes']} nodes, {rec['socps']} SOCPs "
          f"({c.get('feasible', 0)} feasible, {c.get('infeasible', 0)} infeasible), {rec['patterns']} patterns; "
          f"nogoods: mean {c.get('nogood_total', 0) / max(c.get('infeasible', 1), 1):.1f} of "
          f"{c.get('fixed_total', 0) / max(c.get('infeasible', 1), 1):.1f} fixings, "
          f"{c.get('nogood_would_prune', 0)} SOCPs a global store would have pruned")
    print(json.dumps(rec["nogood_sizes_contact_gap"]))


if __name__ == "__main__":
    main()
