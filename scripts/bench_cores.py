#!/usr/bin/env python3
"""How much conflict learning could save in the 3D sign-pattern tree (issue 13): counts.

    PYTHONPATH=. python scripts/bench_cores.py [--scenes 2x6 3x5 3x6] [--mu 0.65]
                                               [--out results/bench_cores]

Each scene is plug3d LEVELSxRING at mu without symmetry (bench_search_3d.scene), its
enumeration tree walked node by node through the product's own PatternTree.explore
(budget 1, each open child handed back with its witness: the same tree as one pass).
Every tree node that the SOCP proves infeasible is then shrunk to a minimal infeasible
subset of its fixings by a deletion filter (drop one fixed node; keep it dropped when the
rest is still infeasible; feasibility.decide on rows.pattern_rows, the tree's own test).
Reported per scene: tree nodes, SOCPs, feasible patterns; the nodes with a feasible
relaxation, split into live ones (a pattern found below them) and dead ones (none), by
depth: the live nodes are what a tree that never solved a node without a pattern below
would solve; the roots of the dead subtrees (a node without a pattern below, its parent
with one): live nodes plus these are what a tree solves that recognises a dead subtree at
its root at the price of one SOCP; infeasible nodes and their depths; minimal cores' sizes and how many are distinct; the infeasible nodes that an
earlier node's minimal core covers (the most that learning minimal cores, at any price,
could prune in this tree order); the deletion filter's SOCPs; and what the tree's own core
learning (PatternTree(learn_cores=True): the part of the interior-point certificate that is
used) prunes. Counts only: the same on every machine.
Writes <out>.json; prints a summary.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import NamedTuple

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from bench_search_3d import scene  # noqa: E402


class Walk(NamedTuple):
    """The enumeration tree walked node by node: the masks (zu, zr) of its infeasible nodes
    and of its nodes with a feasible relaxation, in depth-first order; its node and SOCP
    counts; the masks of the feasible patterns found."""

    infeasible: list
    feasible: list
    nodes: int
    solves: int
    patterns: list


def tree_nodes(param, m: int, mu: float) -> Walk:
    """The enumeration tree's nodes in depth-first order (Walk)."""
    from hpcwedge.patterns.tree import PatternTree
    tree = PatternTree(param, m, mu)
    stack, infeasible, feasible, patterns = [(tree.root(), None)], [], [], []
    nodes = solves = 0
    while stack:
        node, x = stack.pop()
        ex = tree.explore(node, budget=1, x=x)
        nodes += ex.stats.nodes
        solves += ex.stats.solves
        patterns += [f.masks(m) for f in ex.found]
        if not ex.found and not ex.open and not ex.stats.undecided:
            infeasible.append(node.masks(m))
        else:
            feasible.append(node.masks(m))
        stack.extend(reversed(list(zip(ex.open, ex.open_x))))
    return Walk(infeasible, feasible, nodes, solves, patterns)


def live(feasible: list, patterns: list) -> np.ndarray:
    """Of the nodes `feasible` (masks), those with a pattern of `patterns` below them (its
    contact set holds the node's, its gap set the node's gap set): boolean, in order."""
    if not patterns:
        return np.zeros(len(feasible), bool)
    PU = np.array([zu for zu, _ in patterns])
    PR = np.array([zr for _, zr in patterns])
    return np.array([bool(((PU | ~zu).all(axis=1) & (PR | ~zr).all(axis=1)).any()) for zu, zr in feasible],
                    dtype=bool)


def dead_roots(walk: Walk, alive: np.ndarray) -> int:
    """The tree nodes without a pattern below whose parent has one (the roots of the maximal
    dead subtrees). A node's parent is the tree node one fixing shallower whose fixings it
    holds (two tree nodes of one depth conflict in some fixing, so there is only one)."""
    lu = np.array([zu for (zu, _), a in zip(walk.feasible, alive) if a])
    lr = np.array([zr for (_, zr), a in zip(walk.feasible, alive) if a])
    depth = lu.sum(axis=1) + lr.sum(axis=1)
    dead = [f for f, a in zip(walk.feasible, alive) if not a] + list(walk.infeasible)
    return sum(bool(((depth == zu.sum() + zr.sum() - 1) & (~lu | zu).all(axis=1) & (~lr | zr).all(axis=1)).any())
               for zu, zr in dead)


def minimal_core(param, m: int, mu: float, zu: np.ndarray, zr: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """A minimal infeasible subset of the fixings (zu, zr) by a deletion filter, and its SOCPs."""
    from hpcwedge.solvers.feasibility import TREE_OPTIONS, decide
    from hpcwedge.solvers.rows import Status, pattern_rows
    cu, cr, socps = zu.copy(), zr.copy(), 0
    for i in np.flatnonzero(zu | zr):
        tu, tr = cu.copy(), cr.copy()
        tu[i] = tr[i] = False
        socps += 1
        if decide(pattern_rows(param, m, tu, tr), mu, TREE_OPTIONS).status == Status.INFEASIBLE:
            cu, cr = tu, tr
    return cu, cr, socps


def study(levels: int, ring: int, mu: float) -> dict:
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.contact.problem import parametrize
    from hpcwedge.patterns.tree import PatternTree
    prob = contact_problem(scene("enumerate", levels, ring))
    param, m = parametrize(prob), prob.m
    t0 = time.process_time()
    walk = tree_nodes(param, m, mu)
    infeasible, nodes, solves, found = walk.infeasible, walk.nodes, walk.solves, len(walk.patterns)
    alive = live(walk.feasible, walk.patterns)
    cores, filter_socps = [], 0
    for zu, zr in infeasible:
        cu, cr, k = minimal_core(param, m, mu, zu, zr)
        cores.append((cu, cr))
        filter_socps += k
    covered = sum(any(not (cu & ~zu).any() and not (cr & ~zr).any() for cu, cr in cores[:k])
                  for k, (zu, zr) in enumerate(infeasible))
    learnt = PatternTree(param, m, mu, learn_cores=True)
    own = learnt.explore(learnt.root()).stats
    sizes = [int(cu.sum() + cr.sum()) for cu, cr in cores]
    depths = [int(zu.sum() + zr.sum()) for zu, zr in infeasible]
    fdepths = np.array([int(zu.sum() + zr.sum()) for zu, zr in walk.feasible], dtype=int)
    return {"scene": f"plug3d {levels}x{ring}", "m": m, "mu": mu, "tree_nodes": nodes, "socps": solves,
            "patterns": found, "infeasible_nodes": len(infeasible),
            "infeasible_depths": np.bincount(depths, minlength=m + 1).tolist(),
            "feasible_nodes": len(walk.feasible), "live_nodes": int(alive.sum()),
            "dead_nodes": int((~alive).sum()),
            "live_depths": np.bincount(fdepths[alive], minlength=m + 1).tolist(),
            "dead_depths": np.bincount(fdepths[~alive], minlength=m + 1).tolist(),
            "live_nodes_per_pattern": round(int(alive.sum()) / max(found, 1), 1),
            "dead_roots": (roots := dead_roots(walk, alive)),
            "live_and_dead_roots_per_pattern": round((int(alive.sum()) + roots) / max(found, 1), 1),
            "minimal_core_sizes": np.bincount(sizes, minlength=m + 1).tolist(),
            "minimal_core_size_median": float(np.median(sizes)) if sizes else None,
            "distinct_minimal_cores": len({(cu.tobytes(), cr.tobytes()) for cu, cr in cores}),
            "covered_by_earlier_minimal_core": int(covered), "deletion_filter_socps": filter_socps,
            "learnt_cores_tree": {"socps": own.solves, "pruned": own.pruned},
            "cpu_seconds": round(time.process_time() - t0, 1)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["2x6", "3x5", "3x6"])
    ap.add_argument("--mu", type=float, default=0.65)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(HERE), "results", "bench_cores"))
    args = ap.parse_args(argv)
    rows = []
    for s in args.scenes:
        levels, ring = (int(v) for v in s.split("x"))
        r = study(levels, ring, args.mu)
        rows.append(r)
        print(f"{r['scene']} (m = {r['m']}, mu = {r['mu']}): {r['tree_nodes']} nodes, {r['socps']} SOCPs, "
              f"{r['patterns']} patterns; {r['feasible_nodes']} nodes with a feasible relaxation, "
              f"{r['live_nodes']} of them with a pattern below ({r['live_nodes_per_pattern']} per pattern), "
              f"{r['dead_nodes']} without; {r['dead_roots']} roots of dead subtrees "
              f"(live + roots: {r['live_and_dead_roots_per_pattern']} per pattern); "
              f"{r['infeasible_nodes']} infeasible nodes, minimal cores of "
              f"median size {r['minimal_core_size_median']} ({r['distinct_minimal_cores']} distinct), "
              f"{r['covered_by_earlier_minimal_core']} covered by an earlier one "
              f"(deletion filter: {r['deletion_filter_socps']} SOCPs); learnt cores prune "
              f"{r['learnt_cores_tree']['pruned']} ({r['learnt_cores_tree']['socps']} SOCPs)", flush=True)
    from hpcwedge.environment import environment
    with open(args.out + ".json", "w") as f:
        json.dump({"rows": rows, "environment": environment()}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
