"""A discrete-event model of the engine's master loop (Engine._run_master), to predict
its efficiency at rank counts a machine cannot run.

The job is real (its take() and merge() run, and so does its handler, which must
not sleep: `seconds(result)` says how long the task would have run); only time is
simulated. The master is one server: each task costs it `send_s` (take and send) and
each result `merge_s` (receive and merge); between results it waits as mpi.wait_any
does (probes, then sleeps that grow by POLL_FRACTION of the wait up to `poll_max_s`),
so it notices a result at its next wake-up. A task starts `latency_s` after its send
and its result reaches the master when it ends. Results are taken in the order they
arrive; after each the master refills every idle worker, as the engine does.
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass

from hpcwedge.parallel.mpi import POLL_FRACTION, POLL_MAX_MASTER


@dataclass(frozen=True)
class MasterCosts:
    """The master's costs per task (seconds): take + send, receive + merge; the wire and
    worker wake-up before a task starts; the master's longest sleep while it waits."""

    send_s: float
    merge_s: float
    latency_s: float = 0.0
    poll_max_s: float = POLL_MAX_MASTER


@dataclass(frozen=True)
class Simulated:
    """One simulated run: workers, wall seconds (first send to the last merge), the sum of
    the tasks' seconds, the tasks, the master's busy seconds; efficiency = task seconds
    / (workers x wall), master_busy = busy / wall."""

    workers: int
    wall_s: float
    task_s: float
    tasks: int
    busy_s: float

    @property
    def efficiency(self) -> float:
        return self.task_s / (self.workers * self.wall_s) if self.wall_s > 0 else 1.0

    @property
    def master_busy(self) -> float:
        return self.busy_s / self.wall_s if self.wall_s > 0 else 0.0


def noticed_at(since: float, arrival: float, poll_max_s: float) -> float:
    """When a master that started waiting at `since` sees a message that arrives at
    `arrival`: its first wake-up at or after it (wake-ups at since, then every
    min(poll_max_s, max(1e-4, POLL_FRACTION x time waited))); poll_max_s 0: a master
    that never sleeps sees it at once."""
    if arrival <= since or poll_max_s <= 0:
        return max(since, arrival)
    t = since
    # the sleeps grow geometrically up to the cap, then stay at it
    while True:
        step = min(poll_max_s, max(1e-4, POLL_FRACTION * (t - since)))
        if step >= poll_max_s:
            k = -(-(arrival - t) // poll_max_s)          # ceil: whole capped sleeps to reach it
            return t + k * poll_max_s
        t += step
        if t >= arrival:
            return t


def simulate(job, workers: int, costs: MasterCosts, seconds) -> Simulated:
    """Run `job` to its end on `workers` simulated workers (>= 1); seconds(result) -> the
    task's duration. With zero costs the wall time is the schedule's makespan (1 worker:
    the sum of the task durations)."""
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    idle = list(range(workers))[::-1]
    events: list = []                  # (result arrives, seq, worker, token, result)
    t = busy = task_s = 0.0
    seq = tasks = 0
    while True:
        while idle:
            taken = job.take(workers)
            if taken is None:
                break
            token, payload = taken
            t += costs.send_s
            busy += costs.send_s
            result = job.handler(job.context, payload)
            d = float(seconds(result))
            task_s += d
            heapq.heappush(events, (t + costs.latency_s + d, seq, idle.pop(), token, result))
            seq += 1
        if not events:
            return Simulated(workers, t, task_s, tasks, busy)
        arrival, _, w, token, result = heapq.heappop(events)
        t = noticed_at(t, arrival, costs.poll_max_s) + costs.merge_s
        busy += costs.merge_s
        job.merge(token, result)
        tasks += 1
        idle.append(w)
