#!/usr/bin/env python3
"""A design study for issue 42, not the engine: would a second level of hubs carry the tree
search to the floor of 2,000 worker-seconds at 1,024 ranks, where one master does not?

Three schedules of the same synthetic trees (scripts/scale_workload.py, the subtree workload,
seeds SEEDS), with the master costs bench_scale fitted (results/bench_scale.json,
"costs_predicting" "subtree": CPU seconds per message, a rank with a core of its own):

  "flat": the engine as it is (parallel.model.simulate, one master and 1,023 workers);
  "flat, free": the same with every master cost, latency and wake-up 0 and tasks of a fixed
      budget of FREE_BUDGETS nodes (what a one-level schedule of this tree could reach: its
      ramp-up and tail);
  "hubs": streaming hubs, the engine's second level (parallel/hub.py), modelled by
      parallel.model.simulate_hubs: plans of workers per hub, the job's task budget (a hub's
      tasks explore budget // hub.BUDGET_DIVISOR nodes), and the hub's low and chunk
      fractions (hub.LOW, hub.CHUNK). Hubs do not run tasks.

Each at the grain of bench_scale (a synthetic node = scale_workload.GRAIN = 8 real nodes of
17.6 ms) and at the real nodes' grain (1: 2.2 ms). Efficiency = task seconds / (workers x
wall); "efficiency_all_ranks" counts the hubs' ranks as workers too (what they cost).

Writes results/model_hubs.json.

    PYTHONPATH=. .venv/bin/python scripts/model_hubs.py
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import scale_workload  # noqa: E402
from harness import RESULTS, write_json  # noqa: E402
from scale_workload import load_durations, make_job, task_seconds  # noqa: E402

from hpcwedge.parallel.model import FREE, NODE_S, MasterCosts, simulate, simulate_hubs  # noqa: E402

RANKS, FLOOR_WORKER_SECONDS = 1024, 2000.0
#: (workers per hub, task budget in real nodes, low, chunk) tried
HUB_PLANS = ((32, 32, 4.0, 2.0), (64, 64, 4.0, 2.0), (32, 64, 4.0, 2.0), (64, 32, 2.0, 4.0))
#: the synthetic trees (scale_workload's seeds)
SEEDS = (0, 1, 2)
#: task budgets (real nodes) of the free one-level schedule
FREE_BUDGETS = (8, 64)


def hub_layout(ranks: int, per_hub_max: int) -> tuple[int, int]:
    """(hubs, workers per hub) for `ranks` ranks (one master): groups of a hub and at most
    per_hub_max workers, the workers shared out evenly (a remainder left idle)."""
    hubs = math.ceil((ranks - 1) / (per_hub_max + 1))
    return hubs, (ranks - 1 - hubs) // hubs


def study(durations: dict, costs: MasterCosts, grain: int, ranks: int = RANKS,
          worker_seconds: float = FLOOR_WORKER_SECONDS, plans=HUB_PLANS, seed: int = 0) -> list[dict]:
    """The three schedules at one grain, on the tree of `seed` (rows of results/model_hubs.json)."""
    old = scale_workload.GRAIN
    scale_workload.GRAIN = grain
    try:
        rows = []
        free = FREE
        for name, c, budget in (("flat", costs, 64), *(("flat, free", free, b) for b in FREE_BUDGETS)):
            t0 = time.perf_counter()
            job = make_job("subtree", durations, worker_seconds, seed, sleep=False, budget=budget)
            if c is free:
                job.max_scale = 1            # tasks of the budget: growing ones only save messages
            s = simulate(job, ranks - 1, c, task_seconds)
            rows.append({"schedule": name, "seed": seed, "grain": grain, "ranks": ranks, "workers": ranks - 1,
                         "budget": job.budget * grain, "task_s": s.task_s, "wall_s": s.wall_s,
                         "efficiency": s.efficiency, "efficiency_all_ranks": s.efficiency,
                         "master_busy": s.master_busy, "tasks": s.tasks, "nodes": job.counters["nodes"],
                         "model_seconds": time.perf_counter() - t0})
        for per_hub_max, budget, low, chunk in plans:
            hubs, per_hub = hub_layout(ranks, per_hub_max)
            t0 = time.perf_counter()
            job = make_job("subtree", durations, worker_seconds, seed, sleep=False, budget=budget)
            r = simulate_hubs(job, [per_hub] * hubs, costs, task_seconds, low, chunk)
            rows.append({"schedule": "hubs", "seed": seed, "grain": grain, "ranks": ranks, "hubs": hubs, "per_hub": per_hub,
                         "workers": hubs * per_hub, "budget": budget, "low": low, "chunk": chunk, **r,
                         "efficiency_all_ranks": r["task_s"] / ((ranks - 1) * r["wall_s"]),
                         "model_seconds": time.perf_counter() - t0})
        return rows
    finally:
        scale_workload.GRAIN = old


def main() -> None:
    with open(os.path.join(RESULTS, "bench_scale.json")) as f:
        costs = MasterCosts(**json.load(f)["costs_predicting"]["subtree"])
    durations = load_durations(os.path.join(RESULTS, "task_durations.json"))
    rows = []
    for seed, grain in ((seed, grain) for seed in SEEDS for grain in (scale_workload.GRAIN, 1)):
        for row in study(durations, costs, grain, seed=seed):
            rows.append(row)
            print(f"seed {seed} grain {row['grain']} {row['schedule']:10} {row.get('hubs', '-')!s:>3} x {row.get('per_hub', '-')!s:>3} "
                  f"budget {row['budget']:3}: efficiency {row['efficiency']:.3f} (all ranks "
                  f"{row['efficiency_all_ranks']:.3f}), wall {row['wall_s']:.2f} s, master busy "
                  f"{row['master_busy']:.2f}", flush=True)
    write_json(os.path.join(RESULTS, "model_hubs.json"), {"rows": rows, "costs": dataclasses.asdict(costs), "node_s": NODE_S,
                                   "floor_worker_seconds": FLOOR_WORKER_SECONDS,
                                   "command": "PYTHONPATH=. .venv/bin/python scripts/model_hubs.py"})


if __name__ == "__main__":
    main()
