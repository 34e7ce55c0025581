"""Hubs: a second level between the master and its workers for tree jobs at scale
(issue 42, after PEBBL's hubs; docs/parallel.md "Hubs").

Layout (`layout`): ranks 1 .. size-1 in consecutive groups, each a hub and its workers (a
group stays on one host where ranks are placed by block). Hubs serve TreeJobs only; a
TaskJob's tasks go from the master to every rank >= 1, hubs included, as without hubs.

For a tree job the master keeps the job's pool and runs `run_master`; each hub runs `lead`
as its one task of the job. A hub keeps a pool of its own, serves its workers from it (one
task of the job's budget // BUDGET_DIVISOR per message, as TreeJob.take cuts it) and keeps
their open nodes, up to SURPLUS x its workers: beyond that it hands the shallowest back to
the master, down to LOW x its workers. It asks the master for nodes (CHUNK x its workers) when its pool holds
fewer than LOW x its workers. While a hub is dry (idle workers, nothing for them) and the
master's pool is empty, the master asks the hubs with the largest pools to share: such a hub
hands half of its pool back as soon as it holds two nodes. Every message from a hub is a
REPORT: the leaves found and the counters since its last one, and its frontier (its pool
and its tasks in flight) as of the last NODES message it merged (`seq`); it also reports
when it turns dry or stops being dry, and every REPORT_EVERY_S while its state changes. The
master's view of a hub is that frontier plus the nodes sent to it since: each report is a
consistent cut of the hub's part of the tree, so a checkpoint (the master's pool and views
as open) loses at most REPORT_EVERY_S of a hub's work and never counts a node twice. The job
is done when the master's pool is empty and every hub last reported nothing open, with
nothing sent since; the master then ends each hub's task (NODES with None) and the hub
answers with its final report. parallel.model.simulate_hubs models this schedule.

A stop (SIGTERM on the master) reaches every rank with the master's STOP: workers stop their
tasks and answer their hub (a subtree task hands back what it found and its open nodes),
the hub merges them and answers the master with its final report, as a subtree task does.
Answers do not depend on the layout (SPEC §5): every node is explored once, whoever runs it.
"""
from __future__ import annotations

import math
import os
import time

from hpcwedge.errors import UserError
from hpcwedge.parallel import mpi
from hpcwedge.parallel.cancel import task_stopping
from hpcwedge.parallel.jobs import TreeJob

#: workers per hub (0: no hubs); unset: HUB_WORKERS per hub from HUBS_FROM workers on
HUB_WORKERS_ENV = "HPCWEDGE_HUB_WORKERS"
HUBS_FROM, HUB_WORKERS = 256, 32
#: a hub asks for nodes when its pool holds fewer than LOW x its workers, CHUNK x its workers;
#: it hands back the shallowest above LOW x its workers once it holds more than SURPLUS x them
LOW, CHUNK, SURPLUS = 4, 2, 8
#: a hub's tasks explore the job's budget // BUDGET_DIVISOR nodes: its messages are cheap (it
#: serves a few dozen workers), and shorter tasks shorten the tail (parallel.model.simulate_hubs
#: at 1,024 ranks and 2,000 worker-seconds: 0.945-0.954 against 0.874-0.947 with the whole budget)
BUDGET_DIVISOR = 2
#: a hub whose state changed reports at least this often (seconds)
REPORT_EVERY_S = 1.0
#: a stopped hub waits this long for its workers' answers (the master waits 60 s for its hubs)
STOP_WAIT_S = 30.0


def layout(size: int, hub_workers: str | None = None) -> list[tuple[int, list[int]]] | None:
    """[(hub rank, its worker ranks)] for a world of `size` ranks, or None (one level).
    hub_workers: workers per hub (default: $HPCWEDGE_HUB_WORKERS; "0": no hubs; unset: hubs
    of HUB_WORKERS from HUBS_FROM workers on). A last group without a worker joins the one
    before it."""
    v = os.environ.get(HUB_WORKERS_ENV, "") if hub_workers is None else hub_workers
    if v.strip():
        g = int(v) if v.strip().isdigit() else -1
        if g < 0:
            raise UserError(f"{HUB_WORKERS_ENV}={v!r}: give a whole number of workers per hub (0: no hubs)")
        if g == 0:
            return None
    elif size - 1 < HUBS_FROM:
        return None
    else:
        g = HUB_WORKERS
    ranks = list(range(1, size))
    groups = [ranks[i:i + g + 1] for i in range(0, len(ranks), g + 1)]
    if groups and len(groups[-1]) < 2:
        if len(groups) == 1:
            return None
        last = groups.pop()
        groups[-1] += last
    return [(grp[0], grp[1:]) for grp in groups] or None


# ---------------------------------------------------------------- the hub's side

def lead(ctx, payload) -> dict:
    """A hub's task for one tree job (sent by run_master; ctx: the job's handler, context and
    kind, the hub's workers, the job's budget, its groups and id): its final report."""
    from hpcwedge.parallel.worker import current_comm
    return Hub(current_comm(), *ctx).run()


class Hub:
    """One hub's pool and workers for one tree job (module docstring)."""

    def __init__(self, comm, handler, context, kind: str, workers: list, budget: int, groups: int,
                 job_id: int):
        self.comm, self.workers, self.kind, self.job_id = comm, list(workers), kind, job_id
        self.handler, self.context = handler, context
        self.pool = TreeJob("hub", handler, context, [], max(1, budget // BUDGET_DIVISOR), {}, groups=groups)
        self.pool.max_scale = 1
        self.idle = self.workers[::-1]
        self.inflight: dict = {}         # worker -> token of its task
        self.fresh = set(self.workers)   # workers not yet sent this job's context
        self.seq, self.asked, self.dirty, self.open_reported = 0, False, False, 0
        self.share, self.dry = False, True  # a share asked of it; dry (idle workers, nothing for them) as last reported
        self.last_report = time.monotonic()
        self.task_s, self.tasks = 0.0, {w: 0 for w in self.workers}
        self.sends = mpi.Sends(len(self.workers) + 1)
        self._reset()

    def _reset(self) -> None:
        self.pool.found = [[] for _ in self.pool.found]
        self.pool.flagged = [[] for _ in self.pool.flagged]
        self.pool.counters = {"tasks": 0, "handed_back": 0}

    def run(self) -> dict:
        n = len(self.workers)
        while True:
            self._hand_out()
            pending = self.pool.pending()
            dry = not pending and bool(self.idle)
            if self.share and pending >= 2:          # half of the pool to the master, for a hub that is dry
                self.share = False
                self._report(returned=self.pool.give(pending // 2), shared=True)
            elif pending > SURPLUS * n:              # the surplus back: a hub holds, and reports, little
                self._report(returned=self.pool.give(pending - LOW * n))
            elif (pending < LOW * n and not self.asked) or dry != self.dry:
                self.asked = self.asked or pending < LOW * n
                self._report()
            elif not self.inflight and not pending and self.open_reported:
                self._report()               # done with all it had: the master may be waiting to end the job
            elif self.dirty and time.monotonic() - self.last_report >= REPORT_EVERY_S:
                self._report()
            got = self._wait(self.last_report + REPORT_EVERY_S)
            if got is None:
                continue
            if got == "stop":
                return self._stop()
            src, tag, msg = got
            if src != 0:
                self._take_result(src, tag, msg)
            elif tag == mpi.NODES:
                seq, tokens = msg
                if tokens is None:
                    return self._report(final=True)
                self.pool.put(tokens)
                self.seq, self.asked, self.dirty = seq, False, True
            elif tag == mpi.SHARE:
                self.share = True

    def _hand_out(self) -> None:
        from hpcwedge.parallel.worker import run_batch
        while self.idle and self.pool.pending():
            token, payload = self.pool.take(len(self.workers), 1)
            w = self.idle.pop()
            fresh = (self.kind, run_batch, (self.handler, self.context)) if w in self.fresh else None
            self.fresh.discard(w)
            self.sends.add(self.comm.isend((self.job_id, [payload], fresh, math.inf), dest=w, tag=mpi.TASK))
            self.inflight[w] = token
            self.dirty = True

    def _take_result(self, w: int, tag: int, msg, stopping: bool = False) -> None:
        token = self.inflight.pop(w)
        self.idle.append(w)
        self.dirty = True
        if tag == mpi.CANCELLED or (stopping and tag == mpi.ERROR):
            self.pool.put([token])           # still open
            return
        if tag == mpi.ERROR:
            if isinstance(msg, mpi.UserFailure):
                raise UserError(msg.line)
            cause = (str(msg).strip().splitlines() or ["?"])[-1]
            raise RuntimeError(f"worker rank {w} (hub {self.comm.rank}) failed on a {self.kind!r} task: "
                               f"{cause}\n{msg}")
        results, seconds = msg
        self.task_s += seconds
        self.tasks[w] += 1
        self.pool.merge(token, results[0])

    def _report(self, returned: list = (), shared: bool = False, final: bool = False) -> dict:
        """The hub's state since its last report (module docstring): sent to the master,
        or returned when final (the task's answer)."""
        p = self.pool
        rep = {"seq": self.seq, "found": p.found, "flagged": p.flagged, "counters": p.counters,
               "open": p.open_nodes(list(self.inflight.values())), "pool": p.pending(),
               "returned": list(returned), "shared": shared, "dry": not p.pending() and bool(self.idle),
               "want": CHUNK * len(self.workers) if self.asked else 0}
        self._reset()
        self.last_report, self.dirty, self.open_reported = time.monotonic(), False, len(rep["open"])
        self.dry = rep["dry"]
        if final:
            self.sends.complete(timeout=1.0)
            rep.update(task_s=self.task_s, tasks=self.tasks)
            return rep
        self.sends.add(self.comm.isend(rep, dest=0, tag=mpi.REPORT))
        return rep

    def _wait(self, deadline: float):
        """(source, tag, message) of the next message, None at the deadline, "stop" when the
        master's STOP is there (left for serve(), which ends on it)."""
        from mpi4py import MPI
        status = MPI.Status()
        t0 = time.monotonic()
        while True:
            if mpi.probe(self.comm, MPI.ANY_SOURCE, MPI.ANY_TAG, status):
                src, tag = status.Get_source(), status.Get_tag()
                if src == 0 and tag == mpi.STOP:
                    return "stop"
                return src, tag, self.comm.recv(source=src, tag=tag)
            now = time.monotonic()
            if task_stopping():
                return "stop"
            if now >= deadline:
                return None
            time.sleep(mpi.backoff(now - t0, mpi.POLL_MAX_MASTER))

    def _stop(self) -> dict:
        """The master's STOP reached every rank: the answers of the workers' tasks (at most
        STOP_WAIT_S), then the final report (a task not answered stays open)."""
        from mpi4py import MPI
        status = MPI.Status()
        end = time.monotonic() + STOP_WAIT_S
        while self.inflight and time.monotonic() < end:
            got = False
            for w in list(self.inflight):
                if mpi.probe(self.comm, w, MPI.ANY_TAG, status):
                    tag = status.Get_tag()
                    self._take_result(w, tag, self.comm.recv(source=w, tag=tag), stopping=True)
                    got = True
            if not got:
                time.sleep(0.005)
        return self._report(final=True)


# ---------------------------------------------------------------- the master's side

class _Lead:
    """A hub's task as Master.send_task sends it (kind, handler, context)."""

    def __init__(self, kind: str, context: tuple):
        self.kind, self.handler, self.context = kind, lead, context


class _View:
    """The master's view of one hub: its frontier at its last report, the NODES sent since
    [(seq, tokens)], its pool's size, how many nodes it wants, a share asked of it."""

    def __init__(self, workers: list):
        self.workers, self.open, self.sent = workers, [], []
        self.pool, self.want, self.asked_at, self.sharing, self.dry = 0, 0, 0.0, False, True

    def tokens(self) -> list:
        return self.open + [t for _, ts in self.sent for t in ts]


def run_master(engine, job: TreeJob, groups: list) -> None:
    """The master's loop of a tree job over hubs (module docstring); engine: the
    engine.Engine whose job it is (its checkpoint holds the views as tasks in flight)."""
    from hpcwedge.errors import Interrupted
    views = {h: _View(ws) for h, ws in groups}
    state = {"seq": 0}

    def absorb(h: int, rep: dict) -> None:
        v = views[h]
        job.absorb(rep["found"], rep["flagged"], rep["counters"])
        job.put(rep["returned"])
        v.sent = [(s, ts) for s, ts in v.sent if s > rep["seq"]]
        v.open, v.pool = rep["open"], rep["pool"]
        if rep["want"] and not v.sent and not v.want:
            v.want, v.asked_at = rep["want"], time.monotonic()
        v.sharing = v.sharing and not rep["shared"]
        v.dry = rep["dry"]
        engine.hold(h, v.tokens())
        if "task_s" in rep:
            engine.count_tasks(rep["task_s"], rep["tasks"])

    def answer(h: int, tag: int, msg) -> bool:
        if tag in (mpi.REPORT, mpi.RESULT):
            absorb(h, msg)
            return tag == mpi.RESULT
        engine.take_result(job, h, tag, msg)    # a hub's failure: raised
        return True

    for h, ws in groups:
        ctx = (job.handler, job.context, job.kind, ws, job.budget, len(job.found), engine.job_id)
        engine.master.send_task(h, engine.job_id, _Lead(job.kind, ctx), None)
        engine.hold(h, [])
    engine.clock.start()
    last_note = time.monotonic()
    try:
        while True:
            _feed(engine, job, views, state)
            if not job.pending() and not any(v.tokens() for v in views.values()):
                break
            deadline = min(engine.checkpoints.next_at, last_note + engine.progress_every_s
                           if engine.progress is not None and engine.progress_every_s > 0 else math.inf)
            got = mpi.wait_any(engine.comm, deadline, lambda: bool(engine.signals.flags), engine.clock)
            if got is not None:
                answer(*got)
            engine.safe_point()
            last_note = engine.note(job, last_note)
    except Interrupted as e:
        engine.write_checkpoint(str(e))
        engine.master.stop(set(views), 60.0, lambda h, tag, msg: answer(h, tag, msg) if tag != mpi.ERROR else True)
        raise
    for h in views:                      # the end: each hub's final report
        engine.master.isend((state["seq"] + 1, None), h, mpi.NODES)
    left = set(views)
    while left:
        h, tag, msg = mpi.wait_any(engine.comm, math.inf, lambda: False, engine.clock)
        if answer(h, tag, msg):
            left.discard(h)
            engine.hold(h, None)


def _feed(engine, job: TreeJob, views: dict, state: dict) -> None:
    """The master's pool to the hubs that want nodes, first asked first served (at most what
    each asked for, an even share of the pool among them); when the pool is empty, a share
    asked of the hubs that reported the largest pools."""
    waiting = sorted((h for h, v in views.items() if v.want), key=lambda h: views[h].asked_at)
    for i, h in enumerate(waiting):
        if not job.pending():
            break
        v = views[h]
        n = min(v.want, max(1, math.ceil(job.pending() / (len(waiting) - i))))
        tokens = [job.take(1, 1)[0] for _ in range(min(n, job.pending()))]
        state["seq"] += 1
        v.sent.append((state["seq"], tokens))
        v.want, v.dry = 0, False
        engine.master.isend((state["seq"], tokens), h, mpi.NODES)
        engine.hold(h, v.tokens())
        engine.clock.messages += 1
    dry = sum(1 for v in views.values() if v.dry)
    if dry and not job.pending():
        for h in sorted((h for h, v in views.items() if not v.sharing), key=lambda h: -views[h].pool)[:dry]:
            views[h].sharing = True
            engine.master.isend(None, h, mpi.SHARE)
            engine.clock.messages += 1
