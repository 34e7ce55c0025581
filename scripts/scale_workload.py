"""Synthetic, domain-free jobs for the engine's scaling benchmark (issue 42): tasks that
sleep for durations recorded from real runs (results/task_durations.json, written by
scripts/record_durations.py) instead of computing.

  task workloads ("mu_c", "face"): a parallel.jobs.TaskJob of tasks sleeping recorded
      durations: "mu_c" draws them from the recorded tasks (a seeded generator); "face"
      repeats the recorded run's faces (one mu) for as many mu as make the job, in the
      order rays.faces.face_payloads hands them out (face by face over every mu: the
      largest face, every split node in contact, first);
  tree workload ("subtree"): a parallel.jobs.TreeJob over a seeded random tree whose
      nodes cost the recorded seconds per visited node of the plug3d 4 x 6 subtree tasks.
      A synthetic node stands for GRAIN real nodes (its cost the sum of GRAIN draws'
      mean x GRAIN) so that a model of 4,096 ranks stays within seconds; the budget is
      divided by GRAIN alike. Each node has a child 0 and 1 with probability P_CHILD
      each (always two above FULL_DEPTH), down to a depth that gives the requested
      number of worker-seconds.

The handlers take a context {"sleep": bool, ...}: with sleep False they return at once
(parallel.model runs them so). Every result carries its seconds (tasks: "seconds"; the
tree: its counters' "seconds").
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass

import numpy as np

from hpcwedge.parallel.jobs import TaskJob, TreeJob

#: synthetic tree: real nodes per synthetic node; nodes above FULL_DEPTH have both
#: children; below it each child exists with probability P_CHILD
GRAIN = 8
FULL_DEPTH = 4
P_CHILD = 0.7
_MASK = (1 << 64) - 1


def load_durations(path: str) -> dict:
    """{workload: array of seconds}: a task's seconds ("mu_c", "face"), or a real tree
    node's seconds ("subtree": each recorded task's seconds / nodes visited)."""
    with open(path) as f:
        rec = json.load(f)
    out = {k: np.array([r["seconds"] for r in rec[k]["records"]]) for k in ("mu_c", "face") if k in rec}
    if "subtree" in rec:
        out["subtree"] = np.array([r["seconds"] / r["nodes"] for r in rec["subtree"]["records"] if r["nodes"] > 0])
    return out


def sleep_task(ctx: dict, seconds: float) -> dict:
    """A TaskJob task: sleep `seconds` (when ctx["sleep"]); {"seconds": seconds}."""
    if ctx["sleep"]:
        time.sleep(seconds)
    return {"seconds": float(seconds)}


def face_job(durations: np.ndarray, worker_seconds: float, sleep: bool, name: str = "face") -> TaskJob:
    """A TaskJob of the recorded faces (`durations`, in the recorded run's task order, one mu)
    for n_mu = ceil(worker_seconds / their sum) mu, face by face over every mu."""
    n_mu = max(1, int(np.ceil(worker_seconds / durations.sum())))
    return TaskJob(name, sleep_task, {"sleep": sleep}, [float(d) for d in durations for _ in range(n_mu)],
                   kind="sleep")


def task_job(durations: np.ndarray, worker_seconds: float, seed: int, sleep: bool, name: str = "tasks") -> TaskJob:
    """A TaskJob of tasks drawn from `durations` (with replacement) until their sum
    reaches worker_seconds."""
    rng = np.random.default_rng(seed)
    n = max(1, int(np.ceil(worker_seconds / durations.mean())))
    return TaskJob(name, sleep_task, {"sleep": sleep}, list(map(float, rng.choice(durations, n))), kind="sleep")


@dataclass(frozen=True)
class Node:
    """A synthetic tree node: its depth and its path (bit d = the branch taken at depth d)."""

    depth: int
    path: int


def _hash(seed: int, node: Node, salt: int) -> int:
    """A 64-bit mix of (seed, depth, path, salt) (splitmix64's finaliser)."""
    z = (seed * 0x9E3779B97F4A7C15 + node.depth * 0xBF58476D1CE4E5B9 + node.path * 0x94D049BB133111EB
         + salt) & _MASK
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK
    return z ^ (z >> 31)


def children(ctx: dict, node: Node) -> list[Node]:
    if node.depth >= ctx["depth"]:
        return []
    kids = [Node(node.depth + 1, node.path | (b << node.depth)) for b in (0, 1)]
    if node.depth < FULL_DEPTH:
        return kids
    p = int(P_CHILD * 2 ** 64)
    return [k for b, k in enumerate(kids) if _hash(ctx["seed"], node, b + 1) < p]


def node_seconds(ctx: dict, node: Node) -> float:
    """The node's cost: a recorded per-node cost picked by the node's hash, x GRAIN."""
    costs = ctx["costs"]
    return GRAIN * costs[_hash(ctx["seed"], node, 0) % len(costs)]


def sleep_subtree(ctx: dict, payload):
    """A TreeJob task: depth first below the node, at most `budget` nodes, then sleep
    their cost; (leaves found, open nodes, {"nodes", "seconds"}, [], witnesses None)."""
    _, node, budget, _ = payload
    stack, found, seconds, visited = [node], [], 0.0, 0
    while stack and visited < budget:
        n = stack.pop()
        visited += 1
        seconds += node_seconds(ctx, n)
        kids = children(ctx, n)
        if not kids:
            found.append(n)
        stack.extend(reversed(kids))
    if ctx["sleep"]:
        time.sleep(seconds)
    return found, stack, {"nodes": visited, "seconds": seconds}, [], [None] * len(stack)


def expected_nodes(depth: int) -> float:
    """The synthetic tree's expected size down to `depth`."""
    full = min(depth, FULL_DEPTH)
    n = 2 ** (full + 1) - 1
    width = 2.0 ** full
    for _ in range(full, depth):
        width *= 2 * P_CHILD
        n += width
    return n


def tree_depth(node_cost: float, worker_seconds: float) -> int:
    """The depth whose expected tree costs about worker_seconds."""
    depth = FULL_DEPTH
    while expected_nodes(depth) * node_cost < worker_seconds:
        depth += 1
    return depth


def tree_job(costs: np.ndarray, worker_seconds: float, seed: int, sleep: bool, budget: int = 64,
             name: str = "tree") -> TreeJob:
    """A TreeJob over a synthetic tree of about worker_seconds; budget in real nodes."""
    depth = tree_depth(GRAIN * float(costs.mean()), worker_seconds)
    ctx = {"sleep": sleep, "seed": seed, "depth": depth, "costs": [float(c) for c in costs]}
    return TreeJob(name, sleep_subtree, ctx, [Node(0, 0)], max(1, budget // GRAIN), {"nodes": 0, "seconds": 0.0})


def task_seconds(result) -> float:
    """A synthetic task's seconds (parallel.model.simulate's `seconds`)."""
    return float(result["seconds"]) if isinstance(result, dict) else float(result[2]["seconds"])


def make_job(workload: str, durations: dict, worker_seconds: float, seed: int, sleep: bool, budget: int = 64):
    """The synthetic job of a workload ("subtree", "mu_c" or "face")."""
    if workload == "subtree":
        return tree_job(durations["subtree"], worker_seconds, seed, sleep, budget, name=workload)
    if workload == "face":
        return face_job(durations[workload], worker_seconds, sleep, name=workload)
    return task_job(durations[workload], worker_seconds, seed, sleep, name=workload)
