#!/usr/bin/env python3
"""How far the 3D global bracket's tasks (mu_c/global_tasks.py) can carry 2 workers, from the
CPU seconds of its tasks: a measure that a shared machine's load does not scale.

One serial run of the scene (pipeline.run_scene, in-process engine) with every task of the
split bracket timed (time.process_time: its CPU seconds): job "global_bracket" (the
bracket's task, then the first round of frictionless tree nodes), jobs "global_dive_<k>"
(the later rounds). The engine's schedule is then replayed for W workers: the jobs one
after another, each job's tasks in order, each to the worker free first; the master's own
work between jobs (the walk, the certified bound, the settling) is the rest of the run's
CPU seconds and adds to every W. Written: results/bench_global_split.json (per job: its
tasks' seconds; per W: the makespan and the speedup over 1 worker).

    PYTHONPATH=. python scripts/bench_global_split.py [--levels 8] [--ring 16] [--out results/bench_global_split]
"""
from __future__ import annotations

import argparse
import heapq
import os
import time

from harness import RESULTS, write_json


def makespan(tasks: list[float], workers: int) -> float:
    """The seconds of a job whose tasks (in order) go each to the worker free first."""
    free = [0.0] * workers
    for t in tasks:
        heapq.heappush(free, heapq.heappop(free) + t)
    return max(free)


def timed_run(levels: int, ring: int) -> tuple[dict, dict, float, float]:
    """(task CPU seconds per job in order, the result's mu^c and stats.bnb, the run's CPU
    seconds (scene to result, modules loaded before), its mu_c stage's wall seconds) of
    plug3d levels x ring's global mu^c, serially."""
    from hpcwedge.mu_c import global_tasks
    from hpcwedge.run.pipeline import run_scene
    from hpcwedge.scene.parse import parse_scene
    jobs: dict = {}
    task, run_tasks = global_tasks.dive_task, global_tasks.run_tasks

    def timed_task(ctx, payload):
        t = time.process_time()
        out = task(ctx, payload)
        jobs[current[0]].append(time.process_time() - t)
        return out

    current = [None]

    def named_run_tasks(handler, ctx, payloads, engine=None, name=None, kind=None):
        current[0] = name
        jobs.setdefault(name, [])
        return run_tasks(handler, ctx, payloads, engine=engine, name=name, kind=kind)

    global_tasks.dive_task, global_tasks.run_tasks = timed_task, named_run_tasks
    scene = parse_scene({"name": f"plug3d-{levels}x{ring}", "dim": 3,
                         "model": {"kind": "plug3d", "levels": levels, "ring": ring, "taper_deg": 10.0},
                         "friction": {"mu": [0.1]}, "compute": {"enumerate": False, "mu_c": "global"},
                         "run": {"symmetry": False, "checkpoint_every_s": 600}})
    t = time.process_time()
    res = run_scene(scene)
    return jobs, {"mu_c": res.mu_c, "bnb": res.stats["bnb"]}, time.process_time() - t, res.timings["mu_c"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, default=8)
    ap.add_argument("--ring", type=int, default=16)
    ap.add_argument("--out", default=os.path.join(RESULTS, "bench_global_split"))
    args = ap.parse_args()
    load = os.getloadavg()[0]
    jobs, answer, cpu, mu_c_wall = timed_run(args.levels, args.ring)
    in_tasks = sum(sum(v) for v in jobs.values())
    master = cpu - in_tasks                  # condensation, the walk, the bound, ...: serial
    rows = []
    for w in (1, 2, 3):
        span = master + sum(makespan(v, w) for v in jobs.values())
        rows.append({"workers": w, "seconds": span})
    for r in rows:
        r["speedup_vs_1_worker"] = rows[0]["seconds"] / r["seconds"]
        print(f"{r['workers']} worker(s): {r['seconds']:7.2f} CPU-s on the critical path, "
              f"{r['speedup_vs_1_worker']:.2f}x", flush=True)
    print(f"tasks {in_tasks:.2f} CPU-s, master {master:.2f} CPU-s; jobs " +
          ", ".join(f"{k}: {len(v)} tasks {sum(v):.1f} s" for k, v in jobs.items()))
    write_json(args.out + ".json", {"scene": f"plug3d {args.levels} x {args.ring}, global mu^c, no symmetry",
                                    "answer": answer, "cpu_seconds": cpu, "mu_c_wall_seconds": mu_c_wall,
                                    "master_cpu_seconds": master, "load_before": load,
                                    "jobs": {k: {"tasks": len(v), "cpu_seconds": v} for k, v in jobs.items()},
                                    "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
