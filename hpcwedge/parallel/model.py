"""A discrete-event model of the engine's master loop (Engine._run_master), to predict
its efficiency at rank counts a machine cannot run.

The job is real (its take() and merge() run, and so does its handler, which must
not sleep: `seconds(result)` says how long the task would have run); only time is
simulated. Work travels in messages of schedule.batch_size units (batches of tasks, or
tasks of a scaled budget: schedule.cut), as the engine sends them; the master's cost per
message that sizes them is its own busy time per message so far, as the engine measures it. The master is one server: each message costs it `send_s` (take and
send) and each answer `merge_s` (receive and merge); between answers it waits as mpi.wait_any
does (probes, then sleeps that grow by POLL_FRACTION of the wait up to `poll_max_s`),
so it notices a result at its next wake-up; each wake-up probes, at `probe_s` of its busy
time (Open MPI's probe runs its progress engine: with tasks of a second at 64 ranks the
probes, not the messages, are most of the master's busy time). A task reaches its worker `latency_s` after its send; the worker
notices it at its own next wake-up (worker.serve waits as the master does, sleeps capped at
`worker_poll_max_s`, counted from the end of its previous task: a worker left idle for
seconds, as in a tree's ramp-up and tail, starts its next task up to mpi.POLL_MAX late),
and its result reaches the master when the task ends. Where ranks outnumber the cores, a send
is slower the more workers idle (`idle_probe_s` x idle workers x workers: the idle ranks'
probes, each over every peer, share the cores; fitted to measured runs, e.g. the ramp-up
and tail of a tree at 129 ranks on 2 cores). Results are taken in the order they
arrive; after each the master refills every idle worker, as the engine does.
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass

from hpcwedge.parallel.mpi import POLL_FRACTION, POLL_MAX, POLL_MAX_MASTER
from hpcwedge.parallel.schedule import cut, message_cost


@dataclass(frozen=True)
class MasterCosts:
    """The master's costs (seconds): per message take + send, receive + merge; the wire and
    worker wake-up before a task starts; the master's longest sleep while it waits; one
    probe (a wake-up while it waits); an idle worker's longest sleep (0: it never sleeps); a
    send's extra delay per idle worker per worker (ranks sharing few cores: every idle rank's
    probes poll each peer and take the cores from the rest; 0 where each rank has a core)."""

    send_s: float
    merge_s: float
    latency_s: float = 0.0
    poll_max_s: float = POLL_MAX_MASTER
    probe_s: float = 0.0
    worker_poll_max_s: float = POLL_MAX
    idle_probe_s: float = 0.0


#: a master that costs nothing, waits for nothing and wakes its workers at once: what a
#: schedule alone reaches (its ramp-up and tail), the bound for every real master
FREE = MasterCosts(send_s=0.0, merge_s=0.0, poll_max_s=0.0, worker_poll_max_s=0.0)


@dataclass(frozen=True)
class Simulated:
    """One simulated run: workers, wall seconds (first send to the last merge), the sum of
    the tasks' seconds, the tasks, the master's busy seconds, the messages (tasks or
    batches) sent, the master's probes while it waited, the longest task's seconds; efficiency = task seconds /
    (workers x wall), master_busy = busy / wall."""

    workers: int
    wall_s: float
    task_s: float
    tasks: int
    busy_s: float
    messages: int
    probes: int = 0
    longest_s: float = 0.0

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
    return waited(since, arrival, poll_max_s)[0]


def waited(since: float, arrival: float, poll_max_s: float) -> tuple[float, int]:
    """(noticed_at(since, arrival, poll_max_s), the wake-ups up to it, the one at `since`
    and the one that sees it included: each probes once)."""
    if arrival <= since or poll_max_s <= 0:
        return max(since, arrival), 1
    t, wakes = since, 1
    # the sleeps grow geometrically up to the cap, then stay at it
    while True:
        step = min(poll_max_s, max(1e-4, POLL_FRACTION * (t - since)))
        if step >= poll_max_s:
            k = -(-(arrival - t) // poll_max_s)          # ceil: whole capped sleeps to reach it
            return t + k * poll_max_s, wakes + int(k)
        t += step
        wakes += 1
        if t >= arrival:
            return t, wakes


def simulate(job, workers: int, costs: MasterCosts, seconds) -> Simulated:
    """Run `job` to its end on `workers` simulated workers (>= 1); seconds(result) -> the
    task's duration. With zero costs the wall time is the schedule's makespan (1 worker:
    the sum of the task durations)."""
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    idle = list(range(workers))[::-1]
    idle_since = [0.0] * workers       # when each worker's previous task ended (it waits since)
    events: list = []                  # (answer arrives, seq, worker, [(token, result)], seconds)
    t = busy = task_s = 0.0
    seq = tasks = probes = 0
    merged_s = longest = 0.0           # the merged tasks' seconds (the engine's batch sizes); the longest task
    units = 0                          # the merged tasks' units of work (schedule.py)
    max_scale = getattr(job, "max_scale", 1)
    while True:
        while idle:
            k, scale = cut(workers, merged_s / units if units else None, job.pending(), message_cost(busy, seq),
                           max_scale)
            taken = [x for x in (job.take(workers, scale) for _ in range(k)) if x is not None]
            if not taken:
                break
            t += costs.send_s
            busy += costs.send_s
            done = [(token, job.handler(job.context, payload)) for token, payload in taken]
            each = [float(seconds(r)) for _, r in done]
            d, longest = sum(each), max(longest, *each)
            task_s += d
            w = idle.pop()
            delay = costs.latency_s + costs.idle_probe_s * len(idle) * workers
            start = noticed_at(idle_since[w], t + delay, costs.worker_poll_max_s)
            idle_since[w] = start + d
            heapq.heappush(events, (start + d, seq, w, done, d, len(done) * scale))
            seq += 1
        if not events:
            return Simulated(workers, t, task_s, tasks, busy, seq, probes, longest)
        arrival, _, w, done, d, u = heapq.heappop(events)
        merged_s += d
        units += u
        t, wakes = waited(t, arrival, costs.poll_max_s)
        t += costs.merge_s
        probes += wakes
        busy += costs.merge_s + wakes * costs.probe_s
        for token, result in done:
            job.merge(token, result)
        tasks += len(done)
        idle.append(w)
