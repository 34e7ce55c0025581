"""The worker loop (hpcwedge/parallel/worker.py) under the real mpirun: workers drop their
tasks at the master's stop."""
import json
import os
import subprocess
import sys
import time

import pytest
from mpi_helpers import MPIRUN, ROOT, env, needs_mpirun


@pytest.mark.mpi
@needs_mpirun
def test_sigterm_cancels_long_tasks():
    """SIGTERM to the master while every worker is in a 60 s task that calls
    task_tick(): the workers drop their tasks at the master's stop, close()
    returns within seconds, and the whole job ends long before the tasks would."""
    t = time.monotonic()
    p = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "3", "-x", "PYTHONPATH",
                        sys.executable, os.path.join(ROOT, "tests", "engine_driver.py"), "cancel"],
                       env=env(), capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    got = json.loads(p.stdout.strip().splitlines()[-1])
    assert got["interrupted"] is not None and got["interrupted"] < 10, got
    assert got["closed"] - got["interrupted"] < 5, got
    assert time.monotonic() - t < 40, got


@pytest.mark.mpi
@needs_mpirun
def test_stop_checkpoint_does_not_wait_for_a_task_that_never_ticks(tmp_path):
    """SIGTERM to the master while every worker is in an 8 s task that never calls task_tick():
    the checkpoint (the tasks as open) is on disk within seconds, before the master waits for
    the tasks (mpirun's SIGKILL follows its SIGTERM within ~2 s; before: written only once the
    tasks ended, 8 s later)."""
    from hpcwedge.parallel.checkpoint import read_checkpoint
    path = str(tmp_path / "c.ckpt")
    p = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "3", "-x", "PYTHONPATH",
                        sys.executable, os.path.join(ROOT, "tests", "engine_driver.py"), "stuck", path],
                       env=env(), capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    got = json.loads(p.stdout.strip().splitlines()[-1])
    assert got["checkpoint_at"] is not None and got["checkpoint_at"] < 5, got
    assert got["interrupted"] is not None
    assert read_checkpoint(path) is not None


@pytest.mark.mpi
@needs_mpirun
def test_a_worker_error_names_its_exception_on_the_first_line():
    """A worker's task raises: the master's error names the worker's exception on its first
    line, the only line the command line prints (before: 'worker rank 1 failed on a
    'boom' task:' and nothing of the cause)."""
    p = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "2", "-x", "PYTHONPATH",
                        sys.executable, os.path.join(ROOT, "tests", "engine_driver.py"), "boom"],
                       env=env(), capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    got = json.loads(p.stdout.strip().splitlines()[-1])
    assert got["first_line"] == "worker rank 1 failed on a 'boom' task: ValueError: injected fault"
