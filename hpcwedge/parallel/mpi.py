"""MPI plumbing: find the world communicator, wait for messages without spinning,
the tags master and workers speak, and facts about the host (ranks, live pids).

Idle ranks sleep: Open MPI's blocking receive busy-polls a core, so every
wait is a burst of ``Iprobe`` calls + ``time.sleep`` with a back-off (10% of
the time waited so far, at most POLL_MAX seconds; an idle worker costs well
under 1% of a core, see tests). The burst matters: Open MPI's Iprobe sees a
message that is already there only after ~10 progress calls, so one probe per
sleep made every round trip cost ~140 ms instead of ~0.2 ms.

mpi4py is imported only by world() and by the functions that wait (never at
module level): a serial run initialises no MPI.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass

from hpcwedge.errors import UserError

#: longest sleep between two probes of an idle worker / of the master (seconds);
#: a rank that has waited t seconds sleeps min(cap, POLL_FRACTION * t), so a
#: result is noticed within ~10% of the task's duration
POLL_MAX = 0.05
POLL_MAX_MASTER = 0.01
POLL_FRACTION = 0.1
#: an idle worker's longest sleep where every rank of its host has a core of its own: its
#: probes then take no one's core, and a task handed out in a tree's ramp-up or tail starts
#: within ~2 ms, not up to POLL_MAX late (bench_scale's model at 1,024 ranks)
POLL_MAX_OWN_CORE = 0.002
#: probes per wake-up: Open MPI's Iprobe reports a message that has arrived only
#: after several progress calls (~10 measured here), so each wake-up probes in a burst
PROBE_BURST = 32
#: how often an idle worker checks that its master (same host) is still alive
MASTER_CHECK_S = 0.2

#: message tags between the master (rank 0), or a hub, and a worker
TASK, RESULT, ERROR, STOP, HELLO, CANCELLED = 1, 2, 3, 4, 5, 6
#: between the master and a hub (hub.py): the hub's state, open nodes for it, a share asked of it
REPORT, NODES, SHARE = 7, 8, 9

#: environment variables an MPI launcher sets in every rank
MPI_ENV = ("OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE", "MPI_LOCALNRANKS")


class ParallelError(UserError):
    """A launch problem the user must fix (one line; exit status 2)."""


@dataclass
class UserFailure:
    """A worker's task stopped on a user-facing error (run.max_memory_gb, bad input):
    its one line, raised again on the master (exit status 2, no traceback)."""

    line: str


def world():
    """The MPI world communicator when launched by an MPI launcher (mpirun, srun
    --mpi=pmix) with more than one rank, else None (no MPI is initialised).

    Set HPCWEDGE_MPI=0 to never use MPI, =1 to always initialise it. When
    SLURM_NTASKS is set, the world size must equal it: srun without a working
    PMIx starts N independent single-rank copies, which would each redo the
    whole run and race on the output (ParallelError; HPCWEDGE_IGNORE_SLURM_NTASKS=1
    skips the check)."""
    mode = os.environ.get("HPCWEDGE_MPI", "")
    if mode == "0":
        return None
    ntasks = os.environ.get("SLURM_NTASKS", "")
    ntasks = int(ntasks) if ntasks.isdigit() else None
    launched = any(k in os.environ for k in MPI_ENV)
    if not (launched or mode == "1" or (ntasks or 0) > 1):
        return None
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    if ntasks is not None and comm.size != ntasks and not os.environ.get("HPCWEDGE_IGNORE_SLURM_NTASKS"):
        raise ParallelError(
            f"SLURM_NTASKS={ntasks} but this process is rank {comm.rank} of an MPI world of "
            f"{comm.size}: the launcher started independent copies (srun without PMIx?); use "
            f"`srun --mpi=pmix` or `mpirun -n {ntasks}`, or set HPCWEDGE_IGNORE_SLURM_NTASKS=1")
    return comm if comm.size > 1 else None


def pid_alive(pid: int) -> bool:
    """False once the process is gone or a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except (OSError, IndexError):
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except OSError:
            pass
        return True


def local_ranks() -> int | None:
    """The ranks of this job on this host, as the launcher says (Open MPI, MPICH, SLURM's
    srun); None when it does not say."""
    for key in ("OMPI_COMM_WORLD_LOCAL_SIZE", "MPI_LOCALNRANKS", "SLURM_NTASKS_PER_NODE"):
        v = os.environ.get(key, "")
        if v.isdigit() and int(v) > 0:
            return int(v)
    return None


def worker_poll_max() -> float:
    """An idle worker's longest sleep: POLL_MAX_OWN_CORE when the host has a core for each of
    its ranks (its cores: os.cpu_count(), or SLURM_CPUS_ON_NODE when fewer), else POLL_MAX
    (also when the launcher does not say how many ranks share the host)."""
    ranks = local_ranks()
    cores = os.cpu_count() or 1
    slurm = os.environ.get("SLURM_CPUS_ON_NODE", "")
    if slurm.isdigit() and int(slurm) > 0:
        cores = min(cores, int(slurm))
    return POLL_MAX_OWN_CORE if ranks is not None and ranks <= cores else POLL_MAX


def backoff(waited: float, cap: float) -> float:
    """The sleep of a rank that has waited `waited` seconds: POLL_FRACTION of it, in [1e-4, cap]."""
    return min(cap, max(1e-4, POLL_FRACTION * waited))


def probe(comm, source, tag, status) -> bool:
    """A burst of PROBE_BURST Iprobe calls: True (status filled) when a message is there."""
    for _ in range(PROBE_BURST):
        if comm.Iprobe(source=source, tag=tag, status=status):
            return True
    return False


def pending(requests: list, timeout: float = 0.0) -> list:
    """The requests of `requests` (mpi4py isend requests) not yet complete, after
    testing them for up to `timeout` seconds (0: once). A request dropped from the list
    is complete (its buffer can go)."""
    end = time.monotonic() + timeout
    while True:
        requests = [r for r in requests if not r.Test()]
        if not requests or time.monotonic() >= end:
            return requests
        time.sleep(0.001)


class Sends:
    """The master's isend requests not yet known complete: add() keeps one, and tests them
    all (pending) once they reach a mark of 2 x max(workers, those left at the last test),
    so that each send costs O(1) tests amortised; complete(timeout) tests them for up to
    timeout seconds."""

    def __init__(self, workers: int):
        self.workers, self.requests, self.mark = workers, [], 2 * workers

    def add(self, request) -> None:
        self.requests.append(request)
        if len(self.requests) >= self.mark:
            self.complete()

    def complete(self, timeout: float = 0.0) -> None:
        self.requests = pending(self.requests, timeout)
        self.mark = 2 * max(self.workers, len(self.requests))


def wait_any(comm, deadline: float, interrupted, clock=None) -> tuple | None:
    """The next message from any rank as (source, tag, message), or None at the
    deadline (time.monotonic) or as soon as interrupted() is true; its sleeps are added
    to clock.slept_s (a schedule.MasterClock) when given."""
    from mpi4py import MPI
    status = MPI.Status()
    t0 = time.monotonic()
    while True:
        if probe(comm, MPI.ANY_SOURCE, MPI.ANY_TAG, status):
            src, tag = status.Get_source(), status.Get_tag()
            return src, tag, comm.recv(source=src, tag=tag)
        now = time.monotonic()
        if interrupted() or now >= deadline:
            return None
        nap = backoff(now - t0, POLL_MAX_MASTER)
        time.sleep(nap)
        if clock is not None:
            clock.slept_s += nap


def stop_workers(comm, workers, waiting, timeout: float, on_answer) -> None:
    """Master: send STOP to every worker, then hand each message of a rank in `waiting` (those
    with a task in flight) to on_answer(source, tag, message): it is that rank's answer unless
    on_answer returns False (a hub's report before its answer); other messages are dropped.
    At most `timeout` seconds (a worker blocked in a large send would never read the stop)."""
    from mpi4py import MPI
    for w in workers:
        comm.send(None, dest=w, tag=STOP)
    status = MPI.Status()
    waiting = set(waiting)
    end = time.monotonic() + timeout
    while waiting and time.monotonic() < end:
        if probe(comm, MPI.ANY_SOURCE, MPI.ANY_TAG, status):
            src, tag = status.Get_source(), status.Get_tag()
            msg = comm.recv(source=src, tag=tag)
            if src in waiting and on_answer(src, tag, msg) is not False:
                waiting.discard(src)
        else:
            time.sleep(0.005)
