#!/usr/bin/env python3
"""3D sign patterns on plug3d (serial): counts, SOCP solves against 2^m, timings,
mu^c accuracy against tan(taper), solver statuses.

    PYTHONPATH=. python scripts/bench_3d.py [--levels 2 --ring 5] [--mu 0.55 0.6 0.65 0.7 1.0]

For each mu: the branch and bound (PatternTree over the whole tree), then the
brute force (one SOCP per partition, 2^m: reference.brute_force_patterns) as the
peer, both timed, with their pattern sets compared; then mu^c of every pattern found at the largest mu and
the global mu^c. Writes results/bench_3d_<levels>x<ring>.json and prints a table.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import time

from hpcwedge.contact.build import contact_problem
from hpcwedge.contact.problem import parametrize
from hpcwedge.environment import environment
from hpcwedge.mu_c.critical import mu_critical
from hpcwedge.mu_c.global_search import global_mu_critical
from hpcwedge.patterns.tree import BnBStats, PatternTree, Subtree
from hpcwedge.reference import brute_force_patterns
from hpcwedge.scene.parse import parse_scene


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--levels", type=int, default=2)
    ap.add_argument("--ring", type=int, default=5)
    ap.add_argument("--taper", type=float, default=10.0)
    ap.add_argument("--mu", type=float, nargs="+", default=[0.55, 0.60, 0.65, 0.70, 1.00])
    ap.add_argument("--no-brute", action="store_true")
    args = ap.parse_args()
    sc = parse_scene({"name": "p", "dim": 3, "friction": {"mu": args.mu},
                      "model": {"kind": "plug3d", "levels": args.levels, "ring": args.ring,
                                "taper_deg": args.taper}})
    t = time.perf_counter()
    prob = contact_problem(sc)
    p = parametrize(prob)
    m = prob.m
    setup = time.perf_counter() - t
    rows = []
    print(f"plug3d {args.levels}x{args.ring} taper {args.taper} deg: m = {m}, d = {p.d}, "
          f"rigid modes {prob.N.shape[1]}, setup {setup:.2f} s")
    print(f"{'mu':>6} {'patterns':>8} {'SOCPs':>6} {'skipped':>7} {'nodes':>6} {'2^m':>6} {'B&B s':>7} "
          f"{'brute s':>8} {'same':>5}")
    found_last = None
    for mu in args.mu:
        tree = PatternTree(p, m, mu)
        t = time.perf_counter()
        out = tree.explore(tree.root())
        t_bnb = time.perf_counter() - t
        got = sorted(s.contact for s in out.found)
        row = {"mu": mu, "patterns": len(got), "undecided": len(out.undecided), "solves": out.stats.solves,
               "skipped": out.stats.skipped, "nodes": out.stats.nodes, "partitions": 2 ** m,
               "bnb_seconds": round(t_bnb, 3), "statuses": out.stats.statuses}
        same = "-"
        if not args.no_brute:
            t = time.perf_counter()
            counts = {}
            brute = brute_force_patterns(p, m, mu, counts)
            row["brute_seconds"] = round(time.perf_counter() - t, 3)
            row["brute_statuses"] = counts
            row["brute_equal"] = brute == got
            same = str(brute == got)
        rows.append(row)
        found_last = (mu, got)
        print(f"{mu:6.3g} {len(got):8d} {out.stats.solves:6d} {out.stats.skipped:7d} {out.stats.nodes:6d} "
              f"{2 ** m:6d} {t_bnb:7.2f} {row.get('brute_seconds', float('nan')):8.2f} {same:>5}", flush=True)
    mu, got = found_last
    t = time.perf_counter()
    polished, lps, values = 0, 0, []
    for bits in got:
        zu = Subtree(m, contact=bits).masks(m)[0]
        r = mu_critical(p, m, zu, ~zu, mu_hi=mu)
        polished += r.polished
        lps += r.solves
        values.append(r.mu_c)
    t_muc = time.perf_counter() - t
    t = time.perf_counter()
    st = BnBStats()
    g, status = global_mu_critical(p, m, 100.0, stats=st)
    t_glob = time.perf_counter() - t
    want = math.tan(math.radians(args.taper))
    summary = {"m": m, "d": p.d, "setup_seconds": round(setup, 3), "runs": rows,
               "mu_c_patterns": {"mu": mu, "n": len(got), "polished": polished, "solves": lps,
                                 "seconds": round(t_muc, 3), "min": min(values) if values else None},
               "global": {"mu_c": g, "status": status, "tan_taper": want,
                          "rel_error": None if g is None else abs(g - want) / want,
                          "seconds": round(t_glob, 3), "solves": st.solves}}
    print(f"mu^c of the {len(got)} patterns at mu = {mu}: {polished} polished, {lps} solves, {t_muc:.2f} s; "
          f"least {summary['mu_c_patterns']['min']!r}")
    print(f"global mu^c (no enumeration): {g!r} ({status}), tan(taper) = {want!r}, "
          f"rel. error {summary['global']['rel_error']:.1e}, {t_glob:.2f} s, {st.solves} solves")
    os.makedirs("results", exist_ok=True)
    path = f"results/bench_3d_{args.levels}x{args.ring}.json"
    with open(path, "w") as f:
        json.dump({**summary, "environment": environment()}, f, indent=1)
    print("wrote", path)


if __name__ == "__main__":
    main()
