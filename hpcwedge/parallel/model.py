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


#: a node moved between the master and a hub: its pickling and a heap push, at each end (s)
NODE_S = 5e-6


def simulate_hubs(job, groups: list[int], costs: MasterCosts, seconds, low: float | None = None,
                  chunk: float | None = None, node_s: float = NODE_S, max_events: int = 50_000_000) -> dict:
    """hub.py's schedule of a TreeJob `job` over hubs of groups[i] workers (the job's pool is
    the master's; a hub's pool serves its workers one task of the job's budget // hub.BUDGET_DIVISOR
    per message, as TreeJob.take cuts it, and hands back the shallowest above low x its workers once it holds
    more than hub.SURPLUS x them). A hub asks for nodes below low x its workers (hub.LOW) and
    is given at most chunk x its workers (hub.CHUNK; an even share of the master's pool among
    the hubs waiting); while hubs are dry (idle workers, an empty pool) and the master's pool is
    empty, the master asks as many hubs, those that reported the largest pools, to share half
    of theirs once they hold two nodes. Every message costs its sender `send_s` and its
    receiver `merge_s` (hubs pay what the master pays), a node moved costs node_s at each end,
    and a hub reports its frontier every hub.REPORT_EVERY_S (node_s a node, to the master).
    Hubs run no tasks. Returns efficiency (over the workers), wall_s, task_s, nodes, found,
    tasks, moved (nodes between master and hubs), messages (the master's NODES), longest_s
    (the longest task), workers, master_busy and the busiest hub's hub_busy."""
    return _HubSchedule(job, groups, costs, seconds, low, chunk, node_s).run(max_events)


class _HubSchedule:
    """simulate_hubs' state: the master (the job's pool), each hub's pool, workers and flags,
    and the events (time, seq, kind, hub, data...) in time order."""

    def __init__(self, job, groups, costs, seconds, low, chunk, node_s):
        from hpcwedge.parallel.hub import BUDGET_DIVISOR, CHUNK, LOW, REPORT_EVERY_S, SURPLUS
        from hpcwedge.parallel.jobs import TreeJob
        self.job, self.groups, self.costs, self.seconds, self.node_s = job, groups, costs, seconds, node_s
        self.low = LOW if low is None else low
        self.chunk = CHUNK if chunk is None else chunk
        self.surplus, self.report_every_s = max(SURPLUS, 2 * self.low), REPORT_EVERY_S
        hubs = len(groups)
        budget = max(1, job.budget // BUDGET_DIVISOR)
        self.pools = [TreeJob("hub", job.handler, job.context, [], budget, {}, groups=len(job.found))
                      for _ in groups]
        for p in self.pools:
            p.max_scale = 1
        self.free, self.busy, self.reported = [0.0] * hubs, [0.0] * hubs, [0.0] * hubs
        self.idle = [list(range(n)) for n in groups]
        self.asked, self.share, self.dry = [True] * hubs, [False] * hubs, [True] * hubs
        self.known = [0] * hubs                      # each hub's pool as its last message said
        self.waiting, self.sharing, self.starving = list(range(hubs)), set(), set(range(hubs))
        self.events: list = []
        self.seq = self.moved = self.messages = self.tasks = 0
        self.m_free = self.m_busy = self.task_s = self.last = self.longest = 0.0

    def post(self, t: float, *event) -> None:
        heapq.heappush(self.events, (t, self.seq, *event))
        self.seq += 1

    def run(self, max_events: int) -> dict:
        self.m_free = self.m_busy = self.serve_master(0.0)
        handled = 0
        while self.events:
            handled += 1
            if handled > max_events:
                raise RuntimeError("simulate_hubs: no end in sight (max_events)")
            t, _, kind, h, *data = heapq.heappop(self.events)
            self.last = max(self.last, t)
            if kind.startswith("master_"):
                self.at_master(t, kind, h, data)
            else:
                self.at_hub(t, kind, h, data)
        workers, last = sum(self.groups), self.last
        return {"efficiency": self.task_s / (workers * last) if last > 0 else 1.0, "wall_s": last,
                "task_s": self.task_s, "nodes": sum(p.counters.get("nodes", 0) for p in self.pools),
                "found": sum(len(f) for p in self.pools for f in p.found), "tasks": self.tasks,
                "moved": self.moved, "messages": self.messages, "longest_s": self.longest, "workers": workers,
                "master_busy": self.m_busy / last if last > 0 else 0.0,
                "hub_busy": max(self.busy) / last if last > 0 else 0.0}

    def serve_master(self, t: float) -> float:
        """The master feeds the waiting hubs from its pool, else asks shares for the dry; its cost."""
        c, job = 0.0, self.job
        while self.waiting and job.pending():
            h = self.waiting.pop(0)
            self.starving.discard(h)
            n = min(max(1, int(self.chunk * self.groups[h])), max(1, -(-job.pending() // (len(self.waiting) + 1))))
            nodes = job.give(n)
            c += self.costs.send_s + self.node_s * len(nodes)
            self.moved += len(nodes)
            self.messages += 1
            self.post(t + c + self.costs.latency_s, "hub_nodes", h, nodes)
        if self.starving and not job.pending():
            rich = sorted((h for h in range(len(self.groups)) if h not in self.sharing), key=lambda h: -self.known[h])
            for h in rich[:len(self.starving)]:
                self.sharing.add(h)
                c += self.costs.send_s
                self.post(t + c + self.costs.latency_s, "hub_share", h)
        return c

    def at_master(self, t: float, kind: str, h: int, data: list) -> None:
        tm, c = max(t, self.m_free), self.costs.merge_s
        if kind == "master_ask":
            if h not in self.waiting:
                self.waiting.append(h)
            self.known[h] = data[0]
            (self.starving.add if data[1] else self.starving.discard)(h)
        elif kind == "master_share":
            nodes, self.known[h], answered = data
            if answered:
                self.sharing.discard(h)
            self.job.put(nodes)
            c += self.node_s * len(nodes)
        else:                                        # master_report: a frontier of data[0] nodes
            c += self.node_s * data[0]
        c += self.serve_master(tm + c)
        self.m_free, self.m_busy = tm + c, self.m_busy + c

    def at_hub(self, t: float, kind: str, h: int, data: list) -> None:
        pool, th, costs = self.pools[h], max(t, self.free[h]), self.costs
        c = costs.merge_s
        if kind == "hub_done":
            w, token, result, d = data
            pool.merge(token, result)
            self.idle[h].append(w)
            self.task_s += d
        elif kind == "hub_nodes":
            pool.put(data[0])
            self.asked[h] = False
            c += self.node_s * len(data[0])
        else:                                        # hub_share
            self.share[h] = True
        if self.share[h] and pool.pending() >= 2:    # half of the pool back, before its own workers
            self.share[h] = False
            c += self.give_back(th + c, h, pool.pending() // 2, True)
        c += self.hand_out(th + c, h)
        if pool.pending() > self.surplus * self.groups[h]:   # the surplus back: hubs hold little
            c += self.give_back(th + c, h, pool.pending() - int(self.low * self.groups[h]), False)
        now_dry = not pool.pending() and bool(self.idle[h])
        if (pool.pending() < self.low * self.groups[h] and not self.asked[h]) or now_dry != self.dry[h]:
            self.asked[h] = True
            c += costs.send_s
            self.post(th + c + costs.latency_s, "master_ask", h, pool.pending(), now_dry)
        elif th - self.reported[h] >= self.report_every_s:
            self.reported[h] = th
            c += costs.send_s
            self.post(th + c + costs.latency_s, "master_report", h,
                      pool.pending() + self.groups[h] - len(self.idle[h]))
        self.dry[h] = now_dry
        self.free[h], self.busy[h] = th + c, self.busy[h] + c

    def give_back(self, t: float, h: int, n: int, answered: bool) -> float:
        nodes = self.pools[h].give(n)
        c = self.costs.send_s + self.node_s * len(nodes)
        self.moved += len(nodes)
        self.post(t + c + self.costs.latency_s, "master_share", h, nodes, self.pools[h].pending(), answered)
        return c

    def hand_out(self, t: float, h: int) -> float:
        """Hub h's idle workers get tasks from its pool; its cost."""
        pool, c = self.pools[h], 0.0
        while self.idle[h]:
            taken = pool.take(self.groups[h], 1)
            if taken is None:
                break
            token, payload = taken
            c += self.costs.send_s
            self.tasks += 1
            result = pool.handler(pool.context, payload)
            d = float(self.seconds(result))
            self.longest = max(self.longest, d)
            self.post(t + c + self.costs.latency_s + d, "hub_done", h, self.idle[h].pop(), token, result, d)
        return c
