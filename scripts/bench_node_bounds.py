#!/usr/bin/env python3
"""Could bound tightening + McCormick cuts prune the 3D tree's feasible nodes (issue 41)? Counts only.

    PYTHONPATH=. python scripts/bench_node_bounds.py [--levels 4 --ring 8 --mu 0.2] [--every 100]
                                                     [--prune-from D [--r-one]] [--out results/bench_node_bounds]

The tree of plug3d LEVELS x RING at mu (PatternTree with `hpcwedge run`'s options, symmetry off),
explored to the end. At every --every-th node whose SOCP is feasible (a sample of the nodes a
nogood cannot prune, bench_tree_pruning.py):
  pinned   whether the node's contact set pins the rigid amplitudes (the u_n rows of beta on the
           contact nodes have full column rank nb; a sufficient condition for bounded u at sum r_n = 1)
  obbt     per free node i, R_i = max r_n,i and U_i = max u_n,i over the node's relaxation (one
           steered SOCP each, socp.pattern_attempts attempt 0; DualInfeasible: U_i unbounded)
  cut      the node's SOCP (pattern_socp, through the retry ladder socp.attempts) again with the
           McCormick cut r_n,i / R_i + u_n,i / U_i <= 1 (both bounds times 1 + SLACK) of every free
           node with finite bounds: a certified infeasible one means the cuts would have pruned the
           node and its whole subtree
--prune-from D: instead of sampling, every solved feasible inner node of depth >= D gets the
bounds and cuts and is pruned when they make it infeasible (the tree's own counts, plus
counts["bound_socps"], the bound solves); --r-one: R_i = 1 (r_n,i <= sum r_n), no r_n solves.
Valid: each cut holds at every point of the node's relaxation with r_n,i u_n,i = 0, so at every
wedged state below it; a pruned sampled node whose subtree holds a found pattern is counted as
"cut_invalid" (must be 0), and a pruned tree must find the same patterns ("found").
Bounds from uncertified optima (SLACK covers Clarabel's tolerance; a production version would take
the dual bound). Writes <out>.json (with the environment record); prints a summary.
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import sys
from dataclasses import replace

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import bench_2d  # noqa: E402
import harness  # noqa: E402
from bench_near_critical import plug_scene  # noqa: E402

#: relative slack on the bound-LP optima (their solves are not certified)
SLACK = 1e-6


def node_bounds(param, m, mu, zu, zr, r_one: bool = False):
    """(R, U) over the free nodes' (r_n,i, u_n,i) maxima at sum r_n = 1 (nan: undecided,
    inf: unbounded), and the node's rows. r_one: R = 1 (r_n,i <= sum r_n = 1), no solve."""
    import numpy as np

    from hpcwedge.contact.problem import blocks
    from hpcwedge.solvers.rows import pattern_rows
    from hpcwedge.solvers.socp import pattern_attempts

    rows = pattern_rows(param, m, zu, zr)
    Un, Rn = blocks(param.U, m, 3)[0], blocks(param.R, m, 3)[0]
    free = (~zu & ~zr).nonzero()[0]
    out = {}
    for name, B in (("R", Rn), ("U", Un)):
        if name == "R" and r_one:
            out[name] = np.ones(len(free))
            continue
        vals = []
        for i in free:
            o = next(pattern_attempts(rows, mu, True, objective=-B[i]))
            if o.x is not None:
                vals.append(float(B[i] @ o.x / (rows.norm @ o.x)))
            else:
                vals.append(np.inf if o.name == "DualInfeasible" else np.nan)
        out[name] = np.array(vals)
    return free, out["R"], out["U"], rows, Un, Rn


def cut_status(rows, mu, free, R, U, Un, Rn):
    """Clarabel's status name of the node's SOCP with the McCormick cuts added (the first decided
    attempt of the ladder, else the last attempt's)."""
    import numpy as np

    from hpcwedge.solvers.conic import ConicProblem
    from hpcwedge.solvers.rows import Status
    from hpcwedge.solvers.socp import attempts, certificate_ok, pattern_socp

    p = pattern_socp(rows, mu)
    ok = np.isfinite(R) & np.isfinite(U) & (R > 0) & (U > 0)
    if not ok.any():
        return "no_cut"
    cuts = np.array([Rn[i] / (R[k] * (1 + SLACK)) + Un[i] / (U[k] * (1 + SLACK))
                     for k, i in enumerate(free) if ok[k]]) @ rows.Z
    A = np.vstack([p.A[:p.n_zero + p.n_lin], cuts, p.A[p.n_zero + p.n_lin:]])
    b = np.concatenate([p.b[:p.n_zero + p.n_lin], np.ones(len(cuts)), p.b[p.n_zero + p.n_lin:]])
    name, cut = "none", ConicProblem(A, b, p.n_zero, p.n_lin + len(cuts), p.n_soc)
    for _, sol in attempts(cut, False):
        name = sol.name
        if sol.status == Status.INFEASIBLE:
            return name if certificate_ok(A, b, sol.z, cut.n_zero, cut.n_lin) else "uncertified"
        if sol.status != Status.UNDECIDED:
            break
    return name


def measure(levels: int, ring: int, mu: float, every: int, prune_from: int | None = None,
            r_one: bool = False) -> dict:
    """The counts of the module doc for one tree."""
    import numpy as np

    from hpcwedge.contact.build import contact_problem
    from hpcwedge.contact.problem import parametrize
    from hpcwedge.patterns.tree import PatternTree
    from hpcwedge.solvers.rows import Status

    prob = contact_problem(plug_scene(levels, ring, mu))
    param, m = parametrize(prob), prob.m
    form = param.reactions
    n = form.E.shape[1]
    G = form.U[:m, n:]
    nb = G.shape[1]
    counts, samples = collections.Counter(), []

    class Recording(PatternTree):
        def _solve(self, node, mu_, stats):
            dec = super()._solve(node, mu_, stats)
            if dec.status != Status.FEASIBLE:
                return dec
            counts["feasible"] += 1
            zu, zr = node.masks(m)
            pinned = bool(nb == 0 or (zu.any() and np.linalg.matrix_rank(G[zu]) == nb))
            counts["pinned"] += pinned
            if prune_from is not None:
                if prune_from <= node.depth < m:
                    free, R, U, rows, Un, Rn = node_bounds(param, m, mu_, zu, zr, r_one)
                    counts["bound_socps"] += (1 if r_one else 2) * len(free)
                    if cut_status(rows, mu_, free, R, U, Un, Rn) == "PrimalInfeasible":
                        counts["pruned_by_cuts"] += 1
                        return replace(dec, status=Status.INFEASIBLE, x=None)
                return dec
            if counts["feasible"] % every == 1 or every == 1:
                free, R, U, rows, Un, Rn = node_bounds(param, m, mu_, zu, zr)
                status = cut_status(rows, mu_, free, R, U, Un, Rn)
                samples.append({"contact": node.contact, "gap": node.gap, "depth": node.depth,
                                "pinned": pinned, "free": int(len(free)),
                                "u_bounded": int(np.isfinite(U).sum()), "u_undecided": int(np.isnan(U).sum()),
                                "r_max": float(np.nanmax(R)) if len(R) else None, "cut": status})
            return dec

    tree = Recording(param, m, mu)
    out = tree.explore(tree.root())
    found = [(s.contact, s.gap) for s in out.found]
    for s in samples:
        below = any(c & s["contact"] == s["contact"] and g & s["gap"] == s["gap"] for c, g in found)
        s["holds_pattern"] = below
        counts["sampled"] += 1
        counts["sampled_pinned"] += s["pinned"]
        counts["sampled_u_bounded_somewhere"] += s["u_bounded"] > 0
        counts["cut_" + s["cut"]] += 1
        counts["cut_invalid"] += s["cut"] == "PrimalInfeasible" and below
    return {"levels": levels, "ring": ring, "m": m, "mu": mu, "nb": nb, "every": every, "prune_from": prune_from,
            "r_one": r_one,
            "found": found,
            "nodes": out.stats.nodes, "socps": out.stats.solves, "patterns": len(out.found),
            "counts": dict(counts), "samples": samples}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, default=4)
    ap.add_argument("--ring", type=int, default=8)
    ap.add_argument("--mu", type=float, default=0.2)
    ap.add_argument("--every", type=int, default=100, help="sample every k-th feasible node")
    ap.add_argument("--prune-from", type=int, default=None,
                    help="instead of sampling: prune every feasible node of depth >= this whose cuts make it infeasible")
    ap.add_argument("--r-one", action="store_true", help="R_i = 1 in the cuts (no r_n bound solves)")
    ap.add_argument("--out", default=os.path.join(bench_2d.ROOT, "results", "bench_node_bounds"))
    args = ap.parse_args()
    rec = measure(args.levels, args.ring, args.mu, args.every, args.prune_from, args.r_one)
    harness.write_records(args.out, [rec], csv_file=False)
    print(f"plug3d {args.levels} x {args.ring} mu {args.mu}: {rec['nodes']} nodes, {rec['socps']} SOCPs, "
          f"{rec['patterns']} patterns, nb = {rec['nb']}")
    print(json.dumps(rec["counts"]))


if __name__ == "__main__":
    main()
