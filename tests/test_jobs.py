"""The job scripts end to end: jobs/wedge.sbatch on a real one-node SLURM (tests/slurm.py)
and jobs/wedge-mpirun.sh, each compared with a direct run of the same scene.

What is asserted stays true whether `--resume` restarts from scratch or from a
checkpoint: the final result equals the direct run's, and the job really was
signalled, requeued and run again (SLURM's restart count, the log lines).
"""
import json
import math
import os
import signal
import subprocess
import sys
import time

import pytest
from slurm import LocalSlurm, SlurmUnavailable

pytestmark = [pytest.mark.slow, pytest.mark.mpi]

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
SBATCH = os.path.join(REPO, "jobs", "wedge.sbatch")
MPIRUN_SH = os.path.join(REPO, "jobs", "wedge-mpirun.sh")
MULTINODE = os.path.join(REPO, "jobs", "wedge-multinode.sbatch")

# Two ranks, a few seconds at most.
SMALL = """name = "plug2d-r3"
dim = 2
[model]
kind = "plug2d"
rows = 3
[friction]
mu = [0.65]
[compute]
enumerate = true
mu_c = "cones"
"""
# Long enough (10-40 s on 2 cores) to be signalled while it runs, with a small
# result, and all of it work that the engine distributes and checkpoints: the
# 3D sign-pattern tree of plug3d (m = 16) and the mu^c of its 697 patterns. (plug3d
# 2 x 7 took ~10 s until the kept Clarabel solvers made it 6 s, and a signal 2 s after
# the launch then reached a run that finished anyway.)
LONG = """name = "plug3d-2x8"
dim = 3
[model]
kind = "plug3d"
levels = 2
ring = 8
[friction]
mu = [1.0]
[compute]
enumerate = true
mu_c = "cones"
[run]
symmetry = false           # the long way round (~15 s serially), so that signals land mid-run
checkpoint_every_s = 2
"""


def py_env(**extra):
    env = dict(os.environ)
    env["PYTHONPATH"] = REPO + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.update(extra)
    return env


def job_env(**extra):
    """What the scripts need to find this checkout's code with this interpreter."""
    return {"HPCWEDGE_PYTHON": sys.executable, "HPCWEDGE_STOP_GRACE": "3", **extra}


def show(path):
    r = subprocess.run([sys.executable, "-m", "hpcwedge", "show", path, "--json"], env=py_env(),
                       check=True, capture_output=True, text=True)
    return json.loads(r.stdout)


def direct(scene_text, folder, name):
    scene = os.path.join(folder, name + ".toml")
    with open(scene, "w") as f:
        f.write(scene_text)
    out = os.path.join(folder, name + ".h5")
    subprocess.run([sys.executable, "-m", "hpcwedge", "run", scene, "-o", out, "-q"], env=py_env(), check=True)
    return scene, show(out)


def assert_same_result(got, want):
    """Equal except timings and solver counters; the global mu^c to 1e-9 (a parallel
    branch and bound may reach it through another sign pattern); 2D ray vectors bit
    for bit (the face split depends on the scene, not on the ranks)."""
    g = {k: v for k, v in got.items() if k not in ("timings", "stats")}
    w = {k: v for k, v in want.items() if k not in ("timings", "stats")}
    mg, mw = g.pop("mu_c"), w.pop("mu_c")
    assert (mg is None) == (mw is None)
    assert mg is None or math.isclose(mg, mw, rel_tol=1e-9)
    vg, vw = _pop_vectors(g), _pop_vectors(w)
    assert g == w
    assert vg == vw
    assert got["complete"] is True


def _pop_vectors(d):
    d["runs"] = [dict(run) for run in d["runs"]]
    return [[run.pop(k) or [] for k in ("rays", "trivial_rays")] for run in d["runs"]]


def read(path):
    try:
        with open(path) as f:
            return f.read()
    except FileNotFoundError:
        return ""


@pytest.fixture(scope="module")
def slurm(tmp_path_factory):
    cluster = LocalSlurm(str(tmp_path_factory.mktemp("slurm")))
    try:
        cluster.start()
    except SlurmUnavailable as e:
        pytest.skip(f"SLURM cannot run here: {e}")
    yield cluster
    cluster.stop()


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """The two scenes and their direct (one-process) results."""
    d = str(tmp_path_factory.mktemp("direct"))
    return {"small": direct(SMALL, d, "small"), "long": direct(LONG, d, "long")}


def submit(slurm, tmp_path, scene, result, options=(), **env):
    return slurm.sbatch(SBATCH, [scene, result], cwd=str(tmp_path), env=job_env(**env),
                        options=["-n", "2", "-t", "10", "-o", str(tmp_path / "job-%j.out"), *options])


def test_sbatch_matches_direct_run(slurm, scenes, tmp_path):
    scene, want = scenes["small"]
    t0 = time.monotonic()
    jid = submit(slurm, tmp_path, scene, "out/small.h5")
    info = slurm.wait_gone(jid, timeout=300)
    took = time.monotonic() - t0
    log = read(tmp_path / f"job-{jid}.out")
    assert info.get("JobState") == "COMPLETED" and info.get("ExitCode") == "0:0", log
    assert f"start: job {jid} SLURM_RESTART_COUNT=0 ntasks=2" in log
    assert f"hpcwedge {REPO}/hpcwedge/__init__.py" in log          # this checkout's code
    assert "mpirun -n 2 " in log and "--resume" in log and "done:" in log
    assert_same_result(show(str(tmp_path / "out" / "small.h5")), want)
    print(f"submit -> done: {took:.1f} s")

    # A rerun of a finished job (a dependency chain's later link) does nothing.
    jid2 = submit(slurm, tmp_path, scene, "out/small.h5")
    info = slurm.wait_gone(jid2, timeout=300)
    log2 = read(tmp_path / f"job-{jid2}.out")
    assert info.get("JobState") == "COMPLETED", log2
    assert "already complete" in log2 and "launch: " not in log2


def test_sbatch_with_srun_pmix(slurm, scenes, tmp_path):
    """HPCWEDGE_MPIRUN="srun --mpi=pmix": the ranks started by SLURM itself."""
    scene, want = scenes["small"]
    jid = submit(slurm, tmp_path, scene, "small.h5", HPCWEDGE_MPIRUN="srun --mpi=pmix")
    info = slurm.wait_gone(jid, timeout=300)
    log = read(tmp_path / f"job-{jid}.out")
    assert info.get("JobState") == "COMPLETED", log
    assert "launch: srun --mpi=pmix -n 2 " in log and "done:" in log
    assert_same_result(show(str(tmp_path / "small.h5")), want)


def wait_running(slurm, jid, logpath, timeout=120):
    """Until the job's log shows the launch, then a little longer so the ranks are at work."""
    slurm.wait_for(lambda: "launch: " in read(logpath), timeout, f"job {jid} to launch mpirun")
    time.sleep(2.0)
    log = read(logpath)
    if "done:" in log:
        pytest.fail("the scene finished before the signal: the test needs a longer scene\n" + log)


def test_warning_signal_requeues_and_resumes(slurm, scenes, tmp_path):
    scene, want = scenes["long"]
    jid = submit(slurm, tmp_path, scene, "long.h5", HPCWEDGE_STOP_GRACE="60")   # the master's own stop, exit 75
    logpath = tmp_path / f"job-{jid}.out"
    wait_running(slurm, jid, logpath)
    t_sig = time.monotonic()
    slurm.run("scancel", "-b", "-s", "USR1", jid)        # what --signal=B:USR1@N does near the limit
    slurm.wait_for(lambda: slurm.job(jid).get("Restarts", "0") != "0", 60, f"job {jid} to be requeued")
    t_requeued = time.monotonic()
    slurm.start_now(jid)                                   # instead of waiting for the next scheduling pass
    info = slurm.wait_gone(jid, timeout=300)
    t_done = time.monotonic()
    log = read(logpath)
    assert info.get("JobState") == "COMPLETED" and info.get("Restarts") == "1", log
    assert "signal USR1 received: stopping the run with a checkpoint" in log, log
    assert "SIGTERM to rank 0 (pid " in log and "run stopped (exit 75) after the time-limit warning" in log, log
    assert f"requeue: job {jid} goes back to the queue" in log, log
    assert log.count("start: job") == 2 and f"start: job {jid} SLURM_RESTART_COUNT=1" in log, log
    assert "done:" in log and log.index("SLURM_RESTART_COUNT=1") < log.index("done:"), log
    assert_same_result(show(str(tmp_path / "long.h5")), want)
    print(f"signal -> requeued: {t_requeued - t_sig:.1f} s, requeued -> done: {t_done - t_requeued:.1f} s")
    print(log)


def test_scancel_is_not_requeued(slurm, scenes, tmp_path):
    """A user's scancel (SIGTERM to the job) stops the run; the job does not come back."""
    scene, _ = scenes["long"]
    jid = submit(slurm, tmp_path, scene, "cancel.h5")
    logpath = tmp_path / f"job-{jid}.out"
    wait_running(slurm, jid, logpath)
    slurm.run("scancel", jid)
    info = slurm.wait_gone(jid, timeout=60)
    time.sleep(1.0)
    log = read(logpath)
    assert info.get("JobState") == "CANCELLED" and info.get("Restarts") == "0", log
    assert "signal TERM received" in log and "requeue:" not in log, log
    assert not os.path.exists(tmp_path / "cancel.h5")


def test_dependency_chain_without_requeue(slurm, scenes, tmp_path):
    """Sites that disable requeue: --no-requeue, and a second job after the first (afterany)."""
    scene, want = scenes["long"]
    first = submit(slurm, tmp_path, scene, "chain.h5", options=["--no-requeue"])
    second = submit(slurm, tmp_path, scene, "chain.h5", options=["--no-requeue", f"--dependency=afterany:{first}"])
    log1 = tmp_path / f"job-{first}.out"
    wait_running(slurm, first, log1)
    slurm.run("scancel", "-b", "-s", "USR1", first)
    info1 = slurm.wait_gone(first, timeout=120)
    assert info1.get("Restarts") == "0" and info1.get("ExitCode") == "75:0", read(log1)
    assert "not requeueing" in read(log1)
    info2 = slurm.wait_gone(second, timeout=300)
    log2 = read(tmp_path / f"job-{second}.out")
    assert info2.get("JobState") == "COMPLETED", log2
    assert "launch: " in log2 and "done:" in log2
    assert_same_result(show(str(tmp_path / "chain.h5")), want)


def test_multinode_script_requeues_and_resumes(slurm, scenes, tmp_path):
    """jobs/wedge-multinode.sbatch on the one local node with 4 tasks (the node's CPUs, more
    than the machine's 2 cores): at the warning SIGTERM to rank 0, the
    master checkpoints and exits 75, the job is requeued and the rerun resumes; the result
    is the direct run's."""
    scene, want = scenes["long"]
    jid = slurm.sbatch(MULTINODE, [scene, "multi.h5"], cwd=str(tmp_path), env=job_env(HPCWEDGE_STOP_GRACE="60"),
                       options=["-N", "1", "--ntasks-per-node", "4", "-t", "10",
                                "-o", str(tmp_path / "job-%j.out")])
    logpath = tmp_path / f"job-{jid}.out"
    wait_running(slurm, jid, logpath)
    slurm.run("scancel", "-b", "-s", "USR1", jid)
    try:            # 4 ranks on 2 cores beside the rest of the suite: minutes in the worst case
        slurm.wait_for(lambda: slurm.job(jid).get("Restarts", "0") != "0", 180, f"job {jid} to be requeued")
    except TimeoutError as e:
        pytest.fail(f"{e}\njob: {slurm.job(jid)}\nlog:\n{read(logpath)}")
    slurm.start_now(jid)
    info = slurm.wait_gone(jid, timeout=300)
    log = read(logpath)
    assert info.get("JobState") == "COMPLETED" and info.get("Restarts") == "1", log
    assert "[wedge-multinode] nodes " in log and "4 task(s) per node, 4 in all" in log, log
    assert "SIGTERM to rank 0 (pid " in log and "run stopped (exit 75) after the time-limit warning" in log, log
    assert "mpirun -n 4 " in log and f"start: job {jid} SLURM_RESTART_COUNT=1 ntasks=4" in log, log
    assert_same_result(show(str(tmp_path / "multi.h5")), want)


def test_multinode_script_checks_the_task_count(scenes, tmp_path):
    """Tasks per node x nodes must be SLURM_NTASKS (exit 2, one line), checked before any launch."""
    scene, _ = scenes["small"]
    bad = {"SLURM_JOB_ID": "1", "SLURM_NTASKS": "5", "SLURM_JOB_NUM_NODES": "2", "SLURM_NTASKS_PER_NODE": "3"}
    r = subprocess.run(["bash", MULTINODE, scene], capture_output=True, text=True, cwd=str(tmp_path),
                       env={**os.environ, **job_env(), **bad}, timeout=60)
    assert r.returncode == 2 and "SLURM_NTASKS=5 is not 2 node(s) x 3 task(s) per node" in r.stdout, r.stdout


def test_sbatch_bad_arguments(tmp_path):
    """Outside SLURM the script still checks its arguments (exit 2, one clear line)."""
    for args, msg in (([], "usage:"), ([str(tmp_path / "none.toml")], "not readable")):
        r = subprocess.run(["bash", SBATCH, *args], capture_output=True, text=True, cwd=str(tmp_path),
                           env={**os.environ, **job_env()})
        assert r.returncode == 2 and msg in r.stdout, r.stdout + r.stderr


def test_mpirun_script_matches_direct_run(scenes, tmp_path):
    scene, want = scenes["small"]
    r = subprocess.run([MPIRUN_SH, "-n", "2", scene, str(tmp_path / "r.h5")], capture_output=True,
                       text=True, env={**os.environ, **job_env()}, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "start: 2 rank(s)" in r.stderr and "--resume" in r.stderr and "done:" in r.stderr
    assert_same_result(show(str(tmp_path / "r.h5")), want)


def test_mpirun_script_forwards_sigint_then_resumes(scenes, tmp_path):
    scene, want = scenes["long"]
    out = str(tmp_path / "r.h5")
    errpath = tmp_path / "err.txt"
    with open(errpath, "w") as err:
        # a shell started in the background inherits SIGINT ignored, and bash cannot trap a
        # signal ignored on entry: give the script the terminal's default, as a user's has
        p = subprocess.Popen([MPIRUN_SH, "-n", "2", scene, out], stderr=err, stdout=subprocess.DEVNULL,
                             env={**os.environ, **job_env()},
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        t0 = time.monotonic()
        while "launch: " not in read(errpath):
            assert p.poll() is None and time.monotonic() - t0 < 120, read(errpath)
            time.sleep(0.1)
        time.sleep(2.0)
        assert "done:" not in read(errpath), "the scene finished before the signal"
        mpirun_pid = int(read(errpath).split("mpirun pid ")[1].split(")")[0])
        p.send_signal(signal.SIGINT)
        assert p.wait(timeout=60) == 75, read(errpath)         # the master's status, not mpirun's 1
    finally:
        if p.poll() is None:
            p.kill()
    log = read(errpath)
    assert "signal INT received: SIGTERM to the ranks of mpirun" in log, log
    assert "stopped by SIGINT, checkpoint written (exit 75)" in log, log
    with pytest.raises(ProcessLookupError):
        os.kill(mpirun_pid, 0)
    # The same command again finishes the job (from the checkpoint once there is one).
    r = subprocess.run([MPIRUN_SH, "-n", "2", scene, out], capture_output=True, text=True,
                       env={**os.environ, **job_env()}, timeout=600)
    assert r.returncode == 0, r.stderr
    assert_same_result(show(out), want)
