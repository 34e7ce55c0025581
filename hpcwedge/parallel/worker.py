"""The worker loop (ranks >= 1 under mpirun): run the tasks the master, or its hub
(hub.py), sends until the master says stop, and answer each to whoever sent it with its
result, a cancellation or an error."""
from __future__ import annotations

import importlib
import os
import signal
import socket
import time
import traceback

from hpcwedge.errors import UserError
from hpcwedge.parallel import mpi
from hpcwedge.parallel.cancel import TICK_EVERY_S, TaskCancelled, in_task_scopes, run_cancellable


#: the communicator serve() runs on (a hub's task, hub.lead, speaks to its workers on it)
_comm = None


def current_comm():
    """The communicator of this worker's serve() loop (None outside it)."""
    return _comm


def serve(comm, warm_up: tuple[str, ...] = (), tick_every_s: float = TICK_EVERY_S) -> None:
    """Worker loop (ranks >= 1): run tasks until the master says stop. warm_up: modules to
    import first (the task handlers' heavy imports: while the master condenses, not at
    the first task).

    SIGUSR1, SIGTERM and SIGINT are ignored: the master acts on them. (mpirun
    forwards SIGUSR1 to every rank, whose default action is to die. On
    SIGTERM, mpirun sends SIGCONT to every rank, SIGTERM 1 s later and
    SIGKILL ~1 s after that; a worker that died at once would make it kill
    the master before its checkpoint is written.)

    A worker exits when its parent (mpirun) is gone, or when its master runs
    on the same host and has died (kill -9): mpirun would otherwise take
    ~2 s (SIGCONT, SIGTERM, SIGKILL) to tear the job down."""
    from mpi4py import MPI
    global _comm
    _comm = comm
    for sig in (signal.SIGUSR1, signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, signal.SIG_IGN)
    ppid = os.getppid()
    for name in warm_up:
        importlib.import_module(name)
    ctx_id, kind, handler, ctx = None, None, None, None
    status = MPI.Status()
    master_pid, host = None, socket.gethostname()
    poll_max = mpi.worker_poll_max()
    while True:
        t0 = checked = time.monotonic()
        while not mpi.probe(comm, MPI.ANY_SOURCE, MPI.ANY_TAG, status):
            now = time.monotonic()
            if now - checked >= mpi.MASTER_CHECK_S:
                checked = now
                if os.getppid() != ppid or (master_pid is not None and not mpi.pid_alive(master_pid)):
                    os._exit(3)
            time.sleep(mpi.backoff(now - t0, poll_max))
        src, tag = status.Get_source(), status.Get_tag()
        msg = comm.recv(source=src, tag=tag)
        if tag == mpi.STOP and src == 0:
            return
        if tag == mpi.HELLO and src == 0:
            master_pid = msg[1] if msg[0] == host else None
            continue
        if tag != mpi.TASK:
            continue                # late words of a hub's task that failed (hub.py): nobody waits for them
        job_id, payload, fresh, pause_every_s = msg
        if fresh is not None:
            ctx_id, (kind, handler, ctx) = job_id, fresh
        try:
            if ctx_id != job_id:
                raise RuntimeError(f"task of job {job_id} without its context")
            result = run_cancellable(handler, ctx, payload,
                                     lambda: mpi.probe(comm, 0, mpi.STOP, status), tick_every_s, pause_every_s)
        except TaskCancelled:
            comm.send(None, dest=src, tag=mpi.CANCELLED)     # the stop is read next
        except MemoryError:
            from hpcwedge.progress import out_of_memory
            comm.send(mpi.UserFailure(str(out_of_memory(f"a {kind!r} task on rank {comm.rank}"))),
                      dest=src, tag=mpi.ERROR)
        except Exception as e:          # noqa: BLE001  (the master reports it)
            comm.send(mpi.UserFailure(str(e)) if isinstance(e, UserError) else traceback.format_exc(),
                      dest=src, tag=mpi.ERROR)
        else:
            comm.send(result, dest=src, tag=mpi.RESULT)

def run_batch(ctx, payloads: list) -> tuple[list, float]:
    """The handler of a batch of tasks (the engine sends it by reference): ctx = (handler,
    context); their results in order and the seconds they took. Each task runs in task
    scopes of its own (cancel.task_scope), as an unbatched one does."""
    handler, context = ctx
    t0 = time.perf_counter()
    results = [in_task_scopes(handler, context, p) for p in payloads]
    return results, time.perf_counter() - t0
