"""A long call that keeps the interpreter's lock, run in a forked child process so that a
signal is served within a step (`in_child`, `can_fork`).

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
same bits as the call made here. A leaf beside dense.py.
"""
from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys

from hpcwedge.dense import WAIT_STEP_S, run_polls

#: prctl option: the signal this process gets when its parent dies
_PR_SET_PDEATHSIG = 1


def can_fork() -> bool:
    """Whether `in_child` may fork here: POSIX, and neither MPI (mpi4py) nor PETSc started in
    this process (a child of an initialised MPI library may not use it: Open MPI's fork
    warning; PETSc starts MPI as a singleton)."""
    return (os.name == "posix" and "mpi4py.MPI" not in sys.modules
            and "petsc4py.PETSc" not in sys.modules)


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
            kind, value = recv.recv()
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
    if code is not None and code < 0:
        return f"killed by {signal.Signals(-code).name}"
    return f"exit status {code}"


def _child(send, parent: int, fn, args, kwargs) -> None:
    """The child's side of `in_child`: signals left to the parent, fn's value or exception sent."""
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1):
        signal.signal(s, signal.SIG_IGN)
    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):            # not Linux: the parent's kill in in_child only
        pass
    if os.getppid() != parent:                   # the parent died before prctl took effect
        os._exit(1)
    try:
        out = ("value", fn(*args, **kwargs))
    except BaseException as e:                   # noqa: BLE001  (handed to the parent)
        out = ("error", e)
    try:
        send.send(out)
    except Exception as e:                       # noqa: BLE001  (an exception pickle cannot take)
        send.send(("error", RuntimeError(f"{type(out[1]).__name__}: {out[1]}" if out[0] == "error"
                                         else f"the result could not be sent back: {e}")))
    send.close()
