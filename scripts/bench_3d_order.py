#!/usr/bin/env python3
"""Node order of the 3D sign-pattern branch and bound, by measurement.

    PYTHONPATH=. python scripts/bench_3d_order.py

Counts SOCP solves and time of PatternTree.explore over the whole tree for a few
node orders on plug3d (m = 10 and m = 12) and on random 3D bodies (m = 8, free and
supported). Writes results/bench_3d_order.json and prints a table.
Orders: natural (0..m-1), reversed, interleaved (0, m-1, 1, m-2, ...), by
decreasing coupling |k_tn| / k_nn of the single-node blocks (the node that would
wedge alone at the lowest mu first), and its reverse.
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))

from harness import RESULTS, write_json  # noqa: E402
from instances import random_problem_3d  # noqa: E402

from hpcwedge.contact.build import contact_problem  # noqa: E402
from hpcwedge.contact.problem import parametrize  # noqa: E402
from hpcwedge.patterns.tree import PatternTree  # noqa: E402
from hpcwedge.scene.parse import parse_scene  # noqa: E402


def orders(prob):
    m, K = prob.m, prob.K
    coupling = np.array([np.hypot(K[m + i, i], K[2 * m + i, i]) / max(K[i, i], 1e-300) for i in range(m)])
    inter = [v for pair in zip(range(m), range(m - 1, -1, -1)) for v in pair][:m]
    inter = list(dict.fromkeys(inter))
    return {"natural": list(range(m)), "reversed": list(range(m - 1, -1, -1)), "interleaved": inter,
            "coupling_desc": list(np.argsort(-coupling, kind="stable")),
            "coupling_asc": list(np.argsort(coupling, kind="stable"))}


def cases():
    for levels, ring in ((2, 5), (3, 4)):
        sc = parse_scene({"name": "p", "dim": 3, "model": {"kind": "plug3d", "levels": levels, "ring": ring},
                          "friction": {"mu": [1.0]}})
        prob = contact_problem(sc)
        for mu in (0.65, 1.0):
            yield f"plug3d {levels}x{ring} mu={mu}", prob, mu
    for seed in range(4):
        rng = np.random.default_rng(seed)
        free = bool(seed % 2)
        yield f"random m=8 {'free' if free else 'supported'} #{seed}", random_problem_3d(rng, 8, free), 2.0


def main():
    rows = []
    for name, prob, mu in cases():
        p = parametrize(prob)
        ref = None
        for oname, order in orders(prob).items():
            tree = PatternTree(p, prob.m, mu, order=[int(i) for i in order])
            t = time.perf_counter()
            out = tree.explore(tree.root())
            dt = time.perf_counter() - t
            got = sorted(s.contact for s in out.found)
            if ref is None:
                ref = got
            assert got == ref, (name, oname)
            rows.append({"case": name, "order": oname, "m": prob.m, "patterns": len(got),
                         "solves": out.stats.solves, "nodes": out.stats.nodes, "seconds": round(dt, 3)})
            print(f"{name:32s} {oname:14s} patterns {len(got):5d} solves {out.stats.solves:6d} "
                  f"nodes {out.stats.nodes:6d} {dt:7.2f} s", flush=True)
    tot = {}
    for r in rows:
        tot.setdefault(r["order"], [0, 0.0])
        tot[r["order"]][0] += r["solves"]
        tot[r["order"]][1] += r["seconds"]
    print("total:", {k: (v[0], round(v[1], 2)) for k, v in tot.items()})
    write_json(os.path.join(RESULTS, "bench_3d_order.json"), {"rows": rows, "total": tot})


if __name__ == "__main__":
    main()
