"""Cancellation (hpcwedge.parallel.cancel): run_cancellable's tick, and the module (as every
engine sees it) loads no MPI and no HDF5."""
import subprocess
import sys

import pytest
from mpi_helpers import env

from hpcwedge.parallel import cancel


def test_run_cancellable_ticks_and_stops():
    seen = []

    def handler(ctx, payload):
        assert cancel.task_stopping() is False      # first look: check() says go on
        cancel.task_tick()
        return payload

    assert cancel.run_cancellable(handler, None, 7, lambda: seen.append(1) or False, tick_every_s=0.0) == 7
    assert seen and cancel.task_stopping() is False    # outside a task: never stopping
    with pytest.raises(cancel.TaskCancelled):
        cancel.run_cancellable(lambda ctx, p: cancel.task_tick(), None, None, lambda: True, tick_every_s=0.0)


def test_engines_import_no_mpi_and_no_hdf5():
    code = ("import sys, hpcwedge.patterns.tree, hpcwedge.mu_c.critical, hpcwedge.rays.faces, "
            "hpcwedge.parallel.cancel; print('mpi4py' in sys.modules, 'h5py' in sys.modules)")
    p = subprocess.run([sys.executable, "-c", code], env=env(), capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "False False"


def test_task_scopes_wrap_every_task(monkeypatch):
    """A registered scope is entered before the handler and left after it, also when the
    task is cancelled; registering it twice enters it once."""
    import contextlib
    monkeypatch.setattr(cancel, "_scopes", [])
    seen = []

    @contextlib.contextmanager
    def scope():
        seen.append("in")
        try:
            yield
        finally:
            seen.append("out")

    cancel.task_scope(scope)
    cancel.task_scope(scope)
    assert cancel.run_cancellable(lambda ctx, p: seen.append(p) or p, None, 3, lambda: False) == 3
    assert seen == ["in", 3, "out"]
    with pytest.raises(cancel.TaskCancelled):
        cancel.run_cancellable(lambda ctx, p: cancel.task_tick(), None, None, lambda: True, tick_every_s=0.0)
    assert seen[3:] == ["in", "out"]
def test_task_pausing_after_its_period_or_at_a_stop():
    """task_pausing(): False outside a task and before pause_every_s; True once that has
    passed (the engine saying go on), and at once when the engine stops."""
    import time

    def paused_at(ctx, payload):
        assert cancel.task_pausing() is False
        while not cancel.task_pausing():
            time.sleep(0.001)
        return time.monotonic()

    assert cancel.task_pausing() is False
    t0 = time.monotonic()               # before the task is handed out: its period counts from then on
    assert 0.05 <= cancel.run_cancellable(paused_at, None, None, lambda: False, 0.0, pause_every_s=0.05) - t0 < 1.0
    assert cancel.run_cancellable(lambda ctx, p: cancel.task_pausing(), None, None, lambda: True, 0.0) is True
    assert cancel.task_pausing() is False



def test_a_long_dense_call_is_cancelled_within_a_step():
    """dense.interruptible polls task_tick (registered by this module): inside a task whose
    check turns True, a call that would block for 60 s (time.sleep releases the GIL as numpy's
    LAPACK does) is given up on with TaskCancelled within a few wait steps."""
    import time

    from hpcwedge import dense
    start = time.monotonic()
    with pytest.raises(cancel.TaskCancelled):
        cancel.run_cancellable(lambda ctx, p: dense.interruptible(time.sleep, 60.0), None, None,
                               lambda: time.monotonic() - start > 0.2, tick_every_s=0.0)
    assert time.monotonic() - start < 5.0
