#!/usr/bin/env python3
"""3D numerical stress (SPEC §7, tapers down to 0.1 deg and below): plug3d without its
symmetry at tapers 10 .. 0.001 deg.

    PYTHONPATH=. python scripts/stress_3d.py [--quick] [--levels 3] [--ring 6]
                                             [--tapers 10 1 0.1 0.01 0.001] [--limit 300]
                                             [--out results/stress_3d]

Each case is one `hpcwedge run` pipeline (pipeline.run_scene) in its own process, killed
at --limit seconds (harness.run_call: status "timeout"):
  enumerate   mu = 1.5 tan(taper): the feasible patterns, each one's mu^c, the global
              mu^c from them (compute.mu_c = "cones")
  enumerate65 mu = 0.65, the same (the issue-13 scene at 10 deg)
  global      enumerate = false, mu_c = "global" (the global search alone)
Per case: patterns, SOCPs, the share of the tree's SOCPs (the enumeration's; global: the
settling tree's) that Clarabel decided on its first attempt, pyramid LPs, undecided tree
nodes, mu^c polished/unpolished, seconds, and the global mu^c's error
against the analytic tan(taper) (plug3d in a symmetric taper). Counts are the same on
every machine of one kind; seconds are one shared 2-core machine's.
Writes <out>.csv and <out>.json (with the environment record) and prints the table.
"""
from __future__ import annotations

import argparse
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import bench_2d  # noqa: E402  (fmt_s)
from harness import ERROR, OK, RESULTS, run_call, write_records  # noqa: E402

KINDS = ("enumerate", "enumerate65", "global")
COLS = ["kind", "levels", "ring", "m", "taper_deg", "mu", "status", "patterns", "solves", "first_attempt",
        "first_attempt_share", "lps", "undecided", "mu_c_polished", "mu_c_unpolished", "mu_c", "rel_error",
        "enumerate_s", "mu_c_s", "total_s", "wall"]


def scene(kind: str, levels: int, ring: int, taper: float) -> dict:
    mu = 0.65 if kind == "enumerate65" else 1.5 * math.tan(math.radians(taper))
    return {"name": f"plug3d-{levels}x{ring}-{taper:g}deg", "dim": 3,
            "model": {"kind": "plug3d", "levels": levels, "ring": ring, "taper_deg": taper},
            "friction": {"mu": [mu]},
            "compute": {"enumerate": kind != "global", "mu_c": "global" if kind == "global" else "cones"},
            "run": {"symmetry": False}}


def worker(kind: str, levels: int, ring: int, taper: float) -> dict:
    """One case through run_scene: its counts and seconds."""
    from hpcwedge.run.pipeline import run_scene
    from hpcwedge.scene.parse import parse_scene
    data = scene(kind, levels, ring, taper)
    res = run_scene(parse_scene(data))
    st = res.stats
    jobs = st["parallel"]["jobs"]
    tree = jobs.get("patterns") or jobs.get("global_patterns") or {}
    bnb = st.get("bnb") or {}
    solves = int(bnb.get("solves", 0))
    # first attempts: the statuses of the enumeration's tree (global: the settling tree's)
    # that carry no retry prefix
    first = sum(int(v) for k, v in tree.items() if k in ("status_Solved", "status_PrimalInfeasible"))
    tree_solves = int(tree.get("solves", 0))
    return {"m": res.m, "mu": data["friction"]["mu"][0],
            "patterns": None if res.runs[0].patterns is None else len(res.runs[0].patterns),
            "solves": solves, "tree_solves": tree_solves, "first_attempt": first,
            "first_attempt_share": first / tree_solves if tree_solves else None,
            "lps": int(bnb.get("lps", 0)), "undecided": int(bnb.get("undecided", 0)),
            "tree_undecided": int(tree.get("undecided", 0)),
            "mu_c_polished": st.get("mu_c_polished"), "mu_c_unpolished": st.get("mu_c_unpolished"),
            "mu_c": res.mu_c, "enumerate_s": res.timings.get("enumerate"), "mu_c_s": res.timings.get("mu_c"),
            "total_s": res.timings.get("total")}


def line(r: dict) -> str:
    if r["status"] != "ok":
        return f"{r['kind']:11s} {r['taper_deg']:>6g} deg  {r['status']} ({bench_2d.fmt_s(r.get('wall'))} s)"
    share = r["first_attempt_share"]
    err = r["rel_error"]
    return (f"{r['kind']:11s} {r['taper_deg']:>6g} deg  patterns {r['patterns'] if r['patterns'] is not None else '-':>4}"
            f"  SOCPs {r['solves']:6d}  first {'-' if share is None else f'{100 * share:5.1f} %'}"
            f"  LPs {r['lps']:4d}  undecided {r['undecided']:2d}  polished {r['mu_c_polished']}/"
            f"{(r['mu_c_polished'] or 0) + (r['mu_c_unpolished'] or 0)}"
            f"  mu^c err {'-' if err is None else f'{err:.1e}'}  {bench_2d.fmt_s(r['total_s'])} s")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="plug3d 2 x 5, tapers 10, 0.1 and 0.01 deg")
    ap.add_argument("--levels", type=int, default=None)
    ap.add_argument("--ring", type=int, default=None)
    ap.add_argument("--tapers", type=float, nargs="*", default=None)
    ap.add_argument("--kinds", nargs="*", default=list(KINDS), choices=KINDS)
    ap.add_argument("--limit", type=float, default=300.0, help="seconds per case")
    ap.add_argument("--out", default=os.path.join(RESULTS, "stress_3d"))
    args = ap.parse_args()
    levels = args.levels or (2 if args.quick else 3)
    ring = args.ring or (5 if args.quick else 6)
    tapers = args.tapers or ([10.0, 0.1, 0.01] if args.quick else [10.0, 1.0, 0.1, 0.01, 0.001])
    records = []
    for taper in tapers:
        for kind in args.kinds:
            case = run_call(worker, kind, levels, ring, taper, limit=args.limit)
            rec = {"kind": kind, "levels": levels, "ring": ring, "taper_deg": taper, "status": case["status"],
                   "wall": case["seconds"]}
            if case["status"] == OK:
                res = case["value"]
                rec.update(res)
                want = math.tan(math.radians(taper))
                rec["rel_error"] = None if res["mu_c"] is None else abs(res["mu_c"] - want) / want
            elif case["status"] == ERROR:
                rec["error"] = case["error"]
            records.append(rec)
            print(line(rec), flush=True)
    write_records(args.out, records, COLS, extra={"levels": levels, "ring": ring, "limit_s": args.limit,
                                                  "analytic_mu_c": "tan(taper)"})
    print(f"wrote {args.out}.csv and {args.out}.json")
    ok = [r for r in records if r["status"] == "ok"]
    worst = max((r["rel_error"] for r in ok if r["rel_error"] is not None), default=None)
    print(f"{len(ok)} of {len(records)} cases finished; undecided tree nodes {sum(r['undecided'] for r in ok)}; "
          f"pyramid LPs {sum(r['lps'] for r in ok)}; worst mu^c error {'-' if worst is None else f'{worst:.1e}'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
