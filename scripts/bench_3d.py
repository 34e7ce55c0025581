#!/usr/bin/env python3
"""3D sign patterns on plug3d (serial), timed through the product (hpcwedge.api.solve):
counts, SOCP solves against 2^m, timings, mu^c accuracy against tan(taper), solver statuses.

    PYTHONPATH=. python scripts/bench_3d.py [--levels 2 --ring 5] [--mu 0.55 0.6 0.65 0.7 1.0]
                                            [--no-brute] [--limit SECONDS]

Every case is one solve of a plug3d scene without its symmetry (run.symmetry = false: the
whole tree), in a child process under the time limit (harness.run_call):

  per mu     compute.mu_c = "none": the patterns stage (timings.enumerate, stats.bnb,
             stats.socp_statuses), then the brute force (one SOCP per partition, 2^m:
             reference.brute_force_patterns) as the peer, with the pattern sets compared
  mu^c       at the largest mu, compute.mu_c = "cones": mu^c of every pattern found there
             (timings.mu_c, stats.lp_solves, stats.mu_c_polished)
  global     compute.enumerate = false: the global mu^c search, no enumeration

Same-answer checks (harness.Checks): the tree's patterns equal the brute force's; the global
mu^c equals the least pattern mu^c (to 1e-9). Writes results/bench_3d_<levels>x<ring>.json
and prints a table; exit status 1 when a check failed.
"""
from __future__ import annotations

import argparse
import math
import os
import time

from harness import OK, RESULTS, Checks, pattern_hash, run_call, write_json

import hpcwedge as hw
from hpcwedge.nodesets import bits_to_nodes


def scene(args, mu, **compute) -> hw.Scene:
    """The benchmark body at the listed mu, without its symmetry."""
    return hw.Scene.from_dict({"name": "p", "dim": 3, "friction": {"mu": list(mu)},
                               "model": {"kind": "plug3d", "levels": args.levels, "ring": args.ring,
                                         "taper_deg": args.taper},
                               "compute": compute, "run": {"symmetry": False}})


def solved(sc: hw.Scene) -> dict:
    """A case: the scene solved (hpcwedge.solve), what the table needs of its Result."""
    r = hw.solve(sc)
    stats = r.stats
    return {"m": r.m, "timings": r.timings, "mu_c": r.mu_c, "mu_c_status": r.mu_c_status,
            "bnb": stats["bnb"], "statuses": stats.get("socp_statuses"), "lp_solves": stats["lp_solves"],
            "polished": stats["mu_c_polished"], "undecided": stats.get("patterns_undecided"),
            "patterns": [[p.contact, p.mu_c] for p in r.runs[0].patterns or []]}


def brute(sc: hw.Scene, mu: float) -> dict:
    """The reference: one SOCP per partition (reference.brute_force_patterns)."""
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.contact.problem import parametrize
    from hpcwedge.reference import brute_force_patterns
    prob = contact_problem(sc)
    param, counts = parametrize(prob), {}
    t = time.perf_counter()
    found = brute_force_patterns(param, prob.m, mu, counts)
    return {"patterns": [list(bits_to_nodes(b, prob.m)) for b in found], "statuses": counts,
            "seconds": time.perf_counter() - t}


def dimension(sc: hw.Scene) -> int:
    """d, the dimension of the parametrized problem (a description of the body, not timed)."""
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.contact.problem import parametrize
    return parametrize(contact_problem(sc)).d


def _case(rec: dict, what: str) -> dict | None:
    """The value of a case that finished, else None (its status printed)."""
    if rec["status"] != OK:
        print(f"{what}: {rec['status']} after {rec['seconds']} s {rec.get('error', '')}", flush=True)
        return None
    return rec["value"]


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--levels", type=int, default=2)
    ap.add_argument("--ring", type=int, default=5)
    ap.add_argument("--taper", type=float, default=10.0)
    ap.add_argument("--mu", type=float, nargs="+", default=[0.55, 0.60, 0.65, 0.70, 1.00])
    ap.add_argument("--no-brute", action="store_true")
    ap.add_argument("--limit", type=float, default=None, help="seconds per case (default: none)")
    args = ap.parse_args()
    checks = Checks(rel_tol=1e-9)
    sc = scene(args, args.mu[:1], mu_c="none")
    d = dimension(sc)
    rows, setup, m = [], None, None
    print(f"{'mu':>6} {'patterns':>8} {'SOCPs':>6} {'skipped':>7} {'nodes':>6} {'2^m':>6} {'B&B s':>7} "
          f"{'brute s':>8} {'same':>5}")
    for mu in args.mu:
        rec = run_call(solved, scene(args, [mu], mu_c="none"), limit=args.limit)
        out = _case(rec, f"mu = {mu}")
        if out is None:
            rows.append({"mu": mu, "status": rec["status"], "seconds": rec["seconds"]})
            continue
        m, bnb, got = out["m"], out["bnb"], [p for p, _ in out["patterns"]]
        setup = out["timings"]["condense"]
        row = {"mu": mu, "patterns": len(got), "undecided": out["undecided"], "solves": bnb["solves"],
               "skipped": bnb["skipped"], "nodes": bnb["nodes"], "partitions": 2 ** m,
               "bnb_seconds": round(out["timings"]["enumerate"], 3), "statuses": out["statuses"]}
        same = "-"
        if not args.no_brute:
            ref = _case(run_call(brute, sc, mu, limit=args.limit), f"brute force at mu = {mu}")
            if ref is not None:
                row["brute_seconds"] = round(ref["seconds"], 3)
                row["brute_statuses"] = ref["statuses"]
                row["brute_equal"] = checks.compare(f"mu = {mu}: tree against brute force",
                                                    pattern_hash(got), pattern_hash(ref["patterns"]))
                same = str(row["brute_equal"])
        rows.append(row)
        print(f"{mu:6.3g} {len(got):8d} {bnb['solves']:6d} {bnb['skipped']:7d} {bnb['nodes']:6d} "
              f"{2 ** m:6d} {row['bnb_seconds']:7.2f} {row.get('brute_seconds', float('nan')):8.2f} {same:>5}",
              flush=True)
    mu = args.mu[-1]
    pats = _case(run_call(solved, scene(args, [mu], mu_c="cones"), limit=args.limit), f"mu^c at mu = {mu}")
    glob = _case(run_call(solved, scene(args, [mu], enumerate=False, mu_c="global", mu_max=100.0),
                          limit=args.limit), "global mu^c")
    want = math.tan(math.radians(args.taper))
    summary = {"m": m, "d": d, "setup_seconds": None if setup is None else round(setup, 3), "runs": rows}
    if pats is not None:
        values = [v for _, v in pats["patterns"]]
        summary["mu_c_patterns"] = {"mu": mu, "n": len(values), "polished": pats["polished"],
                                    "solves": pats["lp_solves"], "seconds": round(pats["timings"]["mu_c"], 3),
                                    "min": min(values) if values else None}
        print(f"mu^c of the {len(values)} patterns at mu = {mu}: {pats['polished']} polished, "
              f"{pats['lp_solves']} solves, {pats['timings']['mu_c']:.2f} s; least {summary['mu_c_patterns']['min']!r}")
    if glob is not None:
        g = glob["mu_c"]
        summary["global"] = {"mu_c": g, "status": glob["mu_c_status"], "tan_taper": want,
                             "rel_error": None if g is None else abs(g - want) / want,
                             "seconds": round(glob["timings"]["mu_c"], 3), "solves": glob["bnb"]["solves"]}
        print(f"global mu^c (no enumeration): {g!r} ({glob['mu_c_status']}), tan(taper) = {want!r}, "
              f"rel. error {summary['global']['rel_error']:.1e}, {glob['timings']['mu_c']:.2f} s, "
              f"{glob['bnb']['solves']} solves")
    if pats is not None and glob is not None and pats["patterns"]:
        checks.compare("global mu^c against the least pattern mu^c", {"mu_c": glob["mu_c"]},
                       {"mu_c": summary["mu_c_patterns"]["min"]})
    path = write_json(os.path.join(RESULTS, f"bench_3d_{args.levels}x{args.ring}.json"), summary)
    print("wrote", path)
    return checks.exit_status()


if __name__ == "__main__":
    raise SystemExit(main())
