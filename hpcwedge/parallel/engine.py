"""The engine: runs jobs behind one run(job), serially (one process) or as the
master of a world of workers (SPEC §5), with checkpoints and signals.

One process (no MPI launcher, or size 1): the task loop runs in-process. Under
mpirun: rank 0 is the master — it holds the pool, hands a task to each worker
that is free, merges results and alone writes files; ranks >= 1 run
worker.serve(comm) and only run tasks. With hubs (hub.py: from hub.HUBS_FROM workers on, or
$HPCWEDGE_HUB_WORKERS), a tree job's master serves hubs, and each hub a group of workers.

Checkpoints (checkpoint.py: the file and the Checkpointer): every
``checkpoint_every_s`` seconds, at SIGUSR1 (then the run goes on) and at
SIGTERM/SIGINT (then the master stops the workers — a task in progress is
dropped at its next task_tick() — and the command exits with
EXIT_INTERRUPTED). Signal handlers only set a flag inside the task loop, which
acts on it between two merges (a task is done only once its result is merged
into the master's state; tasks in flight are saved as open). Outside the loop,
SIGTERM raises ``Interrupted`` at once: the state is then the finished jobs.

A TaskJob task that runs long may pause (cancel.task_pausing, after checkpoint_every_s or
at a stop) and hand back a Continuation: the job keeps its payload as the task's open one
(in the checkpoint too) and hands it out again.

Resume: a job whose name is in the checkpoint starts from the saved state
(a finished job returns its saved results at once). The pipeline is
deterministic, so it asks for the same jobs in the same order.
"""
from __future__ import annotations

import json
import math
import os
import socket
import time

from hpcwedge.errors import Interrupted, UserError
from hpcwedge.parallel import hub, mpi
from hpcwedge.parallel.cancel import TICK_EVERY_S, Continuation, TaskCancelled, run_cancellable
from hpcwedge.parallel.checkpoint import Checkpointer, CheckpointError
from hpcwedge.parallel.jobs import TaskJob, TreeJob
from hpcwedge.parallel.schedule import MasterClock, cut, utilisation
from hpcwedge.parallel.signals import SignalState
from hpcwedge.parallel.worker import run_batch
from hpcwedge.progress import ShareClock, eta, left_text

#: exit status of `hpcwedge run` after SIGTERM/SIGINT: the checkpoint is written, rerun with --resume
EXIT_INTERRUPTED = 75
#: the master checks the memory guard (Engine.guard) at most this often (seconds)
GUARD_EVERY_S = 1.0


class Batch(list):
    """The tokens of the tasks in one batch (a worker's task in flight)."""


class Master:
    """Rank 0's side of the wire: says hello (host, pid) to every worker, sends tasks
    (with the job's context once per worker and job), stops the workers."""

    def __init__(self, comm):
        self.comm = comm
        self.workers = list(range(1, comm.size))
        self.stopped = False
        #: a task that can hand back a Continuation does so after this long (the checkpoint period)
        self.pause_every_s = math.inf
        self._ctx_sent: dict = {}        # worker -> job id whose context it holds
        self._sends = mpi.Sends(len(self.workers))
        for w in self.workers:           # small: an eager send, returns at once
            comm.send((socket.gethostname(), os.getpid()), dest=w, tag=mpi.HELLO)

    def send_task(self, w: int, job_id: int, job, payload, batched: bool = False) -> None:
        """batched: payload is a list of the job's payloads (run_batch runs them). Sent by isend:
        a blocking send of a context (too large to go eagerly) waits for the worker's probe."""
        fresh = self._ctx_sent.get(w) != (job_id, batched)    # a TreeJob's first batch: run_batch
        self._ctx_sent[w] = (job_id, batched)
        handler, ctx = (run_batch, (job.handler, job.context)) if batched else (job.handler, job.context)
        msg = (job_id, payload, (job.kind, handler, ctx) if fresh else None, self.pause_every_s)
        self._sends.add(self.comm.isend(msg, dest=w, tag=mpi.TASK))

    def isend(self, msg, dest: int, tag: int) -> None:
        """A message that is not a task (hub.py), sent without waiting."""
        self._sends.add(self.comm.isend(msg, dest=dest, tag=tag))

    def stop(self, waiting, timeout: float, on_answer) -> None:
        """Once: stop every worker, hand the answers of `waiting` to on_answer (mpi.stop_workers)."""
        if self.stopped:
            return
        self.stopped = True
        mpi.stop_workers(self.comm, self.workers, waiting, timeout, on_answer)
        self._sends.complete(timeout=1.0)      # a dead worker's stay pending


class Engine:
    """Runs jobs serially (comm None) or as the master of a world of workers.

    checkpoint: set with use_checkpoint(); signals: install_signals() (master, command line
    only). summary(): how the work was split (depends on the rank count and on resumes, unlike
    every answer). tick_every_s: how often a task run in-process looks at signals and the
    checkpoint timer (tasks.run_cancellable). progress: called with a line every
    `progress_every_s` seconds while a job runs (its task counts and job.progress())."""

    def __init__(self, comm=None, progress=None, tick_every_s: float = TICK_EVERY_S,
                 progress_every_s: float = 10.0):
        self.comm = comm
        self.size = comm.size if comm is not None else 1
        self.rank = comm.rank if comm is not None else 0
        self.progress = progress
        self.progress_every_s = progress_every_s
        self.tick_every_s = tick_every_s
        #: progress.MemoryGuard of the run (run.max_memory_gb), checked after merges (pipeline sets it)
        self.guard = None
        self.checkpoints = Checkpointer()
        self.signals = SignalState()
        #: every rank is past the collective start-up (run/batch.py) and the workers
        #: serve tasks: the master can stop them with a message (else only MPI_Abort can)
        self.serving = comm is None
        self.master = Master(comm) if comm is not None and self.rank == 0 else None
        self.tasks_per_rank = [0] * self.size  # this session, merged tasks by the rank that ran them
        self._jobs: dict = {}            # finished jobs, by name, in order
        self._current = None             # the job being run
        self._inflight: dict = {}        # rank -> token of its task in flight
        self.job_id = 0                  # the current job's (workers hold one job's context)
        #: (when, tasks done, share of the trees decided) as the current job started
        self._job_start = (time.monotonic(), 0, 0.0)
        self._job_before_s = 0.0         # the current job's seconds in earlier sessions
        self._share_clock = ShareClock(*self._job_start[::2])
        self._task_started = time.monotonic()     # the serial engine's current task
        self._batched = [0.0, 0]         # the current job's tasks: seconds, units of work (schedule.py)
        self._sent_at: dict = {}         # rank -> when its unbatched task was sent (its seconds)
        self._scale: dict = {}           # rank -> the budget scale of its tasks in flight
        self.clock = MasterClock()       # the master's busy seconds per message (schedule.py)
        self._use: dict = {}             # job name -> schedule.utilisation (under mpirun, this session)
        self._guarded = 0.0

    @property
    def is_master(self) -> bool:
        return self.rank == 0

    @property
    def resumes(self) -> int:
        return self.checkpoints.resumes

    @property
    def checkpoints_written(self) -> int:
        return self.checkpoints.written

    @property
    def checkpoint_reason(self) -> str | None:
        return self.checkpoints.reason

    # ---- checkpoints

    def use_checkpoint(self, path: str, scene_hash: str, scene_text: str, every_s: float,
                       resume: bool, inputs: dict[str, str] | None = None, changed_settings=None) -> bool:
        """Write checkpoints to `path`; with resume, continue from it if it exists
        (Checkpointer.use). Returns True when a checkpoint was loaded. A SIGTERM/SIGINT while
        it is read (seconds for a large one) acts once it is loaded: Interrupted then, with
        the loaded state to save, never an empty one over it."""
        held, self.signals.defer = self.signals.defer, True
        try:
            loaded = self.checkpoints.use(path, scene_hash, scene_text, every_s, resume, inputs, changed_settings)
            if self.master is not None:
                self.master.pause_every_s = float(every_s)
        finally:
            self.signals.defer = held
        if self.signals.stop_reason():
            raise Interrupted(self.signals.stop_reason())
        return loaded

    def restored(self, name: str) -> bool:
        """The checkpoint this run resumed from holds a job `name` not run yet in
        this session (the pipeline then runs that stage as jobs again, so that the
        saved work is used)."""
        return name in self.checkpoints.restored

    def elapsed(self) -> float:
        return self.checkpoints.elapsed()

    def write_checkpoint(self, reason: str = "timer") -> bool:
        """Write the master's state now (no-op without a checkpoint path); True if written.
        A write that fails keeps the previous checkpoint (Checkpointer.write)."""
        if not self.checkpoints.active or not self.is_master:
            return False
        jobs = [(name, _state(job, [], finished=True)) for name, job in self._jobs.items()]
        if self._current is not None and self._current.name not in self._jobs:
            st = _state(self._current, self._in_flight_tokens(), finished=False)
            st["attrs"]["job_elapsed_s"] = self._job_before_s + time.monotonic() - self._job_start[0]
            jobs.append((self._current.name, st))
        return self.checkpoints.write(jobs, self.size, reason)

    def _in_flight_tokens(self) -> list:
        """The tokens of every task in flight (a hub's batch unpacked)."""
        return [t for v in self._inflight.values() for t in (v if isinstance(v, Batch) else [v])]

    def remove_checkpoint(self) -> None:
        """The result is written: remove the checkpoint (Checkpointer.remove)."""
        self.checkpoints.remove()

    # ---- signals

    def install_signals(self) -> None:
        """Master: SIGUSR1 = checkpoint and go on; SIGTERM/SIGINT = checkpoint and stop.
        (Main thread only; elsewhere signals stay as they are.)"""
        self.signals.install()

    def mark_done(self) -> None:
        """Nothing is left to save (the result or the final checkpoint is written):
        from now on SIGTERM/SIGINT/SIGUSR1 change nothing, up to the process's exit.
        They are set to SIG_IGN: CPython's finalisation resets signals that have a
        Python handler to their default action, and a SIGTERM during the seconds
        of interpreter shutdown would turn a finished run into a killed one."""
        self.signals.mark_done()

    def safe_point(self) -> None:
        """Between merges: act on signals and the checkpoint timer."""
        stop = self.signals.stop_reason()
        if stop:
            raise Interrupted(stop)
        self._serve_checkpoint()

    def _serve_checkpoint(self) -> None:
        """Write the checkpoint SIGUSR1 or the timer asks for (tasks in flight saved as open)."""
        if self.signals.take_checkpoint_request():
            self.write_checkpoint("SIGUSR1")
        elif self.checkpoints.due():
            self.write_checkpoint("timer")

    def _in_task(self) -> bool:
        """In-process engine, polled inside a task (task_stopping): serves SIGUSR1, the checkpoint
        timer (the running task is saved as open) and a progress line every progress_every_s (> 0)
        of a long task, and says whether a SIGTERM/SIGINT asks the task to stop."""
        if self.signals.stop_reason():
            return True
        self._serve_checkpoint()
        now = time.monotonic()
        # only a task that has run a whole period itself: short tasks leave the line to note()
        if (self.progress is not None and 0 < self.progress_every_s <= now - self._last_note
                and now - self._task_started >= self.progress_every_s):
            self._last_note = now
            job = self._current
            if isinstance(job, TreeJob):       # the job's line, as the task leaves it open
                self.progress.note(self._job_line(job, now, f"; a task running for {now - self._task_started:.0f} s"))
            else:
                self.progress.note(f"{job.name}: a task running (1 rank, {self.elapsed():.0f} s)")
        return False

    # ---- running jobs

    def run(self, job):
        """Run `job` to the end (resuming it from the checkpoint if it is there); returns it."""
        if not self.is_master:
            raise RuntimeError("Engine.run is for the master; workers call parallel.serve(comm)")
        if job.name in self._jobs:
            raise ValueError(f"job name {job.name!r} used twice")
        self.signals.defer = True            # from here on, signals act at safe points only
        try:
            state = self.checkpoints.restored.get(job.name)
            self._job_before_s = 0.0
            if state is not None:
                before = float(state["attrs"].get("job_elapsed_s", 0.0))   # (older checkpoints: none)
                self._job_before_s = before if 0.0 <= before < math.inf else 0.0
                if state["attrs"].get("kind") != job.kind:
                    raise CheckpointError(f"job {job.name!r}: checkpoint kind {state['attrs'].get('kind')!r}, "
                                          f"this run {job.kind!r}")
                job.load(state)
                job.counters.update(json.loads(state["attrs"]["counters"]))
            self.job_id += 1
            self._current, self._inflight, self._batched = job, {}, [0.0, 0]
            self._job_start = (time.monotonic(), job.counters.get("tasks", 0),
                               job.decided_share([]) if isinstance(job, TreeJob) else 0.0)
            self._share_clock = (ShareClock.resumed(self._job_start[0], self._job_before_s, self._job_start[2])
                                 if self._job_before_s > 0.0 else ShareClock(self._job_start[0], self._job_start[2]))
            self.checkpoints.restored.pop(job.name, None)
            if self.signals.stop_reason():
                raise Interrupted(self.signals.stop_reason())
            groups = hub.layout(self.size) if self.size > 1 and isinstance(job, TreeJob) else None
            if self.size == 1:
                self._run_serial(job)
            else:
                if groups:
                    hub.run_master(self, job, groups)
                else:
                    self._run_master(job)
                workers = sum(len(ws) for _, ws in groups) if groups else len(self.master.workers)
                self._use[job.name] = {**utilisation(self._batched[0], workers, self.clock),
                                       "hubs": len(groups) if groups else 0}
                self._note_use(job.name)
            self._jobs[job.name] = job
            self._current, self._inflight = None, {}
        finally:
            self.signals.defer = False
        if self.signals.stop_reason():
            raise Interrupted(self.signals.stop_reason())
        return job

    def _run_serial(self, job) -> None:
        handler = job.handler
        self._last_note = self._task_started = time.monotonic()
        while True:
            self.safe_point()
            taken = job.take(1, getattr(job, "max_scale", 1))
            if taken is None:
                return
            token, payload = taken
            self._inflight[0] = token
            self._task_started = time.monotonic()
            try:
                result = run_cancellable(handler, job.context, payload, self._in_task, self.tick_every_s,
                                         self.checkpoints.every_s)
            except TaskCancelled:
                raise Interrupted(self.signals.stop_reason()) from None
            self._merge(job, token, result)    # done (or stopped, the rest handed back as open)
            del self._inflight[0]
            self.tasks_per_rank[0] += 1
            self._last_note = self.note(job, self._last_note)

    def _run_master(self, job) -> None:
        idle = [w for w in self.master.workers if w not in self._inflight][::-1]
        last_note = time.monotonic()
        self.clock.start()
        while True:
            self._hand_out(job, idle)
            if not self._inflight:
                return                         # pool empty, nothing in flight: done
            # the wait ends for the timer checkpoint and for the next progress line (a long task)
            deadline = min(self.checkpoints.next_at, last_note + self.progress_every_s
                           if self.progress is not None and self.progress_every_s > 0 else math.inf)
            got = mpi.wait_any(self.comm, deadline, lambda: bool(self.signals.flags), self.clock)
            if got is not None:
                w, tag, msg = got
                idle.append(w)
                self.take_result(job, w, tag, msg)
            try:
                self.safe_point()
            except Interrupted as e:
                # the state as of the signal first (tasks in flight as open): a task that does
                # not tick keeps its worker up to _stop_workers' timeout, and mpirun's SIGKILL
                # follows its SIGTERM within ~2 s; the caller writes again after the collection
                self.write_checkpoint(str(e))
                self._stop_workers(job)
                raise
            last_note = self.note(job, last_note)

    def _hand_out(self, job, idle: list) -> None:
        """To each idle worker while the pool lasts, a message of schedule.batch_size units of
        work: a batch of tasks, or tasks of a scaled budget (schedule.cut); a task alone goes
        unbatched unless it is a TaskJob's."""
        n_workers = len(self.master.workers)
        while idle:
            secs, units = self._batched
            k, scale = cut(n_workers, secs / units if units else None, job.pending(), self.clock.message_s(),
                           getattr(job, "max_scale", 1))
            taken = [t for t in (job.take(n_workers, scale) for _ in range(k)) if t is not None]
            if not taken:
                return
            w = idle.pop()
            self._scale[w] = scale
            self.clock.messages += 1
            if isinstance(job, TaskJob) or len(taken) > 1:
                self._inflight[w] = Batch(t for t, _ in taken)
                self.master.send_task(w, self.job_id, job, [p for _, p in taken], batched=True)
            else:
                (self._inflight[w], payload), self._sent_at[w] = taken[0], time.monotonic()
                self.master.send_task(w, self.job_id, job, payload)

    def take_result(self, job, w: int, tag: int, msg) -> None:
        """Merge worker w's answer to its task in flight (done: in the master's state);
        a cancelled task stays open (not in flight any more: the caller keeps it)."""
        token = self._inflight.pop(w)
        if tag == mpi.CANCELLED:
            self._inflight[w] = token
            return
        if tag == mpi.ERROR and isinstance(msg, mpi.UserFailure):
            raise UserError(msg.line)
        if tag == mpi.ERROR:
            # the worker's exception (its traceback's last line) on the first line, which is
            # all the command line prints; the whole traceback after it (HPCWEDGE_DEBUG=1)
            cause = (str(msg).strip().splitlines() or ["?"])[-1]
            raise RuntimeError(f"worker rank {w} failed on a {job.kind!r} task: {cause}\n{msg}")
        # a batch's seconds as its worker measured them; a task alone's from send to answer
        msg, seconds = msg if isinstance(token, Batch) else (msg, time.monotonic() - self._sent_at[w])
        self._batched[0] += seconds
        self._batched[1] += (len(token) if isinstance(token, Batch) else 1) * self._scale.get(w, 1)
        for t, result in zip(token, msg, strict=True) if isinstance(token, Batch) else [(token, msg)]:
            self._merge(job, t, result)
            self.tasks_per_rank[w] += 1

    def hold(self, rank: int, tokens: list | None) -> None:
        """hub.py: rank's tasks in flight are `tokens` (a checkpoint saves them as open; None: none)."""
        if tokens is None:
            self._inflight.pop(rank, None)
        else:
            self._inflight[rank] = Batch(tokens)

    def count_tasks(self, seconds: float, tasks: dict) -> None:
        """hub.py: tasks that ran elsewhere ({rank: tasks}) and their seconds, for utilisation."""
        self._batched[0] += seconds
        self._batched[1] += sum(tasks.values())
        for w, k in tasks.items():
            self.tasks_per_rank[w] += k

    def _merge(self, job, token, result) -> None:
        """job.merge; a Continuation (a long task paused) makes the checkpoint due, so that
        the next safe point saves its progress."""
        job.merge(token, result)
        if isinstance(result, Continuation) and self.checkpoints.active:
            self.checkpoints.next_at = 0.0

    def _stop_workers(self, job, timeout: float = 60.0) -> None:
        """SIGTERM/SIGINT on the master, inside a job, once the checkpoint of the state at
        the signal is written: stop every worker and collect what is in flight for the stop
        checkpoint that follows — a subtree task hands back what it
        found and its open subtrees (merged, nothing lost), another kind is
        cancelled (kept as open); a failed one stays open too (the checkpoint must
        still be written). At most `timeout` seconds; afterwards close() has
        nothing to do."""
        def answer(src, tag, msg):
            if tag != mpi.ERROR:
                self.take_result(job, src, tag, msg)
        self.master.stop(set(self._inflight), timeout, answer)

    def tell(self, text: str) -> None:
        """A line from the jobs' owner among the progress lines (nothing without progress)."""
        if self.progress is not None:
            self.progress.note(text)

    def note(self, job, last: float) -> float:
        """After a merge: the memory guard (at most every GUARD_EVERY_S), and every
        progress_every_s a progress line."""
        now = time.monotonic()
        if self.guard is not None and now - self._guarded >= GUARD_EVERY_S:
            self._guarded = now
            self.guard.check(0, f"the {job.name!r} stage holds its results and {job.pending()} "
                                f"open tasks after {job.counters.get('tasks', 0)} tasks")
        if self.progress is None or now - last < self.progress_every_s:
            return last
        self.progress.note(self._job_line(job, now))
        return now

    def _job_line(self, job, now: float, running: str = "") -> str:
        """The progress line of `job`: its tasks, what job.progress() adds, a tree job's share
        decided, and the time left (a task list: at this session's rate; a tree: from its share's
        recent growth, progress.ShareClock); `running` ends it (a long task)."""
        done = job.counters.get("tasks", 0)
        left = decided = ""
        t0, done0, _ = self._job_start
        if isinstance(job, TaskJob):           # a fixed list of tasks
            left = eta(now - t0, done - done0, len(job.payloads) - done0)
        elif isinstance(job, TreeJob):         # the share of the trees decided, and its recent rate
            share = job.decided_share(self._in_flight_tokens())
            decided = f", {100 * share:.3g} % of the tree decided"
            left = left_text(self._share_clock.left(now, share) if share < 1.0 else None)
        return (f"{job.name}: {done} tasks done, {job.pending()} pending, "
                f"{len(self._inflight)} running{job.progress()}{decided} ({self.size} rank(s), "
                f"{self.elapsed():.0f} s{left}{running})")

    def _note_use(self, name: str) -> None:
        """After a job that ran progress_every_s or longer under mpirun: how busy its workers were."""
        u = self._use[name]
        if self.progress is not None and 0 < self.progress_every_s <= u["wall_s"]:
            self.progress.note(f"{name}: {u['wall_s']:.0f} s on {u['workers']} workers, busy "
                               f"{u['workers_busy']:.0%} of it (the master {u['master_busy']:.0%})")

    def summary(self) -> dict:
        """How the work was split: depends on ranks and resumes (answers do not); utilisation:
        per job run under mpirun in this session, schedule.utilisation."""
        return {"ranks": self.size, "resumes": self.resumes, "tasks_per_rank": list(self.tasks_per_rank),
                "utilisation": dict(self._use),
                "checkpoints_written": self.checkpoints_written,
                "last_checkpoint_reason": self.checkpoint_reason or "",
                "elapsed_s_all_sessions": self.elapsed(),
                "jobs": {name: dict(job.counters) for name, job in self._jobs.items()}}

    def close(self, timeout: float = 60.0, restore_signals: bool = True) -> None:
        """Master: stop every worker — one in a task that calls task_tick() drops it
        and says so — and collect what is still in flight (a worker blocked in a
        large send would never read the stop; at most `timeout` seconds); restore
        the signal handlers (the command line keeps its own to the end: a signal
        after mark_done() must not turn a finished run into a failed one)."""
        if self.master is not None:
            self.master.stop(set(self._inflight), timeout, lambda src, tag, msg: self._inflight.pop(src, None))
        if restore_signals:
            self.signals.restore()


def _state(job, in_flight, finished: bool) -> dict:
    """A job's checkpoint state: its save() with kind, finished and counters."""
    st = job.save(in_flight)
    st["attrs"].update({"kind": job.kind, "finished": finished, "counters": json.dumps(job.counters)})
    return st


def run_tasks(handler, context, payloads: list, engine: Engine | None = None, name: str | None = None,
              layout=None, payloads_for=None, kind: str | None = None) -> list:
    """Results of independent tasks of `handler` (a module-level callable), in order.
    Results must be dicts of numbers/bools/arrays (so that checkpoints can hold them).
    layout, payloads_for: see TaskJob (a resumed run keeps the saved layout)."""
    engine = engine or Engine()
    job = TaskJob(name or kind or handler.__name__, handler, context, payloads, kind=kind, layout=layout,
                  payloads_for=payloads_for)
    return engine.run(job).output()
