"""Run under mpirun by test_mpi.py and test_worker.py: measure, from /proc, the CPU time of idle
ranks while (A) the master is busy and no worker has a task, (B) one worker
runs a long task and the others have nothing, and (C, the control) a worker
waits in a plain blocking comm.recv, which Open MPI busy-polls. Prints one
JSON line: seconds of CPU per rank and phase, and each phase's length.

With the argument "cancel": every worker runs a 60 s task that calls
task_tick(); the master gets SIGTERM after 0.5 s and closes the
engine; prints when the job was interrupted and when close() returned.

With the arguments "stuck PATH": every worker runs an 8 s task that never ticks; the master,
checkpointing to PATH, gets SIGTERM after 0.5 s; prints when PATH appeared.

With the argument "send": the worker starts serving only after 2 s; the master sends it a task
whose context is 4 MB (engine.Master.send_task) and prints how long the send took, and the
answer's tag once it is in.

With the argument "boom": a worker's task raises ValueError("injected fault"); the master
prints the first line of the RuntimeError it gets (all the command line shows of it)."""
import json
import os
import sys
import time

from hpcwedge.errors import Interrupted
from hpcwedge.parallel.cancel import task_tick
from hpcwedge.parallel.engine import Engine, run_tasks
from hpcwedge.parallel.mpi import world
from hpcwedge.parallel.worker import serve
from hpcwedge.run.batch import WORKER_MODULES


def spin(ctx, seconds):
    t = time.perf_counter()
    while time.perf_counter() - t < seconds:
        if ctx == "tick":
            task_tick()
    return {"pid": os.getpid()}



def boom(ctx, payload):
    raise ValueError("injected fault")



def cpu(pid):
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main(period):
    comm = world()
    for name in WORKER_MODULES:      # the workers' start-up imports, done before measuring
        __import__(name)
    pids = comm.gather(os.getpid(), root=0)
    if comm.rank:
        serve(comm)
        comm.recv(source=0)          # phase C: a blocking receive (busy-polls)
        return
    engine = Engine(comm)
    time.sleep(0.3)                  # let the workers settle into their idle wait
    out = {"pids": pids, "period": period}

    def measure(phase, action):
        before = [cpu(p) for p in pids]
        t = time.perf_counter()
        action()
        out[phase] = {"seconds": time.perf_counter() - t,
                      "cpu": [cpu(p) - b for p, b in zip(pids, before)]}

    measure("master_busy", lambda: spin(None, period))
    measure("one_task", lambda: run_tasks(spin, None, [period], engine=engine))
    engine.close()
    time.sleep(0.2)
    measure("blocking_recv", lambda: time.sleep(period / 2))
    for w in range(1, comm.size):
        comm.send(None, dest=w)
    print(json.dumps(out), flush=True)


def _master():
    """The world's communicator on the master; None on a worker, after it has served."""
    comm = world()
    if comm.rank:
        serve(comm)
        return None
    return comm


def cancel():
    import signal
    import threading
    comm = _master()
    if comm is None:
        return
    engine = Engine(comm)
    engine.install_signals()
    threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGTERM)).start()
    t = time.perf_counter()
    out = {"interrupted": None}
    try:
        run_tasks(spin, "tick", [60.0] * (comm.size - 1), engine=engine)
    except Interrupted:
        out["interrupted"] = time.perf_counter() - t
    engine.close(timeout=30.0)
    out["closed"] = time.perf_counter() - t
    print(json.dumps(out), flush=True)


def stuck(path):
    """Every worker in an 8 s task that never ticks; SIGTERM to the master after 0.5 s, with
    checkpoints to `path`: prints when the checkpoint file appeared and when the job was
    interrupted (seconds from the start)."""
    import signal
    import threading
    comm = _master()
    if comm is None:
        return
    engine = Engine(comm)
    engine.install_signals()
    engine.use_checkpoint(path, "h", "scene", 3600.0, resume=False)
    t = time.perf_counter()
    out = {"checkpoint_at": None, "interrupted": None}

    def watch():
        while out["checkpoint_at"] is None and time.perf_counter() - t < 60:
            if os.path.exists(path):
                out["checkpoint_at"] = time.perf_counter() - t
            time.sleep(0.01)
    watcher = threading.Thread(target=watch)
    watcher.start()
    threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGTERM)).start()
    try:
        run_tasks(spin, None, [8.0] * (comm.size - 1), engine=engine)
    except Interrupted:
        out["interrupted"] = time.perf_counter() - t
    watcher.join()
    engine.close(timeout=30.0)
    print(json.dumps(out), flush=True)


def echo(ctx, payload):
    return len(ctx)


def send():
    from hpcwedge.parallel import mpi
    from hpcwedge.parallel.jobs import TaskJob
    comm = world()
    if comm.rank:
        time.sleep(2.0)              # busy elsewhere: not in a receive
        serve(comm)
        return
    engine = Engine(comm)
    job = TaskJob("big", echo, b"x" * (4 << 20), [None])
    t = time.perf_counter()
    engine.master.send_task(1, 1, job, None)
    out = {"send_s": time.perf_counter() - t}
    answer = mpi.wait_any(comm, time.monotonic() + 60, lambda: False)
    out["answer"] = None if answer is None else [answer[1], answer[2]]
    out["answer_s"] = time.perf_counter() - t
    engine.close()
    print(json.dumps(out), flush=True)


def fail():
    comm = _master()
    if comm is None:
        return
    engine = Engine(comm)
    try:
        run_tasks(boom, None, [1], engine=engine)
    except RuntimeError as e:
        print(json.dumps({"first_line": str(e).splitlines()[0]}), flush=True)
    engine.close(timeout=30.0)


if __name__ == "__main__":
    if sys.argv[1] == "stuck":
        stuck(sys.argv[2])
    else:
        {"cancel": cancel, "boom": fail, "send": send}.get(sys.argv[1], lambda: main(float(sys.argv[1])))()
