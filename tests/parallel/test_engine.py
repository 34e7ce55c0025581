"""The master/worker engine (hpcwedge/parallel/engine.py): a signal in the middle of a job
checkpoints and resumes in-process; a task's error reaches the caller; under the real
mpirun with 1-4 ranks the serial answers (bit for bit: tests/test_determinism.py), exact
rays split over faces included; a bad scene under mpirun is one error, no hang. The
engine's jobs: test_parallel_jobs.py; its tasks beside their engines (test_patterns,
test_faces, test_mu_critical); MPI plumbing and the worker loop: test_mpi, test_worker."""
import os
import signal

import pytest
from instances import tree_factory
from mpi_helpers import THREADS_1, THREADS_2, THREADS_UNSET, answers, needs_mpirun, run, show, show_json, write_scene

from hpcwedge.errors import Interrupted
from hpcwedge.parallel.checkpoint import CheckpointError
from hpcwedge.parallel.engine import Engine, run_tasks
from hpcwedge.patterns import job as job_module
from hpcwedge.patterns.job import run_patterns
from hpcwedge.patterns.tree import explore_task

# ---------------------------------------------------------------- in-process


def _signalling_task(calls: list, at: int, sig):
    """A subtree task that counts its calls in `calls` and sends `sig` to this process on
    call number `at` (a real signal in the middle of a job)."""
    def task(ctx, payload):
        calls.append(1)
        if len(calls) == at:
            os.kill(os.getpid(), sig)
        return explore_task(ctx, payload)
    return task


def _checkpointing_engine(ckpt: str) -> Engine:
    """An in-process engine writing checkpoints to `ckpt` (a fresh start), its signal
    handlers installed."""
    eng = Engine()
    eng.use_checkpoint(ckpt, "hash", "scene", 1000.0, resume=False)
    eng.install_signals()
    return eng


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGUSR1])
def test_engine_signal_checkpoint_resume_in_process(tmp_path, sig):
    """A signal in the middle of a job (sent by a task to its own process):
    SIGTERM -> Interrupted at the next safe point, checkpoint, a new engine
    resumes; SIGUSR1 -> a checkpoint and the job goes on. Same patterns, every
    tree node counted once."""
    make, _ = tree_factory(41, m=6)
    mus = [1.0, 4.0]
    ref = run_patterns(make, mus, budget=2)
    ckpt = str(tmp_path / "x.ckpt")
    calls = []
    task = _signalling_task(calls, 5, sig)
    eng = _checkpointing_engine(ckpt)
    try:
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(job_module, "explore_task", task)
            if sig == signal.SIGTERM:
                with pytest.raises(Interrupted):
                    run_patterns(make, mus, engine=eng, budget=2)
                assert eng.write_checkpoint("SIGTERM")
            else:
                out = run_patterns(make, mus, engine=eng, budget=2)
                assert eng.checkpoints_written == 1 and eng.checkpoint_reason == "SIGUSR1"
    finally:
        eng.close()
    if sig == signal.SIGTERM:
        assert len(calls) == 5                          # stopped at the safe point after the 5th task
        eng = Engine()
        assert eng.use_checkpoint(ckpt, "hash", "scene", 1000.0, resume=True)
        out = run_patterns(make, mus, engine=eng, budget=2)
        with pytest.raises(CheckpointError, match="another scene"):
            Engine().use_checkpoint(ckpt, "other", "scene", 1000.0, resume=True)
    assert out.found == ref.found and out.counters["nodes"] == ref.counters["nodes"]


def test_a_jobs_seconds_add_up_over_its_sessions_in_the_checkpoint(tmp_path):
    """A tree job whose tasks take at least 0.05 s each, stopped by SIGTERM at its 5th task and,
    resumed, at its 3rd: each checkpoint holds the job's seconds of all its sessions
    (attrs job_elapsed_s: at least 5, then 5 + 3 tasks' sleep, the second more than the first),
    which the resumed engine's time left counts from (progress.ShareClock.resumed); the last
    session ends with the uninterrupted answer."""
    import time

    from hpcwedge.parallel.checkpoint import read_checkpoint
    make, _ = tree_factory(41, m=6)
    mus = [1.0, 4.0]
    ref = run_patterns(make, mus, budget=2)
    ckpt = str(tmp_path / "x.ckpt")
    seconds = []
    for at in (5, 3):
        calls = []
        task = _signalling_task(calls, at, signal.SIGTERM)
        def slow(ctx, payload, task=task):
            time.sleep(0.05)
            return task(ctx, payload)
        eng = Engine()
        eng.use_checkpoint(ckpt, "hash", "scene", 1000.0, resume=bool(seconds))
        eng.install_signals()
        try:
            with pytest.MonkeyPatch.context() as mp:
                mp.setattr(job_module, "explore_task", slow)
                with pytest.raises(Interrupted):
                    run_patterns(make, mus, engine=eng, budget=2)
            assert eng.write_checkpoint("SIGTERM")
        finally:
            eng.close()
        seconds.append(float(read_checkpoint(ckpt)["jobs"]["patterns"]["attrs"]["job_elapsed_s"]))
    assert seconds[0] >= 5 * 0.05 and seconds[1] >= seconds[0] + 3 * 0.05
    eng = Engine()
    assert eng.use_checkpoint(ckpt, "hash", "scene", 1000.0, resume=True)
    out = run_patterns(make, mus, engine=eng, budget=2)
    assert out.found == ref.found and out.counters["nodes"] == ref.counters["nodes"]


def test_second_stop_signal_does_not_interrupt_the_stop_checkpoint(tmp_path):
    """SLURM's SIGTERM, then mpirun's forwarded one about a second later: the first stops the
    job (Interrupted), the second arrives while the stop checkpoint is written and must
    not interrupt it (before: a second Interrupted out of the write, an internal error
    with exit 1, the stop checkpoint lost). Real signals to this process."""
    make, _ = tree_factory(41, m=6)
    ckpt = str(tmp_path / "x.ckpt")
    task = _signalling_task([], 3, signal.SIGTERM)
    eng = _checkpointing_engine(ckpt)
    try:
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(job_module, "explore_task", task)
            with pytest.raises(Interrupted):
                run_patterns(make, [1.0, 4.0], engine=eng, budget=2)
        os.kill(os.getpid(), signal.SIGTERM)            # the second one, outside every job
        assert eng.write_checkpoint("SIGTERM")
    finally:
        eng.close()
    assert Engine().use_checkpoint(ckpt, "hash", "scene", 1000.0, resume=True)


def test_stop_signal_while_a_checkpoint_is_read_keeps_its_work(tmp_path):
    """A SIGTERM while --resume reads a large checkpoint (a real signal, sent by a thread
    once the file is open): Interrupted once it is loaded, and the stop checkpoint holds
    the loaded work (before: an empty checkpoint written over it, or the good one refused
    as 'truncated or corrupt')."""
    import threading
    import time

    import numpy as np

    from hpcwedge.parallel.checkpoint import read_checkpoint, write_checkpoint
    ckpt = str(tmp_path / "big.ckpt")
    data = np.random.default_rng(7).random(4_000_000)          # 32 MB: read for a while
    header = {"scene_hash": "hash", "inputs": "{}", "elapsed_s": 12.5, "resumes": 0, "ranks": 1,
              "reason": "timer"}
    write_checkpoint(ckpt, header, "scene", [("rays", {"attrs": {"kind": "face", "finished": True,
                                                                 "counters": "{}"}, "data": {"x": data}})])

    def signal_when_open():
        end = time.monotonic() + 30
        while time.monotonic() < end:
            for fd in os.listdir("/proc/self/fd"):
                try:
                    if os.readlink(f"/proc/self/fd/{fd}") == ckpt:
                        os.kill(os.getpid(), signal.SIGTERM)
                        return
                except OSError:
                    pass
            time.sleep(0.0005)

    eng = Engine()
    eng.install_signals()
    sender = threading.Thread(target=signal_when_open)
    sender.start()
    try:
        with pytest.raises(Interrupted):
            eng.use_checkpoint(ckpt, "hash", "scene", 1000.0, resume=True)
            time.sleep(5)                   # not reached when the signal came during the read
        sender.join()
        assert eng.write_checkpoint("SIGTERM")
    finally:
        eng.close()
    back = read_checkpoint(ckpt)
    assert np.array_equal(back["jobs"]["rays"]["data"]["x"], data)
    assert back["attrs"]["elapsed_s"] >= 12.5 and back["attrs"]["reason"] == "SIGTERM"


def test_worker_error_in_serial_mode_propagates():
    with pytest.raises(ZeroDivisionError):
        run_tasks(_boom, None, [1])


def _boom(ctx, payload):
    return 1 / 0


# ---------------------------------------------------------------- the real mpirun


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The uninterrupted serial run of the pattern scene, its caller asking for 2 BLAS
    threads: (scene path, show JSON)."""
    tmp = tmp_path_factory.mktemp("ref")
    scene = write_scene(tmp, raw=False)     # plug2d: condensation (PETSc) under mpirun too
    out = str(tmp / "ref.h5")
    run(None, "run", scene, "-o", out, "-q", caller=THREADS_2)
    return scene, show(out)


@pytest.mark.mpi
@needs_mpirun
@pytest.mark.parametrize("ranks", [((1, THREADS_1), (2, THREADS_UNSET)), ((3, THREADS_2), (4, THREADS_UNSET))])
def test_same_result_for_1_to_4_ranks(tmp_path, reference, ranks):
    """The pattern scene on 1-4 ranks, whatever BLAS threads the caller asks for: the
    serial run's answers (mu^c and stats.environment included)."""
    scene, want = reference
    for n, threads in ranks:
        out = str(tmp_path / f"r{n}.h5")
        p = run(n, "run", scene, "-o", out, caller=threads)
        assert p.stdout == ""                                  # nobody prints on stdout
        assert p.stderr.count("wrote") == 1                    # only the master reports
        got = show_json(out)
        assert answers(got) == want, f"{n} ranks"
        st = got["stats"]["parallel"]
        jobs = st["jobs"]
        assert st["ranks"] == n and jobs["patterns"]["nodes"] == want["stats"]["bnb"]["nodes"]
        assert jobs["patterns"]["handed_back"] > 0 and jobs["patterns"]["tasks"] > 10
        assert not os.path.exists(out + ".ckpt")
        if n >= 3:
            assert all(t > 0 for t in st["tasks_per_rank"][1:])   # work reached every worker
            assert st["tasks_per_rank"][0] == 0                   # the master only dispatches


#: rank 0 runs a TreeJob over the full binary tree of depth 12 (budget 1: a task visits one
#: node and hands back its two children) and prints what it found and the messages it sent;
#: MESSAGE_S 50 ms: batches of its tasks, however long a round trip takes on a loaded machine
TREE_UNDER_MPIRUN = """
import json
from hpcwedge.parallel import schedule, mpi
from hpcwedge.parallel.engine import Engine
from hpcwedge.parallel.jobs import TreeJob
from hpcwedge.parallel.worker import serve

class Node(tuple):
    depth = property(len)

def explore(depth, payload):
    _, node, budget, _ = payload
    stack, found, visited = [node], [], 0
    while stack and visited < budget:
        n = stack.pop()
        visited += 1
        if len(n) == depth:
            found.append(n)
        else:
            stack += [Node(n + (1,)), Node(n + (0,))]
    return found, stack, {"nodes": visited}, [], [None] * len(stack)

schedule.MESSAGE_S = 0.05
comm = mpi.world()
if comm.rank:
    serve(comm)
else:
    engine, sent = Engine(comm), []
    send = engine.master.send_task
    engine.master.send_task = lambda *a, **k: (sent.append(k.get("batched", False)), send(*a, **k))
    job = engine.run(TreeJob("t", explore, 12, [Node(())], 1, {"nodes": 0}))
    engine.close()
    print(json.dumps({"found": sorted(map(list, job.found[0])), "counters": job.counters,
                      "batches": sum(sent), "messages": len(sent)}))
"""


@pytest.mark.mpi
@needs_mpirun
def test_a_tree_job_of_short_tasks_travels_in_batches_with_the_same_answer(tmp_path):
    """mpirun -n 3, a tree job whose tasks take well under MESSAGE_S: its tasks go out in
    batches (engine.batch_size), and the job still finds each of the 4,096 leaves once and
    counts the tree's 8,191 nodes; every node handed back became one task (tasks and
    handed_back depend on the split: the budget grows while the pool is long)."""
    import json
    import subprocess
    import sys

    from mpi_helpers import MPIRUN, env
    p = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "3", "-x", "PYTHONPATH",
                        sys.executable, "-c", TREE_UNDER_MPIRUN], env=env(), capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 0, p.stderr
    got = json.loads(p.stdout)
    assert got["found"] == [[(k >> i) & 1 for i in reversed(range(12))] for k in range(4096)]
    c = got["counters"]
    assert c["nodes"] == 8191 and c["tasks"] == 1 + c["handed_back"]
    assert got["batches"] > 0 and got["messages"] < c["tasks"]


@pytest.mark.mpi
@needs_mpirun
def test_2d_exact_rays_identical_under_mpirun(tmp_path):
    """Exact arithmetic: a ray is a primitive integer vector, whatever the DD's path,
    so the face split (8 faces) under mpirun gives the unsplit serial answers bit for
    bit, ray vectors included (the exact rays travel and are checkpointed as decimal
    strings)."""
    text = ('name = "plug6-exact"\ndim = 2\n[model]\nkind = "plug2d"\nrows = 3\n[friction]\n'
            'mu = [0.65, 1.0]\n[compute]\nenumerate = true\nmu_c = "cones"\nexact = true\n[run]\nface_split = {}\n')
    whole, split = tmp_path / "whole.toml", tmp_path / "split.toml"
    whole.write_text(text.format(0))
    split.write_text(text.format(3))
    want = str(tmp_path / "s.h5")
    run(None, "run", str(whole), "-o", want, "-q")
    got = str(tmp_path / "p.h5")
    run(3, "run", str(split), "-o", got, "-q")
    a, b = show_json(got), show_json(want)
    assert a["stats"]["dd"][0]["faces"] == 8 and b["stats"]["dd"][0]["faces"] == 1
    a, b = answers(a), answers(b)
    for d in (a, b):
        d["stats"].pop("dd")
        d.pop("scene_hash")
    assert a == b and a["runs"][0]["n_wedged_rays"] == 44


@pytest.mark.mpi
@needs_mpirun
def test_bad_scene_under_mpirun_exit_2_once(tmp_path):
    """Input errors under mpirun: one message (from the master), status 2, nothing
    written, the workers stopped (no hang)."""
    bad = write_scene(tmp_path, name="bad.toml",
                      text='name = "x"\ndim = 2\n[model]\nkind = "plug2d"\n[friction]\nmu = [-1.0]\n')
    out = tmp_path / "r.h5"
    p = run(3, "run", bad, "-o", str(out), timeout=60, check=False)
    assert p.returncode == 2
    assert p.stderr.count("hpcwedge: error: friction.mu") == 1 and p.stdout == ""
    assert not out.exists() and not os.path.exists(str(out) + ".ckpt")


def test_progress_lines_count_patterns_and_tree_nodes():
    """With a progress callback, a line after every merge (progress_every_s = 0) says how many
    patterns and tree nodes the subtree job has so far: non-decreasing, and the last line
    gives the job's final counts."""
    import io
    import re

    from hpcwedge.progress import Progress
    make, _ = tree_factory(41, m=6)
    buf = io.StringIO()
    eng = Engine(progress=Progress(stream=buf), progress_every_s=0.0)
    out = run_patterns(make, [1.0, 4.0], engine=eng, budget=2)
    counts = [tuple(map(int, re.search(r"(\d+) patterns found, (\d+) tree nodes", line).groups()))
              for line in buf.getvalue().splitlines()]
    assert len(counts) == out.counters["tasks"] > 5
    assert all(a <= c and b <= d for (a, b), (c, d) in zip(counts, counts[1:]))
    assert counts[-1] == (sum(map(len, out.found)), out.counters["nodes"])


#: an mpirun script's start: the workers serve, rank 0 goes on with tasks of nap()
NAP_SCRIPT = """
import json, sys, time
from hpcwedge.parallel import mpi
from hpcwedge.parallel.engine import Engine, run_tasks
from hpcwedge.parallel.worker import serve
from hpcwedge.progress import Progress

def nap(ctx, seconds):
    time.sleep(seconds)
    return {"slept": seconds}

comm = mpi.world()
if comm.rank:
    serve(comm)
    sys.exit()
"""

#: rank 0 runs one task of 1.5 s on its worker with progress lines every 0.2 s (to stdout)
LONG_TASK_UNDER_MPIRUN = NAP_SCRIPT + """
engine = Engine(comm, progress=Progress(stream=sys.stdout), progress_every_s=0.2)
got = run_tasks(nap, None, [1.5], engine=engine, kind="naps")
engine.close()
print("answer", got[0]["slept"])
"""


def run_under_mpirun(n: int, script: str):
    """`script` under mpirun -n n (stdout and stderr captured); the finished process."""
    import subprocess
    import sys

    from mpi_helpers import MPIRUN, env
    return subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", str(n), "-x", "PYTHONPATH",
                           sys.executable, "-c", script], env=env(), capture_output=True, text=True, timeout=120)


@pytest.mark.mpi
@needs_mpirun
def test_the_master_prints_progress_lines_while_a_long_task_runs():
    """mpirun -n 2, one task of 1.5 s, progress every 0.2 s: the master prints lines while it
    waits for the answer (before: only after a result was merged, so a job of one long task
    said nothing until its end), and the answer stands."""
    p = run_under_mpirun(2, LONG_TASK_UNDER_MPIRUN)
    assert p.returncode == 0, p.stderr
    lines = p.stdout.splitlines()
    waiting = [line for line in lines if "naps: 0 tasks done, 0 pending, 1 running" in line]
    assert len(waiting) >= 3, p.stdout
    assert lines[-1] == "answer 1.5"


#: two jobs on 2 workers: one task of 1 s (one worker idle), then four of 0.5 s (both busy)
USE_UNDER_MPIRUN = NAP_SCRIPT + """
engine = Engine(comm, progress=Progress(stream=sys.stdout), progress_every_s=0.5)
run_tasks(nap, None, [1.0], engine=engine, name="one")
run_tasks(nap, None, [0.5] * 4, engine=engine, name="four")
engine.close()
print(json.dumps(engine.summary()["utilisation"]))
"""


@pytest.mark.mpi
@needs_mpirun
def test_stats_say_how_busy_each_jobs_workers_were():
    """mpirun -n 3: a job of one task of 1 s keeps one of its 2 workers busy (about half), one
    of four tasks of 0.5 s both; each job's end prints the line."""
    import json
    import re
    p = run_under_mpirun(3, USE_UNDER_MPIRUN)
    assert p.returncode == 0, p.stderr
    use = json.loads(p.stdout.splitlines()[-1])
    assert use["one"]["workers"] == use["four"]["workers"] == 2
    assert 0.99 <= use["one"]["wall_s"] < 1.5 and 0.99 <= use["four"]["wall_s"] < 1.5
    assert 0.35 <= use["one"]["workers_busy"] <= 0.51, use
    assert 0.7 <= use["four"]["workers_busy"] <= 1.0, use
    assert all(0 <= u["master_busy"] < 0.5 for u in use.values()), use
    said = re.findall(r"(one|four): 1 s on 2 workers, busy (\d+)% of it \(the master \d+%\)", p.stdout)
    assert [name for name, _ in said] == ["one", "four"] and 35 <= int(said[0][1]) <= 51, p.stdout
