"""How the master cuts the pool into messages (issue 42): how much work one message
carries, so that the master stays below MAX_BUSY of its time while every worker is busy,
and how that grows and shrinks with the pool. Answers never depend on it (SPEC §5); the
engine (engine.py) and its model (model.py) both follow it.

A message carries units of work: a batch of tasks (a TaskJob), or tasks whose budget is
`scale` x the job's own (a job with max_scale > 1, a TreeJob), batched when one is not enough. A unit's seconds are measured as the run goes (mean over merged tasks), and so is
the master's own cost per message (its wall seconds less its sleeps, per message sent:
~0.1 ms on a rank with a core of its own, 1-2 ms on 2 cores shared by 65 ranks, bench_scale).
"""
from __future__ import annotations

import math
import time

#: the master's cost per message before it has measured its own (seconds; up to 1.2 ms of
#: wall on 2 oversubscribed cores, bench_scale), and the share of its time it may be busy: a
#: master busy 0.66 of the time with 1,023 workers of one 0.12 s task each already queues
#: answers for 12 % of the time (the face workload's model at 1,024 ranks: efficiency 0.878
#: at 0.8, 0.926 at 0.5, 0.959 at 0.3; at 129 ranks and fewer every message is one task
#: either way)
MESSAGE_S, MAX_BUSY = 2e-3, 0.3
#: messages the master sends before its own measure of their cost replaces MESSAGE_S
MEASURED_AFTER = 64


def message_cost(busy_s: float, messages: int) -> float:
    """The master's cost per message that sizes the next one: busy_s / messages once
    MEASURED_AFTER messages are out, MESSAGE_S before (the engine's clock and its model)."""
    return max(0.0, busy_s) / messages if messages >= MEASURED_AFTER else MESSAGE_S


def batch_size(workers: int, mean_task_s: float | None, pending: int, message_s: float = MESSAGE_S) -> int:
    """Units of work in the next message to a worker (>= 1), with `pending` in the pool:
    enough for the message to last workers x message_s / MAX_BUSY seconds at `mean_task_s`
    a unit (None, nothing done yet: 1), at most pending / (2 x workers) (guided
    self-scheduling: the pool is shared out while it is short, the last messages are short)."""
    if not mean_task_s:
        return 1
    return max(1, min(math.ceil(workers * message_s / MAX_BUSY / mean_task_s), pending // (2 * workers)))


def cut(workers: int, mean_unit_s: float | None, pending: int, message_s: float = MESSAGE_S,
        max_scale: int = 1) -> tuple[int, int]:
    """(tasks in the next message, each task's budget scale), with `pending` in the pool:
    batch_size units of work, as a batch of tasks (max_scale 1, a TaskJob) or, for a job whose
    tasks grow up to max_scale (a TreeJob), as tasks of that many units, or of
    pending / (2 x workers) when more (a long pool: fewer, longer tasks, after mplrs'
    budgets, graded so that a pool of a few nodes per worker keeps tasks short as the end
    nears), at most max_scale, as many as make the units."""
    units = batch_size(workers, mean_unit_s, pending, message_s)
    if max_scale <= 1:
        return units, 1
    scale = max(1, min(max(units, pending // (2 * workers)), max_scale))
    return math.ceil(units / scale), scale


class MasterClock:
    """The master's busy seconds (wall time less its sleeps while it waits for answers:
    mpi.wait_any adds them to `slept_s`) and the messages it sent since start(): message_s()
    is busy seconds per message once MEASURED_AFTER messages are out (MESSAGE_S before)."""

    def __init__(self):
        self.slept_s, self.messages = 0.0, 0
        self._t0 = time.perf_counter()

    def start(self) -> None:
        self.slept_s, self.messages, self._t0 = 0.0, 0, time.perf_counter()

    def busy_s(self) -> float:
        """The master's busy seconds since start()."""
        return time.perf_counter() - self._t0 - self.slept_s

    def wall_s(self) -> float:
        return time.perf_counter() - self._t0

    def message_s(self) -> float:
        return message_cost(self.busy_s(), self.messages)


def utilisation(task_s: float, workers: int, clock: MasterClock) -> dict:
    """A job's use of the ranks, from its master's clock (started with the job): wall_s,
    workers, workers_busy = task_s / (workers x wall_s) (task_s: the tasks' seconds as the
    engine measures them, a task alone from send to answer), master_busy = busy / wall."""
    wall = clock.wall_s()
    return {"wall_s": wall, "workers": workers, "workers_busy": min(1.0, task_s / (workers * wall)) if wall > 0 else 0.0,
            "master_busy": min(1.0, clock.busy_s() / wall) if wall > 0 else 0.0}
