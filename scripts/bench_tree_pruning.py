#!/usr/bin/env python3
"""What could prune the 3D pattern tree near mu^c (issue 41): counts of one tree, no timings.

    PYTHONPATH=. python scripts/bench_tree_pruning.py [--levels 4 --ring 8 --mu 0.2]
                                                      [--nodes 0] [--out results/bench_tree_pruning]
    PYTHONPATH=. python scripts/bench_tree_pruning.py --neck --levels 4 --ring 8 --cores 80 [--roots] \
        --out results/bench_tree_pruning_neck_4x8
    PYTHONPATH=. python scripts/bench_tree_pruning.py --neck --levels 6 --ring 8 \
        --fractions 0.5 0.8 0.9 0.97 0.99 1.000000001 --out results/bench_tree_pruning_neck_mu

The tree of plug3d LEVELS x RING at mu (PatternTree with `hpcwedge run`'s options, symmetry off)
explored depth first for --nodes tree nodes (0: to the end); --neck: instead the settling tree
of tests/instances.py's curved neck LEVELS x RING (seed 0, where elasticity sets mu^c), at
its global mu^c (1 + 1e-9) as global_search.py poses it (Clarabel's own steps, branching on
the largest relaxed r_n); its mu^c is --mu, or `hpcwedge run`'s global mu^c when --mu is not
given; --fractions F..: one such tree at each F mu^c instead (F < 1: a tree that proves no
pattern feasible there; how much of the settling tree's size is the nearness of mu^c), each
with its seconds (CPU, one process; read them as +-2x on the shared machine). Per SOCP: its status and how many
nodes it fixes (contact, gap), and per depth the feasible and infeasible ones. --cores K: K
infeasible tree nodes (seeded draw) shrunk to a minimal core by a deletion filter (each fixing
dropped in turn while the node's relaxation stays infeasible, feasibility.decide): fixings the
prune rests on, none of which can be left out, against those the path made.
--roots: the tree again for every first branching node i (both children explored with the
tree's rule below them): its node count per i, beside the rule's own first choice.
Per infeasible SOCP: its reaction-form Farkas certificate
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


def neck_mu_c(levels: int, ring: int) -> float:
    """The curved neck's global mu^c by `hpcwedge run`'s route (pipeline.run_scene)."""
    from bench_near_critical import neck_scene

    from hpcwedge.run.pipeline import run_scene
    return float(run_scene(neck_scene(levels, ring)).mu_c)


def minimal_core(decide_fixed, contact: list[int], gap: list[int]) -> tuple[list[int], list[int]]:
    """A minimal subset of the fixings (contact, gap) whose relaxation is still infeasible
    (deletion filter: contacts then gaps, each in increasing order, dropped when the rest
    stays infeasible). decide_fixed(contact, gap) -> True when infeasible."""
    core = [("c", i) for i in contact] + [("g", i) for i in gap]
    for fix in list(core):
        rest = [f for f in core if f != fix]
        if decide_fixed([i for t, i in rest if t == "c"], [i for t, i in rest if t == "g"]):
            core = rest
    return [i for t, i in core if t == "c"], [i for t, i in core if t == "g"]


def measure(levels: int, ring: int, mu: float | None, nodes: int | None, neck: bool = False,
            cores: int = 0, roots: bool = False, fraction: float = 1 + 1e-9) -> dict:
    """The counts of the module doc for one tree (neck: mu None asks `hpcwedge run` for it;
    the tree at fraction * mu^c)."""
    import time
    import numpy as np

    from hpcwedge.contact.build import contact_problem
    from hpcwedge.contact.problem import parametrize
    from hpcwedge.mu_c.global_search import TREE_BRANCH
    from hpcwedge.patterns.tree import PatternTree, Subtree
    from hpcwedge.solvers.conic import solve
    from hpcwedge.solvers.feasibility import DEFAULT_OPTIONS, decide
    from hpcwedge.solvers.rows import Status, pattern_rows
    from hpcwedge.solvers.socp import certificate_ok, farkas_decisions, reaction_socp

    if neck:
        from bench_near_critical import neck_scene
        mu_c = neck_mu_c(levels, ring) if mu is None else mu
        prob, tree_mu = contact_problem(neck_scene(levels, ring)), mu_c * fraction
        options = {"options": DEFAULT_OPTIONS, "branch": TREE_BRANCH}
    else:
        prob, tree_mu, options = contact_problem(plug_scene(levels, ring, mu)), mu, {}
    param, m = parametrize(prob), prob.m
    by_fixed, sizes, store = collections.Counter(), collections.Counter(), []
    counts, by_depth, pruned = collections.Counter(), collections.defaultdict(lambda: [0, 0]), []

    class Recording(PatternTree):
        def _solve(self, node, mu_, stats):
            held = any(c & ~node.contact == 0 and g & ~node.gap == 0 for c, g in store)
            dec = super()._solve(node, mu_, stats)
            by_fixed[f"{dec.status}_{node.contact.bit_count()}_{node.gap.bit_count()}"] += 1
            counts[str(dec.status)] += 1
            if dec.status == Status.FEASIBLE or dec.status == Status.INFEASIBLE:
                by_depth[node.depth][dec.status == Status.INFEASIBLE] += 1
            if dec.status != Status.INFEASIBLE:
                counts["nogood_held_at_feasible"] += held          # must stay 0
                return dec
            counts["nogood_would_prune"] += held
            pruned.append(node)
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

    tree = Recording(param, m, tree_mu, **options)
    start = time.process_time()
    out = tree.explore(tree.root(), nodes or None)
    seconds = time.process_time() - start

    def infeasible(contact: list[int], gap: list[int]) -> bool:
        zu, zr = np.zeros(m, bool), np.zeros(m, bool)
        zu[contact], zr[gap] = True, True
        return decide(pattern_rows(param, m, zu, zr), tree_mu, DEFAULT_OPTIONS).status == Status.INFEASIBLE

    shrunk = []
    rng = np.random.default_rng(0)
    for k in sorted(rng.choice(len(pruned), min(cores, len(pruned)), replace=False).tolist()):
        node = pruned[k]
        contact, gap = [list(map(int, np.flatnonzero(b))) for b in node.masks(m)]
        core = minimal_core(infeasible, contact, gap)
        shrunk.append({"contact": contact, "gap": gap, "core_contact": core[0], "core_gap": core[1]})
    first = {}
    for i in range(m) if roots else ():
        again = PatternTree(param, m, tree_mu, **options)
        first[i] = sum(again.explore(kid, nodes or None).stats.nodes
                       for kid in (Subtree(1, 1 << i, 0), Subtree(1, 0, 1 << i))) + 1
    return {"body": f"neck-{levels}x{ring}-s0" if neck else f"plug3d-{levels}x{ring}", "levels": levels,
            "ring": ring, "m": m, "mu": tree_mu, "fraction_of_mu_c": fraction if neck else None,
            "seconds": seconds, "node_budget": nodes, "nodes": out.stats.nodes,
            "socps": out.stats.solves, "skipped": out.stats.skipped, "patterns": len(out.found),
            "found": [[n.contact, n.gap] for n in out.found],
            "finished": not out.open, "counts": dict(counts), "solves_by_status_contact_gap": dict(by_fixed),
            "feasible_infeasible_by_depth": {d: by_depth[d] for d in sorted(by_depth)},
            "nogood_sizes_contact_gap": dict(sizes), "cores": shrunk, "core_summary": core_summary(shrunk),
            "nodes_by_first_branching": first}


def core_summary(shrunk: list[dict]) -> dict:
    """Mean and least fixings and minimal-core sizes of the shrunk nodes (empty: {})."""
    if not shrunk:
        return {}
    fixed = [len(c["contact"]) + len(c["gap"]) for c in shrunk]
    core = [len(c["core_contact"]) + len(c["core_gap"]) for c in shrunk]
    return {"nodes": len(shrunk), "mean_fixings": sum(fixed) / len(fixed), "mean_core": sum(core) / len(core),
            "least_core": min(core), "largest_core": max(core),
            "mean_core_contacts": sum(len(c["core_contact"]) for c in shrunk) / len(shrunk)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, default=4)
    ap.add_argument("--ring", type=int, default=8)
    ap.add_argument("--mu", type=float, help="plug3d: default 0.2; --neck: its global mu^c (default: computed)")
    ap.add_argument("--nodes", type=int, default=0, help="tree nodes to explore (0: all)")
    ap.add_argument("--neck", action="store_true", help="the curved neck's settling tree instead of plug3d")
    ap.add_argument("--cores", type=int, default=0, help="infeasible nodes to shrink to a minimal core")
    ap.add_argument("--roots", action="store_true", help="the tree's size for every first branching node")
    ap.add_argument("--fractions", type=float, nargs="+", default=[1 + 1e-9],
                    help="--neck: the trees at these multiples of mu^c (default 1 + 1e-9)")
    ap.add_argument("--out", default=os.path.join(bench_2d.ROOT, "results", "bench_tree_pruning"))
    args = ap.parse_args()
    mu = 0.2 if args.mu is None and not args.neck else args.mu
    if args.neck and mu is None:
        mu = neck_mu_c(args.levels, args.ring)
    records = []
    for fraction in args.fractions if args.neck else [1 + 1e-9]:
        records.append(measure(args.levels, args.ring, mu, args.nodes, args.neck, args.cores, args.roots, fraction))
        summary(records[-1])
    harness.write_records(args.out, records, csv_file=False)


def summary(rec: dict) -> None:
    """Prints one tree's counts."""
    c = rec["counts"]
    at = f" ({rec['fraction_of_mu_c']} mu^c)" if rec["fraction_of_mu_c"] is not None else ""
    print(f"{rec['body']} mu {rec['mu']}{at}: {rec['nodes']} nodes, {rec['socps']} SOCPs "
          f"({c.get('feasible', 0)} feasible, {c.get('infeasible', 0)} infeasible), {rec['patterns']} patterns; "
          f"nogoods: mean {c.get('nogood_total', 0) / max(c.get('infeasible', 1), 1):.1f} of "
          f"{c.get('fixed_total', 0) / max(c.get('infeasible', 1), 1):.1f} fixings, "
          f"{c.get('nogood_would_prune', 0)} SOCPs a global store would have pruned; {rec['seconds']:.1f} s")
    print(json.dumps(rec["nogood_sizes_contact_gap"]))
    print("feasible, infeasible by depth:", json.dumps(rec["feasible_infeasible_by_depth"]))
    if rec["core_summary"]:
        print("minimal cores:", json.dumps(rec["core_summary"]))
    if rec["nodes_by_first_branching"]:
        print("tree nodes by first branching node:", json.dumps(rec["nodes_by_first_branching"]))


if __name__ == "__main__":
    main()
