"""A long call that keeps the interpreter's lock, run in a child process so that a signal is
served within a step: forked (`in_child`, where `can_fork`), or a fresh interpreter started for
it (`in_spawned`, where MPI or PETSc already run here: the master of an MPI run).

PETSc's factorisation of K_ii (contact.condense: 47 s for the 514,242 DOFs of block2d refine
160 on 2 shared cores) holds the interpreter's lock for the whole call: no Python signal
handler and no other thread runs until it returns, so dense.interruptible cannot help, and a
SIGTERM waited up to 30 s. Here the call runs in a child process forked for it while this
process waits in steps of dense.WAIT_STEP_S, running a signal's handler and every poll
registered with dense.on_wait. Given up on (anything raised while waiting: outside a task
SIGTERM raises Interrupted at once), the child is killed before the exception goes on.

The child ignores SIGINT, SIGTERM and SIGUSR1 (this process answers them and ends the child)
and is killed when this process dies (Linux PR_SET_PDEATHSIG: a kill -9 of the run leaves no
factorisation running). Its result, or its exception, comes back pickled through a pipe: the
same bits as the call made here. `in_spawned` does the same through a new interpreter whose
environment has no MPI launcher variables (its PETSc starts MPI as a singleton, never as a rank
of the run) and whose BLAS has this process's thread limit; the call, its arguments and its
answer are pickled through the child's stdin and stdout. A leaf beside dense.py.
"""
from __future__ import annotations

import ctypes
import json
import multiprocessing
import os
import pickle
import select
import signal
import subprocess
import sys
import threading

from hpcwedge.dense import WAIT_STEP_S, run_polls

#: prctl option: the signal this process gets when its parent dies
_PR_SET_PDEATHSIG = 1


def can_fork() -> bool:
    """Whether `in_child` may fork here: POSIX, and neither MPI (mpi4py) nor PETSc started in
    this process (a child of an initialised MPI library may not use it: Open MPI's fork
    warning; PETSc starts MPI as a singleton)."""
    return (os.name == "posix" and "mpi4py.MPI" not in sys.modules
            and "petsc4py.PETSc" not in sys.modules)


def can_spawn() -> bool:
    """Whether `in_spawned` may start a child interpreter here (POSIX)."""
    return os.name == "posix"


def in_child(fn, *args, what: str = "a call", **kwargs):
    """fn(*args, **kwargs) in a forked child while this process waits (module doc); fn's
    exception is raised here. RuntimeError naming `what` if the child ends without an answer
    (killed, out of memory). Where the fork itself fails (OSError: no memory or process slot
    for it), the call runs here. Call only where `can_fork()`."""
    ctx = multiprocessing.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_child, args=(send, os.getpid(), fn, args, kwargs), daemon=True,
                        name="hpcwedge-forked")
    try:
        child.start()
    except OSError:                              # no fork to be had (memory, process limits)
        recv.close()
        send.close()
        return fn(*args, **kwargs)
    send.close()
    try:
        while not recv.poll(WAIT_STEP_S):
            run_polls()
        try:
            kind, value = pickle.loads(recv.recv_bytes())
        except EOFError:
            child.join()
            raise RuntimeError(f"{what}: its child process ended without an answer "
                               f"({_ended(child.exitcode)})") from None
    finally:
        if child.is_alive():
            child.kill()
        child.join()
        recv.close()
    if kind == "error":
        raise value
    return value


def _ended(code: int | None) -> str:
    """How a child ended, for the error line (a SIGKILL is most often the kernel's, out of memory)."""
    if code is not None and code < 0:
        name = signal.Signals(-code).name
        return f"killed by {name}" + (", as the kernel does when memory runs out" if name == "SIGKILL" else "")
    return f"exit status {code}"


def _child(send, parent: int, fn, args, kwargs) -> None:
    """The child's side of `in_child`: signals left to the parent, fn's value or exception sent."""
    _leave_signals_to(parent)
    send.send_bytes(_answer(lambda: fn(*args, **kwargs)))
    send.close()


def _leave_signals_to(parent: int) -> None:
    """In a child: ignore the run's signals (the parent answers them) and die with the parent
    (Linux PR_SET_PDEATHSIG; elsewhere the parent's kill only); exit at once if it is gone."""
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1):
        signal.signal(s, signal.SIG_IGN)
    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent:                   # the parent died before prctl took effect
        os._exit(1)


def _answer(call) -> bytes:
    """call()'s ("value", v) or ("error", exception), pickled; an exception or value pickle
    cannot take comes back as a RuntimeError line."""
    try:
        out = ("value", call())
    except BaseException as e:                   # noqa: BLE001  (handed to the parent)
        out = ("error", e)
    try:
        return pickle.dumps(out, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception as e:                       # noqa: BLE001
        return pickle.dumps(("error", RuntimeError(f"{type(out[1]).__name__}: {out[1]}" if out[0] == "error"
                                                   else f"the result could not be sent back: {e}")))


#: environment variables by which an MPI launcher (Open MPI, PMIx, MPICH/Hydra, Intel MPI)
#: tells a process it is a rank: not passed on to a spawned child
_LAUNCHER_PREFIXES = ("OMPI_", "PMIX_", "PMI_", "OPAL_", "ORTE_", "PRTE_", "HYDRA_", "I_MPI_", "MPIR_")
_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")
_BOOT = "import json, sys; sys.path[:0] = json.loads(sys.argv[1]); from hpcwedge.forked import _spawned; _spawned()"


def in_spawned(fn, *args, what: str = "a call", **kwargs):
    """fn(*args, **kwargs) in a new interpreter while this process waits (module doc); fn,
    its arguments and its answer must pickle (fn a module-level function). fn's exception is
    raised here; RuntimeError naming `what` if the child ends without an answer. Where the
    child cannot be started (OSError), the call runs here. Call only where `can_spawn()`."""
    payload = pickle.dumps((fn, args, kwargs), protocol=pickle.HIGHEST_PROTOCOL)
    try:
        child = subprocess.Popen([sys.executable, "-c", _BOOT, json.dumps(sys.path), str(os.getpid())],
                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=_child_environment(),
                                 close_fds=True)
    except OSError:                              # no process to be had (memory, process limits)
        return fn(*args, **kwargs)
    feeder = threading.Thread(target=_feed, args=(child.stdin, payload), daemon=True)
    feeder.start()
    chunks = []
    try:
        fd = child.stdout.fileno()
        while True:
            if not select.select([fd], [], [], WAIT_STEP_S)[0]:
                run_polls()
                continue
            chunk = os.read(fd, 1 << 20)
            if not chunk:
                break
            chunks.append(chunk)
        child.wait()
        try:
            kind, value = pickle.loads(b"".join(chunks))
        except Exception:                        # noqa: BLE001  (nothing, or a cut answer)
            raise RuntimeError(f"{what}: its child process ended without an answer "
                               f"({_ended(child.returncode)})") from None
    finally:
        if child.poll() is None:
            child.kill()
        child.wait()
        feeder.join()
        child.stdout.close()
    if kind == "error":
        raise value
    return value


def _child_environment() -> dict:
    """This process's environment without the MPI launcher's variables, with its BLAS threads."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(_LAUNCHER_PREFIXES)}
    threads = _blas_threads()
    if threads is not None:
        env.update(dict.fromkeys(_THREAD_VARIABLES, str(threads)))
    return env


def _blas_threads() -> int | None:
    """The fewest threads a BLAS / OpenMP library loaded here may use (threadpoolctl), or None."""
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return None
    counts = [lib["num_threads"] for lib in threadpool_info() if lib.get("num_threads")]
    return min(counts) if counts else None


def _feed(stream, payload: bytes) -> None:
    """Write the call to a spawned child's stdin (a thread: the child reads while it starts)."""
    try:
        stream.write(payload)
    except (BrokenPipeError, OSError, ValueError):   # the child died or was killed
        pass
    finally:
        try:
            stream.close()
        except (BrokenPipeError, OSError):
            pass


def _spawned() -> None:
    """The spawned child's side of `in_spawned`: signals left to the parent (argv[2]), the call
    read from stdin, its value or exception written to stdout (fd 1; anything a library prints
    goes to stderr instead)."""
    _leave_signals_to(int(sys.argv[2]))
    answer = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    data = _answer(lambda: _call(*pickle.load(sys.stdin.buffer)))
    answer.write(data)
    answer.flush()
    os._exit(0)


def _call(fn, args, kwargs):
    return fn(*args, **kwargs)
