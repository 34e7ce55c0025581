"""MPI plumbing (hpcwedge/parallel/mpi.py) under the real mpirun: idle ranks sleep (CPU time
from /proc), a launch that does not match SLURM's task count is one clear error."""
import json
import os
import subprocess
import sys

import pytest
from mpi_helpers import MPIRUN, ROOT, env, needs_mpirun, write_scene


@pytest.mark.mpi
@needs_mpirun
def test_idle_ranks_do_not_spin():
    """CPU time from /proc/PID/stat over 2 s in which (A) the master computes and
    no worker has a task, (B) one worker runs the only task. Control (C): a
    worker in a plain blocking comm.recv burns CPU, so the measure sees spinning."""
    period = 2.0
    p = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "3", "-x", "PYTHONPATH",
                        sys.executable, os.path.join(ROOT, "tests", "engine_driver.py"), str(period)],
                       env=env(), capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    got = json.loads(p.stdout.strip().splitlines()[-1])
    a, b, c = got["master_busy"], got["one_task"], got["blocking_recv"]
    print(json.dumps(got))
    idle = [a["cpu"][1], a["cpu"][2], b["cpu"][2]]
    assert max(idle) <= 0.03 * period, got            # idle workers: < 3% of a core
    assert b["cpu"][0] <= 0.05 * period, got          # the waiting master: < 5%
    assert min(c["cpu"][1:]) >= 0.1 * c["seconds"], got   # control: a blocking recv spins


@pytest.mark.mpi
@needs_mpirun
def test_slurm_ntasks_mismatch_fails_clearly(tmp_path):
    scene = write_scene(tmp_path)
    out = tmp_path / "r.h5"
    e = env()
    e["SLURM_NTASKS"] = "3"
    p = subprocess.run([sys.executable, "-m", "hpcwedge", "run", scene, "-o", str(out)], env=e,
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    assert "SLURM_NTASKS=3" in p.stderr and "srun" in p.stderr and len(p.stderr.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.mpi
@needs_mpirun
def test_a_large_task_message_does_not_wait_for_its_worker():
    """The master's send of a task with a 4 MB context to a worker that reads it only after
    2 s returns at once (an Open MPI blocking send of that size waits for the receive: ~2 s),
    and the answer still arrives."""
    p = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "2", "-x", "PYTHONPATH",
                        sys.executable, os.path.join(ROOT, "tests", "engine_driver.py"), "send"],
                       env=env(), capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    got = json.loads(p.stdout.strip().splitlines()[-1])
    assert got["answer"] == [2, 4 << 20], got          # mpi.RESULT, the context's length
    assert got["send_s"] < 0.5, got
    assert got["answer_s"] >= 1.5, got                  # the worker did start late


def test_sends_keep_the_incomplete_requests_at_amortised_cost():
    """mpi.Sends: a request is dropped only once its Test() is true; with every request
    incomplete (workers not yet receiving) the tests per add stay bounded (the mark doubles),
    and complete() drops those finished since."""
    from hpcwedge.parallel.mpi import Sends

    class Request:                      # the one method Sends uses of an mpi4py Request
        tests = 0

        def __init__(self):
            self.done = False

        def Test(self):
            Request.tests += 1
            return self.done

    sends = Sends(workers=4)
    made = [Request() for _ in range(1000)]
    for r in made:
        sends.add(r)
    assert sends.requests == made and Request.tests <= 4 * len(made), Request.tests
    for r in made[::2]:
        r.done = True
    sends.complete()
    assert sends.requests == made[1::2]
    for r in made:
        r.done = True
    sends.complete(timeout=1.0)
    assert sends.requests == []
