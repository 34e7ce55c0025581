#!/usr/bin/env python3
"""`run.screens` on and off, in the same run (issue 40): the default decided by measurement.

    PYTHONPATH=. python scripts/bench_flags.py [--quick] [--limit 900] [--out results/flags_screens]

Each case is plug3d LEVELS x RING (2 x 6, 3 x 5, 3 x 6, 4 x 6; --quick: 2 x 6), mu 0.65 and 1.0,
`run.symmetry` true and false, an enumeration (`compute.mu_c = "none"`), solved by the
product's entry point (hpcwedge.api.solve) in its own process (bench_2d.run_script), with
`run.screens` off and then on, back to back (the machine is shared: compare the ratio within
a pair, not seconds across pairs). Per row: tree nodes, SOCPs, LPs, patterns and their set's
hash (on and off must agree: `same`), CPU seconds, and per pair the ratios on / off of SOCPs
and CPU. Writes <out>.json (with the environment record) and <out>.csv; prints the table.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import bench_2d  # noqa: E402
from bench_search_3d import patterns_hash  # noqa: E402

BODIES = ((2, 6), (3, 5), (3, 6), (4, 6))
MUS = (0.65, 1.0)


def scene_table(levels: int, ring: int, mu: float, symmetry: bool, screens: bool) -> dict:
    """The enumeration scene of plug3d levels x ring at mu."""
    return {"name": f"plug3d-{levels}x{ring}", "dim": 3,
            "model": {"kind": "plug3d", "levels": levels, "ring": ring},
            "friction": {"mu": [mu]}, "compute": {"enumerate": True, "mu_c": "none"},
            "run": {"symmetry": symmetry, "screens": screens}}


def worker(levels: int, ring: int, mu: float, symmetry: bool, screens: bool) -> dict:
    """One solve through hpcwedge.api.solve: its counters and CPU seconds."""
    from hpcwedge.api import solve
    t, c = time.perf_counter(), time.process_time()
    res = solve(scene_table(levels, ring, mu, symmetry, screens))
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    bnb = res.stats["bnb"]
    pats = [tuple(p["contact"] if isinstance(p, dict) else p.contact) for p in res.runs[0].patterns]
    return {"m": res.m, "nodes": bnb.get("nodes"), "socps": bnb.get("solves"), "lps": bnb.get("lps"),
            "undecided": bnb.get("undecided"), "patterns": len(pats), "patterns_hash": patterns_hash(pats),
            "cpu": cpu, "wall_in_process": wall}


def run_case(levels: int, ring: int, mu: float, symmetry: bool, limit: float) -> list[dict]:
    """The pair (screens off, screens on) of one case, with the ratios on the `on` row."""
    rows = []
    for screens in (False, True):
        rec = {"levels": levels, "ring": ring, "m": levels * ring, "mu": mu, "symmetry": symmetry,
               "screens": screens}
        rec = bench_2d.run_record(os.path.abspath(__file__), ["--worker", str(levels), str(ring), str(mu),
                                                              str(int(symmetry)), str(int(screens))], limit, **rec)
        rows.append(rec)
    off, on = rows
    if off["status"] == on["status"] == "ok":
        on["same"] = (on["patterns"], on["patterns_hash"]) == (off["patterns"], off["patterns_hash"])
        on["socps_ratio"] = on["socps"] / max(off["socps"], 1)
        on["cpu_ratio"] = on["cpu"] / off["cpu"]
    return rows


def line(r: dict) -> str:
    keys = ("patterns", "patterns_hash", "nodes", "socps", "lps", "cpu", "same", "socps_ratio", "cpu_ratio")
    return (f"{r['levels']}x{r['ring']} mu={r['mu']:<4} sym={int(r['symmetry'])} screens={int(r['screens'])} "
            f"{r['status']:7s} {bench_2d.fields(r, keys, 4)}")


#: the CSV's columns
COLUMNS = ["levels", "ring", "m", "mu", "symmetry", "screens", "status", "patterns", "patterns_hash", "nodes",
           "socps", "lps", "undecided", "cpu", "wall", "same", "socps_ratio", "cpu_ratio"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2 x 6 only")
    ap.add_argument("--limit", type=float, default=900.0, help="seconds per solve")
    ap.add_argument("--out", default=os.path.join(bench_2d.ROOT, "results", "flags_screens"))
    ap.add_argument("--worker", nargs=5, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        lv, rg, mu, sym, scr = args.worker
        print(bench_2d.MARK + json.dumps(worker(int(lv), int(rg), float(mu), bool(int(sym)), bool(int(scr)))))
        return
    records = []
    for levels, ring in BODIES[:1] if args.quick else BODIES:
        for mu in MUS:
            for symmetry in (True, False):
                for rec in run_case(levels, ring, mu, symmetry, args.limit):
                    records.append(rec)
                    print(line(rec), flush=True)
    bench_2d.write_records(args.out, records, {"limit_s": args.limit}, COLUMNS)


if __name__ == "__main__":
    main()
