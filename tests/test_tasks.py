"""The task registry and cancellation (hpcwedge.parallel.tasks): registered() restores
what was there, handlers are imported by name, run_cancellable's tick, and the module
(as every engine sees it) initialises no MPI."""
import subprocess
import sys

import pytest

from hpcwedge.parallel import tasks
from mpi_helpers import env


def test_registered_restores_the_previous_handler():
    before = tasks.handler_for("mu_c")
    with tasks.registered("mu_c", lambda ctx, p: "x"):
        assert tasks.handler_for("mu_c")(None, None) == "x"
    assert tasks.handler_for("mu_c") is before
    with tasks.registered("new-kind", lambda ctx, p: 1):
        assert tasks.handler_for("new-kind")(None, None) == 1
    with pytest.raises(KeyError, match="unknown task kind"):
        tasks.handler_for("new-kind")


def test_handlers_live_beside_their_engines():
    from hpcwedge.faces import face_task
    from hpcwedge.mu_critical import mu_c_task
    from hpcwedge.patterns import explore_task
    assert [tasks.handler_for(k) for k in ("subtree", "mu_c", "face")] == [explore_task, mu_c_task, face_task]


def test_run_cancellable_ticks_and_stops():
    seen = []

    def handler(ctx, payload):
        assert tasks.task_stopping() is False      # first look: check() says go on
        tasks.task_tick()
        return payload

    assert tasks.run_cancellable(handler, None, 7, lambda: seen.append(1) or False, tick_every_s=0.0) == 7
    assert seen and tasks.task_stopping() is False    # outside a task: never stopping
    with pytest.raises(tasks.TaskCancelled):
        tasks.run_cancellable(lambda ctx, p: tasks.task_tick(), None, None, lambda: True, tick_every_s=0.0)


def test_engines_import_no_mpi():
    code = ("import sys, hpcwedge.patterns, hpcwedge.mu_critical, hpcwedge.faces, hpcwedge.parallel.tasks; "
            "print('mpi4py' in sys.modules)")
    p = subprocess.run([sys.executable, "-c", code], env=env(), capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "False"
