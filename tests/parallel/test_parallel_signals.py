"""Signals and the checkpoint timer inside long tasks (issue 11): a SIGTERM or the
timer is served within a second or so inside a 3D sign-pattern task, serially and
under the real mpirun; an interrupted subtree task hands back what it found and its
open subtrees, so --resume gives the uninterrupted answer; every stat (minus the
timings and stats.parallel) is the same for a plain, a resumed and an mpirun run."""
from __future__ import annotations

import json
import os
import random
import shutil
import signal
import time

import pytest
from mpi_helpers import all_gone, launch, needs_mpirun, rank_pids, run, show_json, wait_for_checkpoint, write_scene

from hpcwedge.parallel.checkpoint import read_checkpoint

#: plug3d, one mu; run.task_budget so large that one task explores a whole tree
PLUG3D = """name = "plug3d-r{ring}"
dim = 3
[model]
kind = "plug3d"
ring = {ring}
[friction]
mu = {mus}
[compute]
enumerate = true
mu_c = "{mu_c}"
[run]
checkpoint_every_s = {every}
task_budget = {budget}
"""


def plug3d_scene(tmp_path, ring: int, mus=(1.0,), mu_c: str = "none", every: float = 0.3,
                 budget: int = 1_000_000, name: str = "scene.toml") -> str:
    p = tmp_path / name
    p.write_text(PLUG3D.format(ring=ring, mus=list(mus), mu_c=mu_c, every=every, budget=budget))
    return str(p)


def same_part(d: dict) -> dict:
    """A show --json object minus what may differ between plain, resumed and
    parallel runs: the timings and stats.parallel (README)."""
    d = json.loads(json.dumps(d))
    d.pop("timings")
    d["stats"].pop("parallel")
    return d


def found_in_checkpoint(ckpt: str, job: str = "patterns") -> int:
    return len(read_checkpoint(ckpt)["jobs"][job]["data"]["found_mu"])


def sigterm_when_checkpointed(proc, ckpt: str, extra_s: float = 0.0, pids=()) -> float:
    """Wait for the first checkpoint (the timer served), then `extra_s`, then SIGTERM
    to `pids` (default: proc); returns the seconds from the signal to proc's exit."""
    assert wait_for_checkpoint(ckpt, 0.0, proc, timeout=120.0), proc.communicate()
    if extra_s:
        time.sleep(extra_s)
    assert proc.poll() is None, "the run ended before the signal"
    t = time.monotonic()
    for pid in pids or [proc.pid]:
        os.kill(pid, signal.SIGTERM)
    proc.wait(timeout=120)
    return time.monotonic() - t


def test_sigterm_inside_a_3d_subtree_task_serial(tmp_path):
    """plug3d ring 10 (m = 20) as one subtree task of ~20 s: the checkpoint timer is
    served inside the task (a checkpoint appears while it runs), SIGTERM stops the run
    within seconds (before: at the end of the task), exit 75, and the checkpoint keeps
    the patterns the stopped task had found (nothing lost)."""
    scene = plug3d_scene(tmp_path, 10)
    out = str(tmp_path / "r.h5")
    ckpt = out + ".ckpt"
    t0 = time.monotonic()
    p = launch(None, "run", scene, "-o", out, "-q")
    latency = sigterm_when_checkpointed(p, ckpt, extra_s=1.0)
    err = p.stderr.read()
    assert p.returncode == 75, err
    assert latency < 5.0, (latency, time.monotonic() - t0)
    assert "Traceback" not in err
    assert found_in_checkpoint(ckpt) > 0
    assert not os.path.exists(out)


@pytest.fixture(scope="module")
def plug3d_plain(tmp_path_factory):
    """plug3d ring 10, patterns only, one task per tree: (scene, show JSON of a plain run).
    Ring 10: the run must outlast the first checkpoint and 1.5 s more under mpirun -n 3
    (ring 8 took 2.3 s there once the first SOCP attempts stopped failing, and ended first)."""
    tmp = tmp_path_factory.mktemp("plug3d")
    scene = plug3d_scene(tmp, 10)
    out = str(tmp / "plain.h5")
    run(None, "run", scene, "-o", out, "-q")
    return scene, show_json(out)


def test_sigterm_mid_task_then_resume_serial_same_answers_and_stats(tmp_path, plug3d_plain):
    """SIGTERM inside the only subtree task, --resume: the same patterns and the same
    stats (bnb counters, solver statuses) as the plain run."""
    scene, want = plug3d_plain
    out = str(tmp_path / "r.h5")
    p = launch(None, "run", scene, "-o", out, "-q")
    latency = sigterm_when_checkpointed(p, out + ".ckpt", extra_s=0.5)
    assert p.returncode == 75, p.stderr.read()
    assert latency < 5.0
    assert found_in_checkpoint(out + ".ckpt") > 0
    run(None, "run", scene, "-o", out, "-q", "--resume")
    got = show_json(out)
    assert got["stats"]["parallel"]["resumes"] == 1
    assert same_part(got) == same_part(want)


@pytest.mark.mpi
@needs_mpirun
def test_sigterm_to_mpirun_inside_a_worker_task_then_resume(tmp_path, plug3d_plain):
    """mpirun -n 3: SIGTERM to every rank (as SLURM sends it) while a worker runs the
    only subtree task: the job ends within seconds with the master's exit 75 (before:
    the worker finished its task first), the checkpoint holds what the worker found
    before it stopped (handed back, not dropped), and --resume on 3 ranks gives the
    plain serial run's answers and stats."""
    scene, want = plug3d_plain
    out = str(tmp_path / "r.h5")
    p = launch(3, "run", scene, "-o", out, "-q")
    pids = rank_pids(p.pid, 3)
    latency = sigterm_when_checkpointed(p, out + ".ckpt", extra_s=1.5, pids=list(pids.values()))
    err = p.stderr.read()
    assert p.returncode == 75, err
    assert latency < 10.0 and "Traceback" not in err
    assert found_in_checkpoint(out + ".ckpt") > 0
    assert all_gone(pids.values())
    run(3, "run", scene, "-o", out, "-q", "--resume")
    got = show_json(out)
    assert got["stats"]["parallel"]["resumes"] == 1 and got["stats"]["parallel"]["ranks"] == 3
    assert same_part(got) == same_part(want)


@pytest.mark.mpi
@needs_mpirun
@pytest.mark.parametrize("dim", [2, 3])
def test_stats_same_for_plain_resumed_and_3_ranks(tmp_path, dim):
    """Every stat but the timings and stats.parallel is the same for a plain run, a
    run stopped by SIGTERM and resumed, and mpirun -n 3 (2D: plug2d m = 8 in budgets
    of 4 nodes; 3D: plug3d ring 5 at two mu with mu^c, budgets of 4 nodes), so
    subtrees really move between tasks, ranks and sessions; and for the same scene
    in tasks of one tree node (run.task_budget = 1: every subtree handed back)."""
    if dim == 2:
        scene = write_scene(tmp_path, every=0.05)
    else:
        scene = plug3d_scene(tmp_path, 5, mus=(0.65, 1.0), mu_c="cones", every=0.05, budget=4)
    plain = str(tmp_path / "plain.h5")
    run(None, "run", scene, "-o", plain, "-q")
    want = show_json(plain)
    assert want["stats"]["parallel"]["jobs"]["patterns"]["handed_back"] > 0
    text = open(scene).read()
    assert "task_budget = 4" in text
    one = str(tmp_path / "one.toml")
    with open(one, "w") as f:
        f.write(text.replace("task_budget = 4", "task_budget = 1"))
    run(None, "run", one, "-o", str(tmp_path / "one.h5"), "-q")
    got = same_part(show_json(str(tmp_path / "one.h5")))
    assert got.pop("scene_hash") != want["scene_hash"]
    assert got == {k: v for k, v in same_part(want).items() if k != "scene_hash"}
    par = str(tmp_path / "par.h5")
    run(3, "run", scene, "-o", par, "-q")
    assert same_part(show_json(par)) == same_part(want)
    resumed = str(tmp_path / "resumed.h5")
    for _ in range(5):                       # a run may end before the signal: try again
        p = launch(None, "run", scene, "-o", resumed, "-q")
        if wait_for_checkpoint(resumed + ".ckpt", 0.0, p) and p.poll() is None:
            p.send_signal(signal.SIGTERM)
        p.wait(timeout=120)
        if p.returncode == 75:
            break
        assert p.returncode == 0, p.stderr.read()
    assert p.returncode == 75
    run(None, "run", scene, "-o", resumed, "-q", "--resume")
    got = show_json(resumed)
    assert got["stats"]["parallel"]["resumes"] == 1
    assert same_part(got) == same_part(want)


@needs_mpirun
def test_sigterm_to_the_master_before_the_workers_serve_ends_the_job(tmp_path):
    """mpirun -n 3 on a body whose condensation (collective, all ranks) takes seconds: a
    SIGTERM to rank 0 as soon as its handler is in, before the workers leave the collective
    start-up for their task loop. The job ends with exit 75 and every rank gone (before:
    the master exited, the workers waited in the broadcast forever, spinning)."""
    scene = tmp_path / "block.toml"
    scene.write_text('name = "b"\ndim = 2\n[model]\nkind = "block2d"\nrows = 3\nrefine = 150\n'
                     '[friction]\nmu = [0.65]\n[compute]\nmu_c = "none"\n')
    proc = launch(3, "run", str(scene), "-o", str(tmp_path / "b.h5"), "-q")
    try:
        pids = rank_pids(proc.pid, 3)
        bit = 1 << (signal.SIGTERM - 1)
        end = time.monotonic() + 60
        while time.monotonic() < end:
            with open(f"/proc/{pids[0]}/status") as f:
                caught = int(next(ln for ln in f if ln.startswith("SigCgt")).split(":")[1], 16)
            if caught & bit:
                break
            time.sleep(0.002)
        os.kill(pids[0], signal.SIGTERM)
        assert proc.wait(timeout=60) == 75
    finally:
        proc.kill()
        proc.wait()
    assert all_gone(pids.values())
    assert not (tmp_path / "b.h5").exists()



#: plug3d 3 x 5 (m = 15) at a 0 deg taper without its symmetry, the global mu^c only: a
#: search of ~6 s, most of it in the settling tree (job global_patterns; 6,418 tree nodes).
#: At a taper > 0 the certified lower bound (mu_c/lower_bound.py) ends the search before any
#: settling; at 0 elasticity sets mu^c (0.717) and the rigid bound is 0
GLOBAL = """name = "plug3d-global"
dim = 3
[model]
kind = "plug3d"
levels = 3
ring = 5
taper_deg = 0.0
[friction]
mu = [1.0]
[compute]
enumerate = false
mu_c = "global"
[run]
symmetry = false
checkpoint_every_s = 0.3
task_budget = 16
"""


@pytest.fixture(scope="module")
def global_plain(tmp_path_factory):
    """(scene, show JSON of a plain serial run) of GLOBAL."""
    tmp = tmp_path_factory.mktemp("global")
    scene = tmp / "global.toml"
    scene.write_text(GLOBAL)
    out = str(tmp / "plain.h5")
    run(None, "run", str(scene), "-o", out, "-q")
    return str(scene), show_json(out)


def sigterm_in_global_patterns(proc, ckpt: str, pids=()) -> float:
    """Wait until the checkpoint holds the global search's settling tree with tree nodes done
    (job global_patterns), then SIGTERM to `pids` (default: proc); the seconds to proc's exit."""
    end = time.monotonic() + 120
    while time.monotonic() < end:
        assert proc.poll() is None, "the run ended before the signal"
        try:
            job = read_checkpoint(ckpt)["jobs"].get("global_patterns")
        except Exception:                        # not written yet, or being replaced
            job = None
        if job is not None and json.loads(job["attrs"]["counters"]).get("nodes", 0) > 0:
            break
        time.sleep(0.05)
    t = time.monotonic()
    for pid in pids or [proc.pid]:
        os.kill(pid, signal.SIGTERM)
    proc.wait(timeout=120)
    return time.monotonic() - t


@pytest.mark.parametrize("ranks", [None, pytest.param(3, marks=[pytest.mark.mpi, needs_mpirun])])
def test_sigterm_inside_the_global_search_then_resume(tmp_path, global_plain, ranks):
    """mu_c = "global" without an enumeration: a SIGTERM (to every rank, as SLURM sends it)
    while the global search settles its bracket stops the run within seconds with exit 75
    (before: the search ran on the master alone, deaf to signals, to its end), the
    checkpoint keeps the search's bracket and its settling tree's progress, and --resume
    (on as many ranks) ends with the plain serial run's answers and stats."""
    scene, want = global_plain
    out = str(tmp_path / "r.h5")
    p = launch(ranks, "run", scene, "-o", out, "-q")
    pids = list(rank_pids(p.pid, ranks).values()) if ranks else []
    latency = sigterm_in_global_patterns(p, out + ".ckpt", pids)
    err = p.stderr.read()
    assert p.returncode == 75, err
    assert latency < 5.0 and "Traceback" not in err
    jobs = read_checkpoint(out + ".ckpt")["jobs"]
    assert json.loads(jobs["global_bracket"]["attrs"]["counters"])["tasks"] == 1
    if ranks:
        assert all_gone(pids)
    run(ranks, "run", scene, "-o", out, "-q", "--resume")
    got = show_json(out)
    par = got["stats"]["parallel"]
    assert par["resumes"] == 1 and par["ranks"] == (ranks or 1)
    assert same_part(got) == same_part(want)


def test_kill9_inside_the_global_search_then_resume(tmp_path, global_plain):
    """kill -9 of a serial run at random moments after one of its checkpoints (in the global
    search's bracket task or its settling tree, possibly mid-write), three times, each
    followed by --resume: the answers and stats.bnb are the plain run's, and the work of
    the killed runs was kept (at least one resume with the bracket restored)."""
    scene, want = global_plain
    out = str(tmp_path / "r.h5")
    ckpt = out + ".ckpt"
    rng = random.Random(7)
    for _ in range(3):
        since = time.time()
        p = launch(None, "run", scene, "-o", out, "-q", "--resume")
        assert wait_for_checkpoint(ckpt, since, p), p.stderr.read()
        time.sleep(rng.uniform(0.0, 1.5))
        p.kill()
        assert p.wait(timeout=60) == -signal.SIGKILL
        p.stdout.close()
        p.stderr.close()
    assert "global_bracket" in read_checkpoint(ckpt)["jobs"]
    run(None, "run", scene, "-o", out, "-q", "--resume")
    got = show_json(out)
    assert got["stats"]["parallel"]["resumes"] >= 1 and not os.path.exists(ckpt)
    assert same_part(got) == same_part(want)


def bracket_in_checkpoint(ckpt: str) -> tuple[int, dict] | None:
    """(tasks done, continued payloads) of the global bracket job in the checkpoint; None
    when there is none to read (not written yet, or being replaced)."""
    try:
        job = read_checkpoint(ckpt)["jobs"].get("global_bracket")
    except Exception:                            # not written yet, or being replaced
        return None
    if job is None:
        return None
    return json.loads(job["attrs"]["counters"])["tasks"], json.loads(job["attrs"].get("continued", "{}"))


def test_the_bracket_task_is_checkpointed_while_it_runs_and_resumes_after_kill9(tmp_path):
    """The global bracket is one long task: with checkpoint_every_s = 0.02 the timer
    checkpoint is written again and again while it runs, and the bracket pauses between its
    steps (a Continuation) so that a checkpoint holds its progress (its best value so far and
    the next bound). kill -9 with that checkpoint on disk (a copy taken as it is seen: the
    bracket's last step is short), then --resume: the run ends with the plain run's answers
    and stats, the bracket resumed from its continuation."""
    scene = tmp_path / "global.toml"
    scene.write_text(GLOBAL.replace("checkpoint_every_s = 0.3", "checkpoint_every_s = 0.02"))
    scene = str(scene)
    run(None, "run", scene, "-o", str(tmp_path / "plain.h5"), "-q")
    want = show_json(str(tmp_path / "plain.h5"))
    out = str(tmp_path / "r.h5")
    ckpt = out + ".ckpt"
    p = launch(None, "run", scene, "-o", out, "-q")
    snaps, held, last = [], None, None
    end = time.monotonic() + 120
    while held is None and time.monotonic() < end and p.poll() is None:
        try:
            mtime = os.stat(ckpt).st_mtime
        except FileNotFoundError:
            mtime = None
        if mtime is not None and mtime != last:
            last = mtime
            snaps.append(f"{ckpt}.{len(snaps)}")
            shutil.copy(ckpt, snaps[-1])     # each version, as the run replaces it (atomically)
            got = bracket_in_checkpoint(snaps[-1])
            if got is not None and got[0] == 0 and got[1] and got[1]["0"]["best"] is not None:
                held = got[1]["0"]
                shutil.copy(snaps[-1], ckpt + ".kept")
        time.sleep(0.005)
    p.kill()
    p.wait(timeout=60)
    p.stdout.close()
    p.stderr.close()
    assert held is not None, "no checkpoint held the bracket with a value"
    running = [s for s in snaps if (bracket_in_checkpoint(s) or (1,))[0] == 0]
    assert len(running) >= 2                                  # checkpoints while the bracket ran
    os.replace(ckpt + ".kept", ckpt)
    assert held["best"] * (1 - 1e-2) == held["bound"] and want["mu_c"] <= held["best"]
    run(None, "run", scene, "-o", out, "-q", "--resume")
    got = show_json(out)
    assert got["stats"]["parallel"]["resumes"] == 1 and not os.path.exists(ckpt)
    assert same_part(got) == same_part(want)


#: plug3d 6 x 8 (m = 48) without its symmetry, the global mu^c: a bracket of ~20 s whose
#: first dive (r_t free) and steps are single Clarabel-bound tree dives of seconds
GLOBAL_48 = GLOBAL.replace("levels = 3", "levels = 6").replace("mu = [1.0]", "mu = [0.1]")


def test_sigterm_inside_a_long_bracket_at_m48_is_served_at_once(tmp_path):
    """SIGTERM while the global bracket of plug3d 6 x 8 (m = 48) runs its tree dives (Clarabel
    solves that ask task_stopping every iteration): the checkpoint is written and the
    run says so within 2 s of the signal, and it exits 75 (the rest of the exit is the
    interpreter's teardown, ~1-2 s on the shared 2-core machine); the checkpoint holds the
    bracket job."""
    scene = tmp_path / "g48.toml"
    scene.write_text(GLOBAL_48)
    out = str(tmp_path / "r.h5")
    p = launch(None, "run", str(scene), "-o", out, "-q")
    end = time.monotonic() + 180
    while (bracket_in_checkpoint(out + ".ckpt") or (1,))[0] != 0:   # a checkpoint: the bracket runs
        assert p.poll() is None and time.monotonic() < end, p.communicate()
        time.sleep(0.05)
    t = time.monotonic()
    p.send_signal(signal.SIGTERM)
    line = p.stderr.readline()
    said = time.monotonic() - t
    assert p.wait(timeout=60) == 75, line + p.stderr.read()
    gone = time.monotonic() - t
    assert "checkpoint written" in line and said < 2.0, (line, said)
    assert gone < 6.0, gone
    assert bracket_in_checkpoint(out + ".ckpt") is not None
