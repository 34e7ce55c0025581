"""hpcwedge.forked: a long call in a forked child while the caller waits in steps, serving
signals; what the child returns or raises comes back; a child given up on is killed."""
import multiprocessing
import os
import signal
import sys
import time

import numpy as np
import pytest
from mpi_helpers import all_gone, alive, children, python_child, stopped_by_sigterm

from hpcwedge import dense, forked


def test_in_child_returns_and_raises_what_fn_does():
    a = np.random.default_rng(0).standard_normal((50, 40))
    out = forked.in_child(np.multiply, a, 3.0)
    assert out.tobytes() == np.multiply(a, 3.0).tobytes()
    with pytest.raises(ZeroDivisionError):
        forked.in_child(divmod, 1, 0)
    with pytest.raises(ValueError, match="^condense: a bad K$"):
        forked.in_child(_raise, ValueError("condense: a bad K"))


def _raise(e):
    raise e


def _kill_self():
    os.kill(os.getpid(), signal.SIGKILL)


class _Unpicklable(Exception):
    def __reduce__(self):
        raise TypeError("no pickling")


def test_an_exception_pickle_cannot_take_comes_back_as_a_runtime_error_naming_it():
    with pytest.raises(RuntimeError, match="^_Unpicklable: lost$"):
        forked.in_child(_raise, _Unpicklable("lost"))


def test_a_child_that_dies_is_one_runtime_error():
    with pytest.raises(RuntimeError, match=r"^condense: its child process ended without an answer "
                       r"\(killed by SIGKILL, as the kernel does when memory runs out\)$"):
        forked.in_child(_kill_self, what="condense")
    with pytest.raises(RuntimeError, match=r"\(exit status 3\)$"):
        forked.in_child(os._exit, 3)


@pytest.mark.parametrize("call", ["in_child", "in_spawned"])
def test_a_poll_that_raises_gives_the_call_up_and_kills_the_child(monkeypatch, call):
    """The registered polls run every step (the engine's task_tick); one that raises ends the
    wait within a step or two and leaves no child behind."""
    t0 = time.monotonic()

    def poll():
        if time.monotonic() - t0 > 0.5:
            raise KeyboardInterrupt
    monkeypatch.setattr(dense, "_polls", [poll])
    before = set(children(os.getpid()))     # the suite's own (an MPI singleton's helper, ...)
    with pytest.raises(KeyboardInterrupt):
        getattr(forked, call)(time.sleep, 60.0)
    assert time.monotonic() - t0 < 5.0
    assert set(children(os.getpid())) <= before


def test_no_fork_once_mpi_or_petsc_is_started(monkeypatch):
    assert forked.can_fork() == ("mpi4py.MPI" not in sys.modules and "petsc4py.PETSc" not in sys.modules)
    for name in ("mpi4py.MPI", "petsc4py.PETSc"):
        with monkeypatch.context() as mp:
            mp.setitem(sys.modules, name, object())
            assert not forked.can_fork()


def test_a_fork_that_fails_runs_the_call_here(monkeypatch):
    """No memory or process slot for the child (fork's OSError): the call runs in this process."""
    def no_fork(self):
        raise OSError(12, "Cannot allocate memory")
    monkeypatch.setattr(multiprocessing.get_context("fork").Process, "start", no_fork)
    assert forked.in_child(os.getpid) == os.getpid()


def test_the_child_ignores_the_runs_signals_and_dies_with_its_parent():
    """SIGTERM to the child's process group (SLURM signals every process of a step) is the
    parent's to answer; a kill -9 of the parent takes the child with it (PR_SET_PDEATHSIG)."""
    code = ("import os, time\n"
            "from hpcwedge import forked\n"
            "def work():\n"
            "    print('child', os.getpid(), flush=True)\n"
            "    time.sleep(60)\n"
            "forked.in_child(work)\n")
    p = python_child(code)
    try:
        child = int(p.stdout.readline().split()[1])
        os.kill(child, signal.SIGTERM)
        os.kill(child, signal.SIGUSR1)
        time.sleep(0.3)
        assert alive(child)
        p.kill()
        p.wait()
        assert all_gone([child])
    finally:
        p.kill()
        p.wait()


@pytest.mark.parametrize("call", ["in_child", "in_spawned"])
def test_a_signal_is_served_while_the_child_works(call):
    """The caller's SIGTERM handler (outside a task the engine's raises at once) runs within a
    step although the child computes for a minute; the child ignores a SIGTERM of its own (the
    caller answers) and is gone after."""
    p = python_child(stopped_by_sigterm("import time\nfrom hpcwedge import forked", f"forked.{call}(time.sleep, 60.0)"))
    try:
        assert p.stdout.readline().strip() == "ready"
        deadline = time.monotonic() + 30
        while not children(p.pid) and time.monotonic() < deadline:
            time.sleep(0.02)
        kids = children(p.pid)
        assert len(kids) == 1
        time.sleep(0.5)
        os.kill(kids[0], signal.SIGTERM)
        start = time.monotonic()
        p.send_signal(signal.SIGTERM)
        assert p.wait(timeout=30) == 75
        assert time.monotonic() - start < 2.0
        assert all_gone(kids)
    finally:
        p.kill()
        p.wait()


# in_spawned: the same contract through a fresh interpreter (the master of an MPI run)

def test_in_spawned_returns_and_raises_what_fn_does():
    a = np.random.default_rng(1).standard_normal((300, 200))
    assert forked.in_spawned(np.multiply, a, 3.0).tobytes() == np.multiply(a, 3.0).tobytes()
    assert forked.in_spawned(os.getppid) == os.getpid()
    with pytest.raises(ZeroDivisionError):
        forked.in_spawned(divmod, 1, 0)
    with pytest.raises(RuntimeError, match="^_Unpicklable: lost$"):
        forked.in_spawned(_raise_unpicklable)
    with pytest.raises(RuntimeError, match=r"^condense: its child process ended without an answer \(exit status 3\)$"):
        forked.in_spawned(os._exit, 3, what="condense")


def test_a_spawned_child_is_no_rank_and_has_this_processs_blas_threads(monkeypatch):
    """The MPI launcher's variables stay behind (the child's PETSc must not join the run's MPI
    job); the BLAS thread variables carry this process's limit (threadpoolctl), so the child
    computes the same bits."""
    from threadpoolctl import threadpool_limits
    monkeypatch.setenv("OMPI_COMM_WORLD_RANK", "0")
    monkeypatch.setenv("PMIX_RANK", "0")
    monkeypatch.setenv("HPCWEDGE_KEEP", "yes")
    with threadpool_limits(limits=1):
        got = forked.in_spawned(_getenvs, ["OMPI_COMM_WORLD_RANK", "PMIX_RANK", "HPCWEDGE_KEEP",
                                           "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"])
    assert got == [None, None, "yes", "1", "1"]


def _raise_unpicklable():
    raise _Unpicklable("lost")


def _getenvs(names):
    return [os.environ.get(n) for n in names]
