#!/usr/bin/env python3
"""2D global mu^c through `hpcwedge run`'s route with HiGHS's LPs (issue 41): seconds and LP
counts, of this checkout or of another one (before / after a change), in one record.

    PYTHONPATH=. python scripts/bench_highs_lp.py [--quick] [--limit 300] [--checkout DIR]
                                                  [--only MODEL:ROWS ...] [--out results/bench_highs_lp]

Scenes: plug2d rows 80 / 160 / 320 (m = 160 / 320 / 640) and block2d rows 79 / 159 (refine 1,
m = 160 / 320), taper 10 deg (global mu^c = tan 10 deg analytically), `enumerate = false`,
`mu_c = "global"`, `run.symmetry = false`; --quick: the m = 160 scenes only. Each scene runs
in its own process, killed at --limit seconds ("timeout"). --checkout DIR: import hpcwedge
from DIR (e.g. an unpacked `git archive` of the commit before) instead of this checkout.
Counts (tree nodes, LP solves of the tree and the pattern bisections, MILPs and their nodes) are the same on every machine;
seconds are not (2 cores shared with other jobs: read them as +-30 %; cpu_with_setup, this
process's CPU seconds for the whole run, is less sensitive to the sharing). Error: relative to
tan(10 deg). Writes <out>.csv and <out>.json (with the environment record); prints the table.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import bench_2d  # noqa: E402

CASES = (("plug2d", 80), ("plug2d", 160), ("plug2d", 320), ("block2d", 79), ("block2d", 159))
QUICK = (("plug2d", 80), ("block2d", 79))
TAPER = 10.0
COLS = ["model", "rows", "m", "status", "seconds", "cpu_with_setup", "mu_c", "error", "route", "tree_nodes", "lps",
        "milp_solves", "milp_nodes", "undecided"]


def scene(model: str, rows: int):
    from hpcwedge.scene.parse import parse_scene
    return parse_scene({"name": f"{model}-r{rows}", "dim": 2,
                        "model": {"kind": model, "rows": rows, "taper_deg": TAPER},
                        "friction": {"mu": [0.1]}, "compute": {"enumerate": False, "mu_c": "global"},
                        "run": {"symmetry": False}})


def worker(model: str, rows: int) -> dict:
    """One scene: {"mu_c", "seconds" (the mu^c stage), counts}."""
    from hpcwedge.run.pipeline import run_scene
    t, cpu = time.perf_counter(), time.process_time()
    res = run_scene(scene(model, rows))
    wall, cpu = time.perf_counter() - t, time.process_time() - cpu
    b = res.stats["bnb"]
    import hpcwedge
    return {"mu_c": res.mu_c, "seconds": res.timings["mu_c"], "wall_with_setup": wall, "cpu_with_setup": cpu, "m": res.m,
            "checkout": os.path.dirname(os.path.dirname(hpcwedge.__file__)),
            "route": b.get("route"), "tree_nodes": b.get("nodes"), "lps": b.get("solves"),
            "milp_solves": b.get("milp_solves"), "milp_nodes": b.get("milp_nodes"), "undecided": b.get("undecided")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--limit", type=float, default=300.0)
    ap.add_argument("--checkout", default=None)
    ap.add_argument("--only", nargs="+", default=None, metavar="MODEL:ROWS", help="these scenes only")
    ap.add_argument("--out", default=os.path.join(HERE, "..", "results", "bench_highs_lp"))
    ap.add_argument("--worker", nargs=2, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.worker:
        if a.checkout:
            sys.path.insert(0, os.path.abspath(a.checkout))
        print(bench_2d.MARK + json.dumps(worker(a.worker[0], int(a.worker[1])), default=str), flush=True)
        return
    records = []
    cases = [(c.split(":")[0], int(c.split(":")[1])) for c in a.only] if a.only else QUICK if a.quick else CASES
    for model, rows in cases:
        argv = ["--worker", model, str(rows)] + (["--checkout", a.checkout] if a.checkout else [])
        status, r, wall, err = bench_2d.run_script(os.path.abspath(__file__), argv, a.limit)
        rec = {"model": model, "rows": rows, "status": status, "wall": wall, **(r or {})}
        if r and r.get("mu_c") is not None:
            rec["error"] = abs(r["mu_c"] - math.tan(math.radians(TAPER))) / math.tan(math.radians(TAPER))
        if status != "ok":
            rec["seconds"], rec["stderr"] = wall, err
        records.append(rec)
        print(bench_2d.fields(rec, tuple(COLS)), flush=True)
    meta = {"checkout": os.path.abspath(a.checkout) if a.checkout else "this", "limit": a.limit,
            "quick": a.quick, "note": "2 cores shared with other jobs: seconds +-30 %"}
    bench_2d.write_records(a.out, records, meta, COLS)


if __name__ == "__main__":
    main()
