#!/usr/bin/env python3
"""Parallel speedup of the sign-pattern branch and bound (issue 3), one run.

Runs one 3D scene (default plug3d levels 2 x ring 7, m = 14, mu 1.0) through
the real command line: in one process, then under mpirun with 1, 2 and 3
workers (2, 3, 4 ranks; rank 0 is the master and sleeps while it waits, so
3 workers oversubscribe this 2-core machine). Checks that every run gives the
same answers, and writes results/bench_parallel.{json,csv} with wall times and
speedups relative to 1 worker. The SOCP count against 2^m for m = 8..14 is
scripts/bench_socp_count.py (results/bench_socp_count.json); its table is
copied into the JSON here when present.

    .venv/bin/python scripts/bench_parallel.py [--ring 7] [--mu 1.0] [--repeat 2]
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "results")


def scene_text(levels: int, ring: int, mu: float) -> str:
    return (f'name = "plug3d-{levels}x{ring}"\ndim = 3\n[model]\nkind = "plug3d"\nlevels = {levels}\n'
            f'ring = {ring}\n[friction]\nmu = [{mu}]\n[compute]\nenumerate = true\nmu_c = "cones"\n'
            '[run]\ncheckpoint_every_s = 600\n')


def run(ranks: int | None, scene: str, out: str) -> float:
    env = dict(os.environ, PYTHONPATH=ROOT, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    cmd = [sys.executable, "-m", "hpcwedge", "run", scene, "-o", out, "-q"]
    if ranks:
        extra = ["--allow-run-as-root"] if os.geteuid() == 0 else []
        cmd = [shutil.which("mpirun"), *extra, "--oversubscribe", "-n", str(ranks),
               "-x", "PYTHONPATH", "-x", "OMP_NUM_THREADS", "-x", "OPENBLAS_NUM_THREADS"] + cmd
    t = time.perf_counter()
    subprocess.run(cmd, check=True, env=env)
    return time.perf_counter() - t


def answers(path: str) -> dict:
    env = dict(os.environ, PYTHONPATH=ROOT)
    js = json.loads(subprocess.run([sys.executable, "-m", "hpcwedge", "show", path, "--json"],
                                   check=True, capture_output=True, text=True, env=env).stdout)
    return {"mu_c": js["mu_c"], "patterns": [[p["contact"], p["mu_c"]] for r in js["runs"]
                                             for p in r["patterns"]],
            "stats": js["stats"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, default=2)
    ap.add_argument("--ring", type=int, default=7)
    ap.add_argument("--mu", type=float, default=1.0)
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="bench_parallel_")
    scene = os.path.join(tmp, "scene.toml")
    with open(scene, "w") as f:
        f.write(scene_text(args.levels, args.ring, args.mu))
    configs = [("serial", None, 0), ("1 worker", 2, 1), ("2 workers", 3, 2), ("3 workers (oversubscribed)", 4, 3)]
    rows, ref = [], None
    for label, ranks, workers in configs:
        out = os.path.join(tmp, f"r{ranks}.h5")
        times = [run(ranks, scene, out) for _ in range(args.repeat)]
        got = answers(out)
        if ref is None:
            ref = got
        same = got["mu_c"] == ref["mu_c"] and [p[0] for p in got["patterns"]] == [p[0] for p in ref["patterns"]] \
            and all(abs(a[1] - b[1]) <= 1e-12 * abs(b[1]) for a, b in zip(got["patterns"], ref["patterns"]))
        rows.append({"config": label, "ranks": ranks or 1, "workers": workers, "seconds": min(times),
                     "all_seconds": times, "patterns": len(got["patterns"]), "same_answers": same,
                     "tasks_per_rank": got["stats"].get("parallel", {}).get("tasks_per_rank")})
        print(f"{label:<28} {min(times):7.2f} s  patterns {len(got['patterns'])}  same {same}", flush=True)
    one = next(r["seconds"] for r in rows if r["workers"] == 1)
    for r in rows:
        r["speedup_vs_1_worker"] = one / r["seconds"]
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "bench_parallel.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["config", "ranks", "workers", "seconds", "speedup_vs_1_worker",
                                          "patterns", "same_answers"], extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    socp = os.path.join(OUT, "bench_socp_count.json")
    doc = {"scene": scene_text(args.levels, args.ring, args.mu), "machine_cores": os.cpu_count(), "rows": rows,
           "socp_count": json.load(open(socp)) if os.path.exists(socp) else None}
    with open(os.path.join(OUT, "bench_parallel.json"), "w") as f:
        json.dump(doc, f, indent=1)
    for r in rows:
        print(f"{r['config']:<28} speedup vs 1 worker {r['speedup_vs_1_worker']:.2f}x")
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
