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
  "hubs": streaming hubs (after PEBBL): the master holds the pool of open nodes and hubs ask it for
      nodes; each hub keeps a pool of its own and serves its workers as the engine serves
      them (schedule.cut with its own workers and its own cost per message); its workers'
      open nodes stay in its pool. A hub asks the master for nodes when its pool holds fewer
      than low x its workers and is given at most chunk x its workers (an even share of the
      master's pool among the hubs waiting); when hubs wait and the master's pool is empty,
      the master asks the hubs that reported the most nodes to share half of their pools
      (answered when the hub holds two nodes or more). A hub's messages cost what the
      master's do; a node moved between master and hub costs NODE_S at each end. Hubs do
      not run tasks.

Each at the grain of bench_scale (a synthetic node = scale_workload.GRAIN = 8 real nodes of
17.6 ms) and at the real nodes' grain (1: 2.2 ms). Efficiency = task seconds / (workers x
wall); "efficiency_all_ranks" counts the hubs' ranks as workers too (what they cost).

Writes results/model_hubs.json.

    PYTHONPATH=. .venv/bin/python scripts/model_hubs.py
"""
from __future__ import annotations

import dataclasses
import heapq
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

from hpcwedge.parallel.jobs import TreeJob  # noqa: E402
from hpcwedge.parallel.model import FREE, MasterCosts, simulate  # noqa: E402
from hpcwedge.parallel.schedule import cut, message_cost  # noqa: E402

#: a node moved between the master and a hub: its pickling and a heap push, at each end (s)
NODE_S = 5e-6
RANKS, FLOOR_WORKER_SECONDS = 1024, 2000.0
#: (workers per hub, task budget in real nodes, low, chunk) tried
HUB_PLANS = ((32, 32, 4.0, 2.0), (64, 64, 4.0, 2.0), (32, 64, 4.0, 2.0), (64, 32, 2.0, 4.0))
#: the synthetic trees (scale_workload's seeds)
SEEDS = (0, 1, 2)
#: task budgets (real nodes) of the free one-level schedule
FREE_BUDGETS = (8, 64)


class Pool(TreeJob):
    """One pool of open nodes (the master's or a hub's) of the outer job's tree: one group;
    tasks of the job's budget, or one node while the pool is short (TreeJob.take), never
    scaled (a hub's messages are few)."""

    max_scale = 1

    def __init__(self, outer: TreeJob):
        super().__init__("pool", outer.handler, outer.context, [], outer.budget, {"nodes": 0, "seconds": 0.0})
        self.found, self.flagged = [[]], [[]]

    def put(self, nodes: list) -> None:
        for node, witness in nodes:
            self._push(0, node, witness)

    def give(self, n: int) -> list:
        """The n shallowest open nodes, out of the pool."""
        return [heapq.heappop(self._pool)[3:] for _ in range(min(n, len(self._pool)))]


def simulate_hubs(job: TreeJob, hubs: int, per_hub: int, costs: MasterCosts, low: float, chunk: float,
                  node_s: float = NODE_S, max_events: int = 50_000_000) -> dict:
    """Streaming hubs (module docstring) on `job` (a TreeJob of one root); the job's pool
    is taken as the master's. Returns efficiency (over hubs x per_hub workers), wall, task
    seconds, nodes explored, leaves found, tasks, nodes moved, the master's and the busiest
    hub's busy fractions."""
    master = Pool(job)
    master.put([(node, witness) for _, _, _, node, witness in job._pool])
    pools = [Pool(job) for _ in range(hubs)]
    low_n, chunk_n = max(1, int(low * per_hub)), max(1, int(chunk * per_hub))
    free, busy = [0.0] * hubs, [0.0] * hubs          # each hub: when it is free; its busy seconds
    idle = [list(range(per_hub)) for _ in range(hubs)]
    sent = [0] * hubs                                # messages to workers, per hub
    unit = [[0.0, 0] for _ in range(hubs)]           # merged task seconds and tasks, per hub
    asked, share = [True] * hubs, [False] * hubs     # hub waits for nodes; hub owes a share
    known = [0] * hubs                               # each hub's pool as its last message said
    waiting, sharing = list(range(hubs)), set()
    events: list = []
    seq = 0
    m_free = m_busy = task_s = last = 0.0
    tasks = moved = 0

    def post(t: float, *event) -> None:
        nonlocal seq
        heapq.heappush(events, (t, seq, *event))
        seq += 1

    def serve_master(t: float) -> float:
        """The master feeds the waiting hubs from its pool, else asks for shares; its cost."""
        nonlocal moved
        c = 0.0
        while waiting and master.pending():
            h = waiting.pop(0)
            n = min(chunk_n, max(1, math.ceil(master.pending() / (len(waiting) + 1))))
            nodes = master.give(n)
            c += costs.send_s + node_s * len(nodes)
            moved += len(nodes)
            post(t + c + costs.latency_s, "hub_nodes", h, nodes)
        if waiting and not master.pending():
            for h in sorted((h for h in range(hubs) if h not in sharing), key=lambda h: -known[h])[:len(waiting)]:
                sharing.add(h)
                c += costs.send_s
                post(t + c + costs.latency_s, "hub_share", h)
        return c

    m_free = serve_master(0.0)
    m_busy = m_free
    handled = 0
    while events:
        handled += 1
        if handled > max_events:
            raise RuntimeError("simulate_hubs: no end in sight (max_events)")
        t, _, kind, h, *data = heapq.heappop(events)
        last = max(last, t)
        if kind.startswith("master_"):
            tm = max(t, m_free)
            c = costs.merge_s
            if kind == "master_ask":
                waiting.append(h)
                known[h] = data[0]
            else:                                    # master_share
                nodes, known[h] = data
                sharing.discard(h)
                master.put(nodes)
                c += node_s * len(nodes)
            c += serve_master(tm + c)
            m_free, m_busy = tm + c, m_busy + c
            continue
        pool, th, c = pools[h], max(t, free[h]), 0.0
        if kind == "hub_done":
            w, token, result, seconds = data
            pool.merge(token, result)
            idle[h].append(w)
            unit[h][0] += seconds
            unit[h][1] += 1
            task_s += seconds
            c += costs.merge_s
        elif kind == "hub_nodes":
            pool.put(data[0])
            asked[h] = False
            c += costs.merge_s + node_s * len(data[0])
        else:                                        # hub_share
            share[h] = True
            c += costs.merge_s
        if share[h] and pool.pending() >= 2:         # half of the pool back, before its own workers
            nodes = pool.give(pool.pending() // 2)
            share[h] = False
            c += costs.send_s + node_s * len(nodes)
            moved += len(nodes)
            post(th + c + costs.latency_s, "master_share", h, nodes, pool.pending())
        while idle[h]:
            secs, n = unit[h]
            _, scale = cut(per_hub, secs / n if n else None, pool.pending(), message_cost(busy[h] + c, sent[h]), 1)
            taken = pool.take(per_hub, scale)
            if taken is None:
                break
            token, payload = taken
            c += costs.send_s
            sent[h] += 1
            tasks += 1
            result = pool.handler(pool.context, payload)
            post(th + c + costs.latency_s + task_seconds(result), "hub_done", h, idle[h].pop(), token, result,
                 task_seconds(result))
        if pool.pending() < low_n and not asked[h]:
            asked[h] = True
            c += costs.send_s
            post(th + c + costs.latency_s, "master_ask", h, pool.pending())
        free[h], busy[h] = th + c, busy[h] + c
    workers = hubs * per_hub
    return {"efficiency": task_s / (workers * last), "wall_s": last, "task_s": task_s,
            "nodes": sum(p.counters["nodes"] for p in pools), "found": sum(len(p.found[0]) for p in pools),
            "tasks": tasks, "moved": moved, "master_busy": m_busy / last, "hub_busy": max(busy) / last}


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
            r = simulate_hubs(job, hubs, per_hub, costs, low, chunk)
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
