"""Checkpoints and --resume (SPEC §5) on the real command line: kill -9 of the
master at random moments (serially and under mpirun), SIGTERM, SIGUSR1, a
killed worker, and both in the middle of a 2D double description split over
faces — then --resume gives exactly the uninterrupted answers; a checkpoint of
another scene or a damaged one is refused (exit 2) and left as is."""
import errno
import json
import os
import random
import shutil
import signal
import subprocess
import time

import h5py
import numpy as np
import pytest
from mpi_helpers import (
    all_gone,
    answers,
    command,
    damaged,
    env,
    interrupt_cycles,
    launch,
    needs_mpirun,
    rank_pids,
    ray_arrays,
    rays_answers,
    run,
    scene_text,
    show,
    show_json,
    tmpfs,
    usr1_handled,
    wait_for_checkpoint,
    write_rays_scene,
    write_scene,
)

from hpcwedge.files import checkpoint_path
from hpcwedge.parallel.checkpoint import CheckpointError, read_checkpoint, write_checkpoint
from hpcwedge.parallel.engine import EXIT_INTERRUPTED


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """show --json (minus timings and stats.parallel) of the uninterrupted serial run."""
    tmp = tmp_path_factory.mktemp("ref")
    out = str(tmp / "ref.h5")
    run(None, "run", write_scene(tmp), "-o", out, "-q")
    return show(out)


def _signal(ranks, sig, rank=0):
    """how(proc) for interrupt_cycles: send `sig` to rank `rank` of an mpirun run with
    `ranks` ranks (ranks None: to the serial process); the pids that must be gone."""
    def how(p):
        if ranks is None:
            p.send_signal(sig)
            return [p.pid]
        pids = rank_pids(p.pid, ranks, proc=p)
        if rank not in pids:           # the run finished first
            return []
        os.kill(pids[rank], sig)
        return list(pids.values())
    return how


def _kill9_master(ranks):
    return _signal(ranks, signal.SIGKILL)


def _finish(scene, out, ranks=None, rays=True):
    run(ranks, "run", scene, "-o", out, "-q", "--resume")
    assert not os.path.exists(checkpoint_path(out)) and not os.path.exists(checkpoint_path(out) + ".tmp")
    return show_json(out, rays=rays)


# ---------------------------------------------------------------- kill -9


def test_kill9_at_random_moments_then_resume(tmp_path, reference):
    """Ten kill -9 of the (serial) master, each at a random moment after the
    engine's first checkpoint of that run (possibly mid-write), each followed by
    --resume: the final answers equal the uninterrupted run's."""
    scene, out, kills, codes = interrupt_cycles(tmp_path, None, 10, _kill9_master(None), random.Random(1))
    assert kills == 10 and all(c == -signal.SIGKILL for c in codes)
    got = _finish(scene, out)
    assert got["stats"]["parallel"]["resumes"] >= 1
    assert answers(got) == reference


@pytest.mark.mpi
@needs_mpirun
@pytest.mark.parametrize("ranks,seed", [(3, 2), (2, 3)])
def test_kill9_master_under_mpirun_then_resume(tmp_path, reference, ranks, seed):
    """kill -9 of rank 0 under mpirun, three times per rank count (each mpirun
    start costs ~3 s here), the workers go (they notice the dead master), and
    --resume under mpirun continues to the same answers."""
    scene, out, kills, codes = interrupt_cycles(tmp_path, ranks, 3, _kill9_master(ranks), random.Random(seed))
    assert kills == 3 and all(c != 0 for c in codes)
    assert answers(_finish(scene, out, ranks)) == reference


@pytest.mark.mpi
@needs_mpirun
def test_killed_worker_then_resume(tmp_path, reference):
    """kill -9 of a worker: Open MPI aborts the job (the master writes its
    checkpoint in mpirun's grace period or not at all); resume gives the same answers."""
    scene, out, kills, codes = interrupt_cycles(tmp_path, 3, 1, _signal(3, signal.SIGKILL, rank=1),
                                                random.Random(4))
    assert all(c != 0 for c in codes)
    assert answers(_finish(scene, out)) == reference          # resumed serially: any rank count


# ---------------------------------------------------------------- signals


def test_sigterm_writes_checkpoint_and_exits_75(tmp_path, reference):
    scene, out, n, codes = interrupt_cycles(tmp_path, None, 4, _signal(None, signal.SIGTERM), random.Random(5))
    assert codes == [EXIT_INTERRUPTED] * 4
    job = _show_of_checkpoint(out)
    a = read_checkpoint(checkpoint_path(out))["attrs"]
    p = run(None, "run", scene, "-o", out, "--resume")          # with its progress lines
    assert (f"resuming from {checkpoint_path(out)} (session {a['resumes'] + 2}; "
            f"{a['elapsed_s']:.1f} s of work before it)") in p.stderr, p.stderr
    assert not os.path.exists(checkpoint_path(out))
    final = show_json(out)
    assert answers(final) == reference
    if "found" in job:
        assert job["found"] <= sum(r["n_patterns"] for r in final["runs"])


def _twice(gap: float):
    """how(proc): SIGTERM to the serial process, and again `gap` seconds later."""
    def how(p):
        p.send_signal(signal.SIGTERM)
        time.sleep(gap)
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
        return [p.pid]
    return how


def test_a_second_sigterm_after_the_first_still_exits_75(tmp_path, reference):
    """SIGTERM, then SIGTERM again 0.05-0.2 s later (mpirun forwards SLURM's after its own):
    exit 75 with the checkpoint written (before: 143 in 6 of 6 runs, the handlers restored
    while the run closed, so the second signal killed it), and the resume finishes."""
    codes = []
    for gap in (0.05, 0.1, 0.2):
        (tmp_path / str(gap)).mkdir()
        scene, out, n, got = interrupt_cycles(tmp_path / str(gap), None, 1, _twice(gap), random.Random(7))
        codes += got
    assert codes == [EXIT_INTERRUPTED] * 3
    assert answers(_finish(scene, out)) == reference


def _show_of_checkpoint(out: str) -> dict:
    """`show RESULT.h5.ckpt` tells how far the stopped run got, from the checkpoint's own
    data (text and JSON); show, plot and export of the missing result or of the checkpoint
    as a result are one line, exit 2, naming --resume. Returns the last job's summary."""
    ckpt = checkpoint_path(out)
    ck = read_checkpoint(ckpt)
    text = run(None, "show", ckpt).stdout
    lines = text.splitlines()
    assert lines[0].startswith(f"{ckpt}: checkpoint of an unfinished run of ") and lines[0].endswith("(SIGTERM)")
    assert lines[-1] == f"to finish it: hpcwedge run SCENE -o {out} --resume"
    js = show_json(ckpt)
    assert js["checkpoint"] is True and js["reason"] == "SIGTERM" and js["resumes"] == ck["attrs"]["resumes"]
    assert [j["name"] for j in js["jobs"]] == ck["order"]
    job = js["jobs"][-1]                    # the job in progress, or the last finished one
    attrs, data = ck["jobs"][job["name"]]["attrs"], ck["jobs"][job["name"]]["data"]
    assert job["finished"] is bool(attrs["finished"]) and job["counters"] == json.loads(attrs["counters"])
    assert lines[-2].endswith("; done" if job["finished"] else "; in progress")
    if "found" in job:
        assert (job["found"], job["open"]) == (len(data["found_mu"]), len(data["open_mu"]))
        assert f"{job['found']} pattern(s) found, {job['open']} open subtree(s)" in text
        # the share decided as the run's progress line had it: 1 - the open subtrees' 2^-depth per tree
        share = 1.0 - sum(2.0 ** -int(d) for d in data["open_depth"]) / len(data["mus"])
        assert job["decided"] == pytest.approx(share, abs=1e-15) and 0.0 <= job["decided"] <= 1.0
        assert f"tree nodes, {100 * job['decided']:.3g} % of the tree decided (mu " in text
    else:
        assert job["done"] == len(data["done"]) and f"{job['done']} of {job['tasks']}" in text
    alone = os.path.join(os.path.dirname(out), "alone", "r.h5")     # a result not written yet
    os.makedirs(os.path.dirname(alone))
    shutil.copy(ckpt, checkpoint_path(alone))
    for cmd in (["show", alone], ["plot", checkpoint_path(alone), "-o", alone + ".png"],
                ["export", checkpoint_path(alone), "--pattern", "0", "-o", alone + ".vtu"]):
        p = run(None, *cmd, check=False)
        assert p.returncode == 2 and p.stderr.count("\n") == 1 and f"-o {alone} --resume" in p.stderr, p.stderr
    assert sorted(os.listdir(os.path.dirname(alone))) == ["r.h5.ckpt"]
    return job


@pytest.mark.mpi
@needs_mpirun
def test_sigterm_to_master_under_mpirun(tmp_path, reference):
    """SIGTERM to rank 0 (as SLURM sends it to every process of the job): the
    master writes its checkpoint, tells the workers to stop, and mpirun exits
    with the master's status 75, no rank left. Resume under mpirun: same answers."""
    scene, out, n, codes = interrupt_cycles(tmp_path, 3, 1, _signal(3, signal.SIGTERM), random.Random(6))
    assert codes == [EXIT_INTERRUPTED]
    with h5py.File(checkpoint_path(out)) as f:
        assert f.attrs["reason"] == "SIGTERM" and f.attrs["ranks"] == 3
    assert answers(_finish(scene, out, 2)) == reference


@pytest.mark.mpi
@needs_mpirun
def test_sigterm_to_mpirun(tmp_path):
    """SIGTERM to mpirun: it sends SIGCONT to every rank, SIGTERM 1 s later and
    SIGKILL ~1 s after that; the master writes its checkpoint in that grace.
    (A scene with four mu values, so that the run cannot end within the second
    mpirun waits, and plug2d rows 8 (m = 16: about 10 s of work serially; rows 5 ended
    before the signal once the 2D LPs were kept warm); a run that ends first anyway, or
    that mpirun kills before the stop checkpoint is written, leaving the periodic one
    whole, is started again.)"""
    text = (scene_text(raw=False).replace("mu = [0.65, 1.0]", "mu = [0.65, 1.0, 2.0, 4.0]")
            .replace("rows = 4", "rows = 8"))
    scene = write_scene(tmp_path, text=text)
    out = str(tmp_path / "r.h5")
    ckpt = checkpoint_path(out)
    for attempt in range(3):
        since = time.time()
        p = launch(3, "run", scene, "-o", out, "-q")
        pids = rank_pids(p.pid, 3)
        assert wait_for_checkpoint(ckpt, since, p)
        p.send_signal(signal.SIGTERM)
        code = p.wait(timeout=60)
        assert all_gone(pids.values())
        if os.path.exists(ckpt):
            with h5py.File(ckpt) as f:
                reason = f.attrs["reason"]
            if reason == "SIGTERM":
                assert code != 0
                break
            # mpirun's SIGKILL came before the stop checkpoint was written (once in CI, the
            # suite's disk busy): the periodic one before it is whole, and a resume goes on
            assert code != 0 and read_checkpoint(ckpt)["attrs"]["reason"] == reason
            os.unlink(ckpt)
            if os.path.exists(out):
                os.unlink(out)
        else:
            # the run ended first (its result written, the checkpoint removed, maybe killed after)
            assert os.path.exists(out), "neither a checkpoint nor a result"
            os.unlink(out)
    else:
        pytest.fail("no SIGTERM checkpoint in 3 runs: each ended, or mpirun killed it, first")
    got = _finish(scene, out)                           # resumed serially
    assert got["stats"]["parallel"]["resumes"] == 1
    from hpcwedge.results.hdf5 import write_result
    from hpcwedge.run.pipeline import run_scene  # the uninterrupted answers, in-process
    from hpcwedge.scene.parse import load_scene
    ref = str(tmp_path / "ref.h5")
    write_result(ref, run_scene(load_scene(scene)))
    assert answers(got) == answers(show_json(ref))


@pytest.mark.mpi
@needs_mpirun
def test_sigusr1_checkpoints_and_goes_on(tmp_path, reference):
    """SIGUSR1 to mpirun is forwarded to every rank: the master writes a
    checkpoint and the run (workers included) goes on to the same answers."""
    scene = write_scene(tmp_path, every=1000)        # no timer checkpoints: only the signal's
    out = str(tmp_path / "r.h5")
    ckpt = checkpoint_path(out)
    for attempt in range(5):                         # a run may end before a signal lands: start again
        if os.path.exists(out):
            os.remove(out)
        p = launch(3, "run", scene, "-o", out, "-q")
        pids = rank_pids(p.pid, 3, proc=p)
        # a rank that has not yet reached hpcwedge's first line dies of SIGUSR1, as any program would
        deadline = time.monotonic() + 60
        while not all(usr1_handled(pid) for pid in pids.values()) and p.poll() is None \
                and time.monotonic() < deadline:
            time.sleep(0.01)
        since = time.time()
        reason = None
        while p.poll() is None and time.monotonic() < deadline:
            p.send_signal(signal.SIGUSR1)
            time.sleep(0.3)
            try:
                with h5py.File(ckpt) as f:
                    reason, written = f.attrs["reason"], f.attrs["written_unix"]
                break
            except (OSError, KeyError):              # not there yet, or being replaced
                continue
        code = p.wait(timeout=120)
        assert all_gone(pids.values())
        if code == -signal.SIGUSR1 and os.path.exists(out) and not os.path.exists(ckpt):
            continue                                 # mpirun itself, tearing down a finished run
        assert code == 0, p.stderr.read()
        got = show_json(out)
        if reason is not None:                       # caught before the finished run removed it
            assert reason == "SIGUSR1" and written >= since - 1
        if got["stats"]["parallel"]["checkpoints_written"] >= 1:
            assert got["stats"]["parallel"]["last_checkpoint_reason"] == "SIGUSR1"
            break
    else:
        pytest.fail("the run always ended before a SIGUSR1 checkpoint")
    want = dict(reference, scene_hash=got["scene_hash"])   # the scene differs in checkpoint_every_s only
    assert answers(got) == want and not os.path.exists(ckpt)


# ---------------------------------------------------------------- in the middle of the 2D double description

#: plug2d rows 8 (m = 16) at mu 0.65, no mu^c: 8 face tasks of 0.05-0.6 s CPU (1.3 s in
#: all) under mpirun -n 3; a checkpoint every 0.3 s (each writes the finished faces' rays)
DD_ROWS, DD_EVERY = 8, 0.3


def _dd_scene(tmp_path) -> str:
    return write_rays_scene(tmp_path, DD_ROWS, every=DD_EVERY, mu_c="none")


@pytest.fixture(scope="module")
def dd_reference(tmp_path_factory):
    """The uninterrupted mpirun -n 3 run of the DD scene: show --json --no-rays and
    the ray arrays (mpi_helpers.ray_arrays)."""
    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not found")
    tmp = tmp_path_factory.mktemp("dd")
    scene = _dd_scene(tmp)
    out = str(tmp / "ref.h5")
    run(3, "run", scene, "-o", out, "-q")
    return show_json(out, rays=False), ray_arrays(out)


def _same_arrays(a: list, b: list) -> bool:
    return all(np.array_equal(x, y) and x.dtype == y.dtype
               for ra, rb in zip(a, b, strict=True) for x, y in zip(ra, rb, strict=True))


def _faces_done(ckpt: str, since: float):
    """(done, total) faces of the rays job in a checkpoint written after `since`, or None."""
    try:
        if os.stat(ckpt).st_mtime < since:
            return None
        job = read_checkpoint(ckpt)["jobs"].get("rays")
    except (OSError, CheckpointError):
        return None
    if job is None:
        return None
    return len(job["data"]["done"]), int(job["attrs"]["n_tasks"])


def _interrupt_mid_dd(tmp_path, how, attempts: int = 6):
    """Run the DD scene under mpirun -n 3 until a checkpoint holds some but not all
    faces, then how(proc, pids). A run whose DD ends first, or whose faces in flight all
    finish before the stop is read (its last checkpoint holds every face), is started again.
    Returns (scene, out, faces done in that checkpoint, exit status)."""
    scene = _dd_scene(tmp_path)
    out = str(tmp_path / "r.h5")
    ckpt = checkpoint_path(out)
    for attempt in range(attempts):
        for f in (out, ckpt):
            if os.path.exists(f):
                os.unlink(f)
        since = time.time()
        p = launch(3, "run", scene, "-o", out, "-q")
        pids = rank_pids(p.pid, 3, proc=p)
        state = None
        while p.poll() is None:
            state = _faces_done(ckpt, since)
            if state is not None and state[0] > 0:
                break
            time.sleep(0.01)
        if state is not None and 0 < state[0] < state[1] and p.poll() is None:
            how(p, pids)
            code = p.wait(timeout=60)
            p.stdout.close()
            p.stderr.close()
            assert all_gone(pids.values()), "ranks left behind"
            if code != 0:
                final = _faces_done(ckpt, since)
                if final is not None and final[0] == final[1]:
                    # the faces in flight finished before the master read the stop: the
                    # checkpoint holds them all, nothing is left to resume; start again
                    print(f"attempt {attempt + 1}: every face done by the stop")
                    continue
                print(f"interrupted in attempt {attempt + 1}, {state[0]} of {state[1]} faces done")
                return scene, out, state[0], code
        assert p.wait(timeout=120) == 0, p.stderr.read()
        p.stdout.close()
        p.stderr.close()
    pytest.fail("the DD always ended before a checkpoint caught it half-way")


def _tasks(d: dict) -> int:
    return sum(d["stats"]["parallel"]["tasks_per_rank"])


@pytest.mark.mpi
@needs_mpirun
def test_sigterm_mid_dd_then_resume_serially(tmp_path, dd_reference):
    """SIGTERM to rank 0 while the faces run (mpirun -n 3): exit 75, every rank
    gone, a checkpoint holding the finished faces. --resume without mpirun keeps
    the saved split (3 branching nodes, where a serial run would not split), runs
    only the missing faces and gives bit for bit the uninterrupted answers."""
    ref, ref_arrays = dd_reference
    t = {}

    def how(p, pids):
        t["sent"] = time.monotonic()
        os.kill(pids[0], signal.SIGTERM)
    scene, out, _, code = _interrupt_mid_dd(tmp_path, how)
    assert code == EXIT_INTERRUPTED
    assert time.monotonic() - t["sent"] < 30
    ck = read_checkpoint(checkpoint_path(out))
    assert ck["attrs"]["reason"] == "SIGTERM"
    done = len(ck["jobs"]["rays"]["data"]["done"])
    assert 0 < done < int(ck["jobs"]["rays"]["attrs"]["n_tasks"])
    assert _show_of_checkpoint(out)["kind"] == "face"
    got = _finish(scene, out, rays=False)
    assert got["stats"]["parallel"]["ranks"] == 1 and got["stats"]["parallel"]["resumes"] == 1
    assert _tasks(got) == _tasks(ref) - done                  # finished faces are not run again
    assert got["stats"]["parallel"]["jobs"]["rays"]["tasks"] == ref["stats"]["parallel"]["jobs"]["rays"]["tasks"]
    assert rays_answers(got)[0] == rays_answers(ref)[0]
    assert _same_arrays(ray_arrays(out), ref_arrays)          # the ray vectors too, bit for bit
    assert got["stats"]["dd"][0]["branching_nodes"] == ref["stats"]["dd"][0]["branching_nodes"]


@pytest.mark.mpi
@needs_mpirun
def test_kill9_master_mid_dd_then_resume_on_2_ranks(tmp_path, dd_reference):
    """kill -9 of rank 0 while the faces run (mpirun -n 3), --resume under
    mpirun -n 2 (which alone would split on 2 nodes): the saved split is kept,
    the faces of the last checkpoint are not run again, same answers bit for bit."""
    ref, ref_arrays = dd_reference
    scene, out, done, code = _interrupt_mid_dd(tmp_path, lambda p, pids: os.kill(pids[0], signal.SIGKILL))
    assert code != 0 and os.path.exists(checkpoint_path(out))
    got = _finish(scene, out, 2, rays=False)
    assert got["stats"]["parallel"]["ranks"] == 2 and got["stats"]["parallel"]["resumes"] == 1
    assert _tasks(got) <= _tasks(ref) - done
    assert rays_answers(got)[0] == rays_answers(ref)[0]
    assert _same_arrays(ray_arrays(out), ref_arrays)
    assert got["stats"]["dd"][0]["branching_nodes"] == ref["stats"]["dd"][0]["branching_nodes"]


# ---------------------------------------------------------------- refusing bad checkpoints


def _some_checkpoint(tmp_path):
    """A real checkpoint (a run stopped by SIGTERM once the engine has written one)."""
    scene = write_scene(tmp_path)
    out = str(tmp_path / "r.h5")
    since = time.time()
    p = launch(None, "run", scene, "-o", out, "-q")
    assert wait_for_checkpoint(checkpoint_path(out), since, p)
    p.send_signal(signal.SIGTERM)
    assert p.wait(timeout=60) == EXIT_INTERRUPTED
    return scene, out


def test_resume_with_another_scene_exit_2(tmp_path):
    scene, out = _some_checkpoint(tmp_path)
    ckpt = checkpoint_path(out)
    before = open(ckpt, "rb").read()
    other = write_scene(tmp_path, name="other.toml", text=scene_text().replace("1.0]", "1.5]"))
    p = run(None, "run", other, "-o", out, "--resume", check=False)
    assert p.returncode == 2
    err = p.stderr.strip()
    assert len(err.splitlines()) == 1 and "another scene" in err and ckpt in err
    assert open(ckpt, "rb").read() == before and not os.path.exists(out)
    # the right scene still resumes
    p = run(None, "run", scene, "-o", out, "-q", "--resume")
    assert os.path.exists(out) and not os.path.exists(ckpt)


def test_resume_with_other_run_settings_goes_on(tmp_path, reference):
    """The memory guard's advice is to raise run.max_memory_gb and resume; the checkpoint
    interval may change too: settings of the run, not of its answers, so --resume takes the
    checkpoint (one note naming them) and ends with the uninterrupted answers (before: 'the
    checkpoint belongs to another scene', exit 2). Any other change is still refused."""
    scene, out = _some_checkpoint(tmp_path)
    text = open(scene).read()
    assert "checkpoint_every_s = 0.02" in text
    changed = text.replace("checkpoint_every_s = 0.02", "checkpoint_every_s = 30.0\nmax_memory_gb = 64")
    other = write_scene(tmp_path, name="other.toml", text=changed.replace("1.0]", "1.5]"))
    _refused(other, out, "another scene")
    same = write_scene(tmp_path, name="same.toml", text=changed)
    p = run(None, "run", same, "-o", out, "--resume")
    assert "run.max_memory_gb, run.checkpoint_every_s differ from the checkpoint's scene" in p.stderr
    got, want = (answers({**d, "timings": None, "stats": {**d["stats"], "parallel": None}})
                 for d in (show(out), reference))
    assert got.pop("scene_hash") != want.pop("scene_hash") and got == want


def test_a_comment_or_a_setting_is_the_same_scene_for_checkpoints_and_results(tmp_path, reference):
    """One rule for "the same scene": texts that differ in comments, layout or run settings
    only. A comment added resumes the checkpoint (before: 'belongs to another scene', while a
    comment plus a changed setting resumed); a complete result stands under a changed
    checkpoint interval (before: recomputed in full)."""
    scene, out = _some_checkpoint(tmp_path)
    text = open(scene).read()
    commented = write_scene(tmp_path, name="commented.toml", text="# the same body\n" + text)
    p = run(None, "run", commented, "-o", out, "--resume")
    assert "resuming from" in p.stderr and not os.path.exists(checkpoint_path(out))
    got, want = show(out), dict(reference)
    assert got.pop("scene_hash") != want.pop("scene_hash") and got == want
    assert "checkpoint_every_s = 0.02" in text
    interval = write_scene(tmp_path, name="interval.toml",
                           text=text.replace("checkpoint_every_s = 0.02", "checkpoint_every_s = 30.0"))
    p = run(None, "run", interval, "-o", out, "--resume")
    assert "is already complete for this scene" in p.stderr, p.stderr
    other = write_scene(tmp_path, name="other.toml", text=text.replace("1.0]", "1.5]"))
    p = run(None, "run", other, "-o", out, "-q", "--resume")
    assert "already complete" not in p.stderr


def _refused(scene: str, out: str, phrase: str) -> None:
    """`run --resume` must refuse the checkpoint of `out`: exit 2, one line naming the
    checkpoint and `phrase`, the checkpoint byte for byte as it was, no result written."""
    ckpt = checkpoint_path(out)
    before = open(ckpt, "rb").read()
    p = run(None, "run", scene, "-o", out, "--resume", check=False)
    err = p.stderr.strip()
    assert p.returncode == 2 and len(err.splitlines()) == 1, p.stderr
    assert err.startswith("hpcwedge: error: ") and ckpt in err and phrase in err, err
    assert open(ckpt, "rb").read() == before and not os.path.exists(out)


@pytest.mark.parametrize("damage", ["truncate", "garbage", "empty"])
def test_damaged_checkpoint_exit_2_left_untouched(tmp_path, damage):
    if damage == "truncate":
        scene, out = _some_checkpoint(tmp_path)
        ckpt = checkpoint_path(out)
        data = open(ckpt, "rb").read()
        open(ckpt, "wb").write(data[: len(data) // 2])
    else:
        scene = write_scene(tmp_path)
        out = str(tmp_path / "r.h5")
        ckpt = checkpoint_path(out)
        open(ckpt, "wb").write(b"" if damage == "empty" else b"\x89HDF\r\n\x1a\n" + os.urandom(3000))
    _refused(scene, out, "unreadable checkpoint")


def test_random_damage_of_a_real_checkpoint_refused_and_kept(tmp_path, reference):
    """20 random damages (fixed seed) of a checkpoint written by a real SIGTERM'd run: 1 or 16
    flipped bytes at random offsets (anywhere: h5py never reads some of them), or a
    truncation. Each --resume is refused (exit 2, one line) and leaves the file as it is;
    the intact checkpoint then resumes to the uninterrupted answers."""
    scene, out = _some_checkpoint(tmp_path)
    ckpt = checkpoint_path(out)
    good = open(ckpt, "rb").read()
    rng = random.Random(11)
    for i in range(20):
        open(ckpt, "wb").write(damaged(good, rng, i))
        _refused(scene, out, "unreadable checkpoint")
        if i < 4:                   # show's summary trusts no more than --resume does
            p = run(None, "show", ckpt, check=False)
            assert p.returncode == 2 and p.stderr.count("\n") == 1 and not p.stdout, p
    open(ckpt, "wb").write(good)
    assert answers(_finish(scene, out)) == reference


def test_one_flipped_bit_in_the_saved_patterns_refused(tmp_path):
    """One bit of a saved sign-pattern word (a dataset h5py reads back without complaint,
    giving other patterns) makes the checkpoint refused."""
    scene, out = _some_checkpoint(tmp_path)
    ckpt = checkpoint_path(out)
    with h5py.File(ckpt, "r") as f:
        found = []
        f["jobs"].visititems(lambda name, ds: found.append((name, ds.id.get_offset(), ds[()]))
                             if isinstance(ds, h5py.Dataset) and name.endswith("_contact") and ds.size
                             and ds.id.get_offset() is not None else None)
    name, offset, words = found[0]
    with open(ckpt, "r+b") as fh:
        fh.seek(offset)
        byte = fh.read(1)[0]
        fh.seek(offset)
        fh.write(bytes([byte ^ 1]))
    with h5py.File(ckpt, "r") as f:                 # HDF5 alone does not notice
        assert not np.array_equal(f["jobs"][name][()], words)
    _refused(scene, out, "checksum")


def test_resume_after_the_stiffness_file_changed_exit_2(tmp_path, reference):
    """The checkpoint's identity covers the bytes of model.file: another K under the same name
    is refused (resuming would mix two problems); the original K resumes as usual."""
    scene, out = _some_checkpoint(tmp_path)
    k = tmp_path / "plug8.npz"
    good = k.read_bytes()
    with np.load(k) as z:
        K, N = z["K"], z["null_space"]
    np.savez(k, K=2 * K, null_space=N)              # a stiffer body: other u in every ray
    _refused(scene, out, "model.file plug8.npz changed since the checkpoint was written")
    k.write_bytes(good)
    assert answers(_finish(scene, out)) == reference


def test_resume_after_the_mesh_file_changed_exit_2(tmp_path):
    """The same for a mesh scene (its model.file), with a checkpoint the engine writes."""
    import meshio

    from hpcwedge.models import block2d
    from hpcwedge.parallel.engine import Engine
    from hpcwedge.scene.parse import load_scene
    ref = block2d(rows=2)
    meshio.write(str(tmp_path / "body.vtu"), meshio.Mesh(ref.coords, [("quad", ref.cells["quad"])]))
    path = tmp_path / "s.toml"
    path.write_text('name = "m"\ndim = 2\n[model]\nkind = "mesh"\nfile = "body.vtu"\n[contact]\n'
                    f"nodes = {ref.contact_nodes.tolist()}\nnormals = {ref.normals.tolist()}\n"
                    "[friction]\nmu = [0.65]\n")
    out = str(tmp_path / "r.h5")
    scene = load_scene(str(path))
    engine = Engine()
    engine.use_checkpoint(checkpoint_path(out), scene.hash, scene.text, 60.0, False, inputs=scene.input_digests)
    assert engine.write_checkpoint("SIGTERM")
    moved = ref.coords.copy()
    moved[0] += 0.01
    meshio.write(str(tmp_path / "body.vtu"), meshio.Mesh(moved, [("quad", ref.cells["quad"])]))
    _refused(str(path), out, "model.file body.vtu changed since the checkpoint was written")


@pytest.fixture
def small_fs(tmp_path):
    """A real 4 MB file system (tmpfs; mounting needs root), unmounted afterwards."""
    d = tmp_path / "fs"
    d.mkdir()
    with tmpfs(d, "size=4M"):
        yield d


def _fill(path) -> None:
    """Write `path` (appending) until its file system is full."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND)
    try:
        while True:
            os.write(fd, b"\0" * 4096)
    except OSError as e:
        assert e.errno == errno.ENOSPC, e
    finally:
        os.close(fd)


def _lines(path, phrase: str) -> list[str]:
    with open(path) as f:
        return [line for line in f if phrase in line]


def test_checkpoint_write_on_a_full_disk_keeps_the_last_and_goes_on(tmp_path, small_fs):
    """The output's file system fills up mid-run: every timer checkpoint that fails says so
    in one line, the last good checkpoint stays as it was, and the run goes on; once there
    is room again it finishes with the uninterrupted answers. (The plug of m = 12 at five
    mu: ~1 s of enumeration, time for the disk to fill; the default scene's run is 0.13 s.)"""
    text = scene_text(0.05).replace("plug8.npz", "plug12.npz").replace("mu = [0.65, 1.0]",
                                                                       "mu = [0.65, 0.8, 1.0, 1.2, 1.5]")
    scene = write_scene(tmp_path, text=text, rows=6)
    run(None, "run", scene, "-o", str(tmp_path / "ref.h5"), "-q")
    reference = show(str(tmp_path / "ref.h5"))
    out = str(small_fs / "r.h5")
    ckpt, filler, errors = checkpoint_path(out), small_fs / "filler", tmp_path / "stderr.txt"
    warning = f"hpcwedge: warning: checkpoint not written to {ckpt} (No space left on device)"
    for attempt in range(4):                        # a run may end before the disk is full: start again
        for f in (out, ckpt, filler):
            if os.path.exists(f):
                os.unlink(f)
        with open(errors, "w") as err:
            p = subprocess.Popen(command(None, "run", scene, "-o", out, "-q"), env=env(),
                                 stdout=subprocess.DEVNULL, stderr=err)
        try:
            if not wait_for_checkpoint(ckpt, 0, p):
                continue
            _fill(filler)
            deadline = time.monotonic() + 60
            while not _lines(errors, "warning") and p.poll() is None and time.monotonic() < deadline:
                time.sleep(0.01)
            _fill(filler)                           # what the failed write had used is free again: take it
            n, kept = len(_lines(errors, "warning")), open(ckpt, "rb").read()
            while len(_lines(errors, "warning")) <= n and p.poll() is None and time.monotonic() < deadline:
                time.sleep(0.01)
            running = p.poll() is None
            if running:
                assert open(ckpt, "rb").read() == kept and read_checkpoint(ckpt)["order"]
            os.unlink(filler)
            code = p.wait(timeout=120)
        finally:
            if p.poll() is None:
                p.kill()
                p.wait()
        if not running:                             # ended (the result write failed) before the test looked
            continue
        lines = open(errors).read().splitlines()
        if code == 2 and lines and "cannot write the result (No space left on device)" in lines[-1]:
            continue                                # ended between the test's look and its freeing the disk
        assert code == 0 and lines and all(line.startswith(warning) for line in lines), lines
        assert answers(show_json(out)) == dict(reference, scene_hash=show_json(out)["scene_hash"])
        assert not os.path.exists(ckpt)
        return
    pytest.fail("the run always ended before the disk was full")


def test_checkpoint_that_cannot_be_replaced_nor_removed(tmp_path, reference):
    """An immutable checkpoint (chattr +i: not even root may replace or delete it): each failed
    timer checkpoint and the failed removal at the end are one warning line, the file stays
    as it was, and the resumed run finishes with the uninterrupted answers."""
    scene, out = _some_checkpoint(tmp_path)
    ckpt = checkpoint_path(out)
    before = open(ckpt, "rb").read()
    p = subprocess.run(["chattr", "+i", ckpt], capture_output=True, text=True)
    if p.returncode != 0:
        pytest.skip(f"chattr +i not possible here: {p.stderr.strip()}")
    try:
        r = run(None, "run", scene, "-o", out, "-q", "--resume", check=False)
        lines = r.stderr.splitlines()
        assert r.returncode == 0 and lines, r.stderr
        assert lines[-1] == f"hpcwedge: warning: cannot remove {ckpt} (Operation not permitted)"
        assert all(line.startswith(f"hpcwedge: warning: checkpoint not written to {ckpt} (Operation not "
                                   f"permitted)") for line in lines[:-1]), lines
        assert open(ckpt, "rb").read() == before
    finally:
        subprocess.run(["chattr", "-i", ckpt], check=True)
    assert answers(show_json(out)) == reference


@pytest.mark.parametrize("ranks", [None, pytest.param(3, marks=needs_mpirun)])
def test_resume_on_a_complete_result_does_nothing(tmp_path, reference, ranks):
    """A chained or requeued job whose run has finished: `run --resume` on the complete result
    of this scene and these input files' bytes says so and exits 0, the file untouched (under
    mpirun too, the workers released); once the K file's bytes change it is another scene's
    result and the run computes again (before: every such rerun computed everything again)."""
    from hpcwedge.results.hdf5 import result_state
    from hpcwedge.scene.parse import load_scene
    scene = write_scene(tmp_path)
    out = str(tmp_path / "r.h5")
    run(None, "run", scene, "-o", out, "-q")
    before = open(out, "rb").read()
    assert result_state(out, load_scene(scene)) == "complete"
    t0 = time.monotonic()
    p = run(ranks, "run", scene, "-o", out, "--resume", timeout=60)
    assert p.stderr.splitlines()[-1] == (f"[hpcwedge] {out} is already complete for this scene and its input "
                                         "files; nothing to do (remove it to recompute)"), p.stderr
    assert open(out, "rb").read() == before and sorted(os.listdir(tmp_path)) == ["plug8.npz", "r.h5", "scene.toml"]
    assert time.monotonic() - t0 < 50
    k = dict(np.load(tmp_path / "plug8.npz"))
    k["K"] = 2.0 * k["K"]                       # the same wedged states, other bytes
    np.savez(tmp_path / "plug8.npz", **k)
    assert result_state(out, load_scene(scene)) == "other-scene"
    p = run(ranks, "run", scene, "-o", out, "--resume", "-q")
    assert "already complete" not in p.stderr and open(out, "rb").read() != before
    assert result_state(out, load_scene(scene)) == "complete"
    assert result_state(str(tmp_path / "none.h5"), load_scene(scene)) == "missing"


def test_resume_without_checkpoint_starts_fresh(tmp_path, reference):
    """SLURM requeue / job chains: `run --resume` is always safe to repeat."""
    scene = write_scene(tmp_path)
    out = str(tmp_path / "r.h5")
    run(None, "run", scene, "-o", out, "-q", "--resume")
    assert answers(show_json(out)) == reference and not os.path.exists(checkpoint_path(out))


# ---------------------------------------------------------------- the file itself


def _state(n):
    return {"attrs": {"kind": "subtree", "finished": False, "counters": "{}"},
            "data": {"x": np.arange(n), "w": np.ones((n, 2), dtype=np.uint64)}}


def test_write_read_round_trip(tmp_path):
    path = str(tmp_path / "c.h5.ckpt")
    write_checkpoint(path, {"scene_hash": "h", "inputs": "{}", "elapsed_s": 1.5, "resumes": 2, "ranks": 3,
                            "reason": "timer"},
                     "name = 'x'\n", [("a", _state(4)), ("b", _state(0))])
    ck = read_checkpoint(path)
    assert ck["order"] == ["a", "b"] and ck["scene_text"] == "name = 'x'\n"
    assert ck["attrs"]["scene_hash"] == "h" and ck["attrs"]["resumes"] == 2
    assert ck["jobs"]["a"]["data"]["x"].tolist() == [0, 1, 2, 3]
    assert ck["jobs"]["b"]["data"]["w"].shape == (0, 2)


def test_failed_write_keeps_the_good_checkpoint(tmp_path, monkeypatch):
    path = str(tmp_path / "c.h5.ckpt")
    header = {"scene_hash": "h", "inputs": "{}", "elapsed_s": 1.0, "resumes": 0, "ranks": 1, "reason": "timer"}
    write_checkpoint(path, header, "s", [("a", _state(3))])
    good = open(path, "rb").read()

    class Boom(Exception):
        pass

    bad = _state(3)
    bad["data"]["x"] = object()          # h5py cannot store it: the write fails half-way
    with pytest.raises(Exception):
        write_checkpoint(path, header, "s", [("a", bad)])
    assert open(path, "rb").read() == good and not os.path.exists(path + ".tmp")
    # a temp file that does not read back (verify fails) never replaces the good one
    import hpcwedge.parallel.checkpoint as ck

    def broken(p):
        raise CheckpointError("x")
    monkeypatch.setattr(ck, "read_checkpoint", broken)
    with pytest.raises(CheckpointError):
        write_checkpoint(path, header, "s", [("a", _state(5))])
    monkeypatch.undo()
    assert open(path, "rb").read() == good
    assert read_checkpoint(path)["jobs"]["a"]["data"]["x"].tolist() == [0, 1, 2]
