#!/usr/bin/env python3
"""Parallel speedup of the sign-pattern branch and bound (issue 3), one run.

Runs one 3D scene (default plug3d levels 3 x ring 6, m = 18, mu 1.0: with its
node symmetry as `hpcwedge run` uses it, ~5,000 SOCPs and ~500 mu^c tasks)
through the real command line: in one process, then under mpirun with 1, 2 and
3 workers (2, 3, 4 ranks; rank 0 is the master and sleeps while it waits, so
3 workers oversubscribe this 2-core machine). The configurations take turns
in each repeat (noise on a shared machine hits them alike); the best of the
repeats counts. Checks that every run gives the same answers, and writes
results/bench_parallel.{json,csv} with wall times (mpirun start-up included),
the program's own run time (timings.total: scene to result) and speedups
relative to 1 worker for both; every run's stage times (timings: condense,
enumerate, mu_c) and the 1-minute load average before it (a shared machine's
noise) are in the JSON. The SOCP count against 2^m for m = 8..14 is
scripts/bench_socp_count.py (results/bench_socp_count.json); its table is
copied into the JSON here when present.

    .venv/bin/python scripts/bench_parallel.py [--levels 3] [--ring 6] [--mu 1.0] [--repeat 2]
        [--mu-c cones|none|global] [--no-symmetry] [--screens] [--neck] [--workers 0 1 2 3]
        [--out results/bench_parallel]

Issue 13's target (plug3d 4 x 6 without symmetry, patterns only, 2 workers >= 1.8x 1 worker):
    .venv/bin/python scripts/bench_parallel.py --levels 4 --ring 6 --mu 0.65 --mu-c none \
        --no-symmetry --workers 1 2 --repeat 1 --out results/bench_parallel_4x6
The global mu^c search alone (stats.bnb compared too) on a body where elasticity sets it
(the curved neck 4 x 8, m = 32: its settling tree is the work the workers share; plug3d's
search ends at its rigid bound, with no tree to share):
    .venv/bin/python scripts/bench_parallel.py --neck --levels 4 --ring 8 --mu-c global \
        --workers 0 1 2 --repeat 2 --out results/bench_parallel_global_neck
Issue 41's target (the m = 128 global mu^c, `mpirun -n 3` >= 1.8x over 1 worker):
    .venv/bin/python scripts/bench_parallel.py --levels 8 --ring 16 --mu 0.1 --mu-c global \
        --no-symmetry --workers 0 1 2 --repeat 1 --out results/bench_parallel_global_8x16
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import tempfile

from harness import ERROR, OK, OVERRUN, Checks, mpirun_command, python_command, run_command, write_csv, write_json

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "results")


def scene_text(levels: int, ring: int, mu: float, mu_c: str = "cones", symmetry: bool = True,
               screens: bool = False) -> str:
    """mu_c "global": the global mu^c alone (no enumeration), else the patterns and mu_c."""
    enumerate_ = str(mu_c != "global").lower()
    return (f'name = "plug3d-{levels}x{ring}"\ndim = 3\n[model]\nkind = "plug3d"\nlevels = {levels}\n'
            f'ring = {ring}\n[friction]\nmu = [{mu}]\n[compute]\nenumerate = {enumerate_}\nmu_c = "{mu_c}"\n'
            f'[run]\ncheckpoint_every_s = 600\nsymmetry = {str(symmetry).lower()}\n'
            f'screens = {str(screens).lower()}\n')


def neck_text(levels: int, ring: int, mu: float, mu_c: str = "global") -> str:
    """tests/instances.py's curved neck LEVELS x RING (seed 0; elasticity sets its mu^c, so
    the global search settles a tree) as a scene file, without symmetry."""
    import sys
    sys.path.insert(0, os.path.join(ROOT, "tests"))
    from instances import curved_neck

    from hpcwedge.scene.parse import Scene
    data = curved_neck(levels, ring, 0, mu=mu)
    data.update(compute={"enumerate": mu_c != "global", "mu_c": mu_c},
                run={"symmetry": False, "checkpoint_every_s": 600})
    return Scene.from_dict(data).text


def run(ranks: int | None, scene: str, out: str, limit: float | None = None) -> dict:
    """`hpcwedge run` in one process (ranks None) or under mpirun (harness.run_command)."""
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    args = ("-m", "hpcwedge", "run", scene, "-o", out, "-q")
    cmd = mpirun_command(ranks, *args, env=env) if ranks else python_command(*args)
    rec = run_command(cmd, limit=limit, env=env)
    if rec["status"] == ERROR:
        raise SystemExit(f"{' '.join(cmd)}: exit {rec['returncode']}\n{rec['stderr']}")
    return rec


def answers(path: str) -> dict:
    js = json.loads(run_command(python_command("-m", "hpcwedge", "show", path, "--json"))["stdout"])
    return {"mu_c": js["mu_c"], "patterns": [[p["contact"], p["mu_c"]] for r in js["runs"]
                                             for p in r["patterns"] or []],
            "stats": dict(js["stats"], timings_total=js["timings"]["total"]),
            "stages": {k: js["timings"].get(k) for k in ("condense", "enumerate", "mu_c")}}


def same_answers(checks: Checks, label: str, g: dict, ref: dict) -> bool:
    """g's mu^c and patterns' mu^c equal ref's to 1e-12 relative, its patterns and stats.bnb equal."""
    def key(a):
        return {"mu_c": a["mu_c"], "bnb": a["stats"].get("bnb"),
                "patterns": [{"contact": c, "mu_c": v} for c, v in a["patterns"]]}
    return checks.compare(label, key(g), key(ref))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, default=3)
    ap.add_argument("--ring", type=int, default=6)
    ap.add_argument("--mu", type=float, default=1.0)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--mu-c", default="cones", choices=["cones", "none", "global"],
                    help="global: the global mu^c search alone (its jobs global_bracket, global_patterns, "
                         "global_mu_c), no enumeration")
    ap.add_argument("--no-symmetry", action="store_true", help="run.symmetry = false (a generic body)")
    ap.add_argument("--screens", action="store_true", help="run.screens = true (LP screens in the 3D tree)")
    ap.add_argument("--neck", action="store_true",
                    help="tests/instances.py's curved neck LEVELS x RING instead of plug3d (no symmetry)")
    ap.add_argument("--workers", type=int, nargs="*", default=[0, 1, 2, 3],
                    help="configurations: 0 = serial, k = mpirun with k workers (1 must be among them)")
    ap.add_argument("--out", default=os.path.join(OUT, "bench_parallel"))
    ap.add_argument("--limit", type=float, default=None, help="seconds per run (default: none)")
    args = ap.parse_args()
    if 1 not in args.workers:
        ap.error("--workers must include 1: the speedups are against 1 worker")
    text = (neck_text(args.levels, args.ring, args.mu, args.mu_c) if args.neck else
            scene_text(args.levels, args.ring, args.mu, args.mu_c, not args.no_symmetry, args.screens))
    tmp = tempfile.mkdtemp(prefix="bench_parallel_")
    scene = os.path.join(tmp, "scene.toml")
    with open(scene, "w") as f:
        f.write(text)
    configs = [c for c in [("serial", None, 0), ("1 worker", 2, 1), ("2 workers", 3, 2),
                           ("3 workers (oversubscribed)", 4, 3)] if c[2] in args.workers]
    walls = {label: [] for label, _, _ in configs}
    inside = {label: [] for label, _, _ in configs}
    stages = {label: [] for label, _, _ in configs}
    loads = {label: [] for label, _, _ in configs}       # 1-min load average before each run (noise)
    got = {}
    status = {label: OK for label, _, _ in configs}
    for rep in range(args.repeat):
        for label, ranks, workers in configs[rep % len(configs):] + configs[:rep % len(configs)]:
            out = os.path.join(tmp, f"r{ranks}.h5")
            loads[label].append(os.getloadavg()[0])
            rec = run(ranks, scene, out, args.limit)
            if rec["status"] == OVERRUN:
                status[label] = OVERRUN
                print(f"  {label:<28} overran its {args.limit} s", flush=True)
                continue
            walls[label].append(rec["seconds"])
            got[label] = answers(out)
            inside[label].append(got[label]["stats"].get("timings_total", float("nan")))
            stages[label].append(got[label]["stages"])
            st = ", ".join(f"{k} {v:.2f}" for k, v in stages[label][-1].items() if v is not None)
            print(f"  {label:<28} {walls[label][-1]:7.2f} s wall, {inside[label][-1]:7.2f} s in the program "
                  f"({st} s; load before {loads[label][-1]:.1f})", flush=True)
    rows, checks = [], Checks(rel_tol=1e-12)
    ref_label = next((label for label, _, _ in configs if label in got), None)
    for label, ranks, workers in configs:
        if label not in got:
            rows.append({"config": label, "ranks": ranks or 1, "workers": workers, "status": status[label],
                         "seconds": float("nan"), "program_seconds": float("nan"), "same_answers": None})
            continue
        g = got[label]
        same = same_answers(checks, f"{label} against {ref_label}", g, got[ref_label])
        rows.append({"config": label, "ranks": ranks or 1, "workers": workers, "status": status[label],
                     "seconds": min(walls[label]),
                     "all_seconds": walls[label], "program_seconds": min(inside[label]),
                     "all_program_seconds": inside[label], "all_stage_seconds": stages[label],
                     "all_load_before": loads[label],
                     "patterns": len(g["patterns"]), "same_answers": same,
                     "tasks_per_rank": g["stats"].get("parallel", {}).get("tasks_per_rank")})
    one = next(r for r in rows if r["workers"] == 1)
    for r in rows:
        r["speedup_vs_1_worker"] = one["seconds"] / r["seconds"]
        r["program_speedup_vs_1_worker"] = one["program_seconds"] / r["program_seconds"]
    write_csv(args.out + ".csv", rows, ["config", "ranks", "workers", "seconds", "speedup_vs_1_worker",
                                        "program_seconds", "program_speedup_vs_1_worker", "patterns",
                                        "same_answers"])
    socp = os.path.join(OUT, "bench_socp_count.json")
    with open(socp) if os.path.exists(socp) else contextlib.nullcontext() as f:
        socp_count = None if f is None else json.load(f)
    write_json(args.out + ".json", {"scene": text, "machine_cores": os.cpu_count(), "rows": rows,
                                    "socp_count": socp_count})
    for r in rows:
        print(f"{r['config']:<28} {r['seconds']:7.2f} s wall ({r['speedup_vs_1_worker']:.2f}x vs 1 worker), "
              f"{r['program_seconds']:7.2f} s in the program ({r['program_speedup_vs_1_worker']:.2f}x), "
              f"patterns {r['patterns']}, same answers {r['same_answers']}")
    shutil.rmtree(tmp, ignore_errors=True)
    return checks.exit_status()


if __name__ == "__main__":
    raise SystemExit(main())
