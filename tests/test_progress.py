"""Progress lines (time left) and the runaway guard (run.max_memory_gb): a run that
would outgrow its memory stops early with one line naming the key (exit 2, nothing
written), serially and under mpirun; a MemoryError that still happens is one line too."""
from __future__ import annotations

import io
import os
import resource
import subprocess
import time

import pytest
from mpi_helpers import command, env, needs_mpirun

from hpcwedge.errors import UserError
from hpcwedge.progress import (GB, SHARE_DECAY, SHARE_GROWTH_MIN, SHARE_LEFT_MAX_S, SHARE_WINDOW, SHARE_WINDOW_MIN_S,
                               MemoryGuard, MemoryLimit, Progress, ShareClock, eta, left_text, rss_bytes)
from hpcwedge.scene.parse import parse_scene
from hpcwedge.scene.values import SceneError

#: plug2d with 36 contact nodes: its rays outgrow any small memory within seconds
RUNAWAY = """name = "runaway"
dim = 2
[model]
kind = "plug2d"
rows = 18
[friction]
mu = [0.65]
[compute]
enumerate = true
mu_c = "cones"
[run]
max_memory_gb = {gb}
"""


def _run(tmp_path, gb, ranks=None, limit_as=None):
    scene = tmp_path / "s.toml"
    scene.write_text(RUNAWAY.format(gb=gb))
    out = tmp_path / "r.h5"

    def cap():
        if limit_as:
            resource.setrlimit(resource.RLIMIT_AS, (limit_as, limit_as))

    p = subprocess.run(command(ranks, "run", str(scene), "-o", str(out), "-q"), env=env(), capture_output=True,
                       text=True, timeout=300, preexec_fn=cap)
    return p, out


def test_runaway_2d_run_refused_early_in_one_line(tmp_path):
    """plug2d m = 36 with run.max_memory_gb = 0.4: stopped at the double description step
    that would exceed it — one line with the estimate and the key, exit 2, no result
    and no checkpoint, peak memory near the limit (before: allocation up to a
    MemoryError traceback at ~5 GB)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    p, out = _run(tmp_path, 0.4)
    peak_gb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024 / GB
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hpcwedge: error: run.max_memory_gb: "), p.stderr
    assert "live rays" in lines[0] and "GB needed" in lines[0] and "max_memory_gb = 0.4" in lines[0]
    assert not out.exists() and not os.path.exists(str(out) + ".ckpt")
    assert before * 1024 / GB > 2.0 or peak_gb < 2.0, peak_gb


def test_memory_error_is_one_line(tmp_path):
    """A MemoryError the guard did not foresee (address space capped at 2.5 GB, the key
    at 1000 GB): one line naming run.max_memory_gb, exit 2, nothing written."""
    p, out = _run(tmp_path, 1000, limit_as=int(2.5 * GB))
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "run.max_memory_gb: out of memory" in lines[0], p.stderr
    assert "Traceback" not in p.stderr and not out.exists()


@pytest.mark.mpi
@needs_mpirun
def test_runaway_refused_under_mpirun(tmp_path):
    """mpirun -n 3: the face task of a worker hits the guard; the master reports the
    worker's one line (exit 2, no traceback), every rank ends."""
    p, out = _run(tmp_path, 0.4, ranks=3)
    assert p.returncode == 2, p.stderr
    assert p.stderr.count("hpcwedge: error: run.max_memory_gb: the double description of face") == 1
    assert "Traceback" not in p.stderr and not out.exists()


def test_guard_limit_and_message():
    """"auto" takes a share of the machine's available memory; a number is GB; the
    error names the key and the need."""
    auto = MemoryGuard("auto")
    assert 0 < auto.limit < float("inf")
    assert MemoryGuard("auto", ranks_here=4).limit < auto.limit
    g = MemoryGuard(0.001)
    assert g.limit == 0.001 * GB
    with pytest.raises(MemoryLimit, match=r"^run.max_memory_gb: building X: about .* GB needed") as e:
        g.check(0, "building X")
    assert isinstance(e.value, UserError) and "\n" not in str(e.value)
    MemoryGuard(1e6).check(10 * GB, "fits")          # a large limit: no error
    assert rss_bytes() > 0


@pytest.mark.parametrize("bad", [0, -1.0, "lots", True, float("inf")])
def test_max_memory_gb_key_checked(bad):
    with pytest.raises(SceneError, match="run.max_memory_gb"):
        parse_scene({"name": "s", "dim": 2, "model": {"kind": "plug2d"}, "friction": {"mu": [1.0]},
                     "run": {"max_memory_gb": bad}})
    sc = parse_scene({"name": "s", "dim": 2, "model": {"kind": "plug2d"}, "friction": {"mu": [1.0]},
                      "run": {"max_memory_gb": 2}})
    assert sc.max_memory_gb == 2


def test_progress_lines_give_the_time_left():
    assert eta(10.0, 1, 4) == ", about 30 s left"
    assert eta(60.0, 1, 11) == ", about 10 min left"
    assert eta(1.0, 0, 4) == "" and eta(1.0, 4, 4) == ""
    buf = io.StringIO()
    pr = Progress(stream=buf, every=0.0).stage("rays mu=0.65")
    pr({"done": 2, "total": 6, "rays": 10, "bytes": 100, "elapsed": 4.0})
    assert "2/6 constraints" in buf.getvalue() and "about 8 s left" in buf.getvalue()


def test_time_left_units():
    assert left_text(None) == "" and left_text(119.4) == ", about 119 s left"
    assert left_text(150.0) == ", about 2 min left" and left_text(7199.0) == ", about 120 min left"
    assert left_text(3 * 3600.0) == ", about 3 h left"


def test_share_clock_is_exact_on_a_steady_rate():
    """decay = 0: a share that grows 1 % a second from 0.2 at t = 100 has 80 s left at any sample."""
    clock = ShareClock(100.0, 0.2, decay=0.0)
    for t in (101.0, 105.0, 130.0, 150.0):
        share = 0.2 + 0.01 * (t - 100.0)
        assert clock.left(t, share) == pytest.approx(100.0 - (t - 100.0) - 20.0)


def test_share_clock_is_exact_on_its_decaying_rate():
    """A share 0.1 + 0.05 tau^0.3 (tau: seconds since the job started at t = 50) reaches 1 at
    tau = 18^(1/0.3) = 15,290 s; the default clock (SHARE_DECAY 0.7) tells what is left from any
    two samples, the steady rate of its window far less."""
    assert SHARE_DECAY == 0.7
    def share(tau):
        return 0.1 + 0.05 * tau ** 0.3

    end = 18.0 ** (1.0 / 0.3)
    assert end == pytest.approx(15290.0, rel=1e-3)
    clock, steady = ShareClock(50.0, share(0.0)), ShareClock(50.0, share(0.0), decay=0.0)
    for tau in (3.0, 40.0, 100.0, 400.0):
        assert clock.left(50.0 + tau, share(tau)) == pytest.approx(end - tau, rel=1e-9)
        assert steady.left(50.0 + tau, share(tau)) < 0.3 * (end - tau)
    assert clock.left(50.0 + end, 1.0) == pytest.approx(0.0, abs=1e-6)


def test_share_clock_follows_the_recent_growth():
    """A tree whose easy part closes first: 0 -> 0.8 in 10 s, then 0.001 a second. At t = 60
    (share 0.85; 150 s left) the rate since the start says 10.6 s; the clock fits its window
    (its last 20 s, SHARE_WINDOW_MIN_S, all in the slow part) and tells the decaying model's
    time, (60^q + 0.15 / c)^(1/q) - 60 with c = 0.02 / (60^q - 40^q), q = 0.3: 414 s. A steady
    rate over the same window (decay 0) says 150 s."""
    def share(t):
        return 0.08 * t if t <= 10.0 else 0.8 + 0.001 * (t - 10.0)

    q = 1.0 - SHARE_DECAY
    clock, steady = ShareClock(0.0, 0.0), ShareClock(0.0, 0.0, decay=0.0)
    for t in range(1, 60):
        clock.left(float(t), share(t))
        steady.left(float(t), share(t))
    since_start = 60.0 * (1.0 - share(60)) / share(60)
    assert since_start == pytest.approx(10.59, abs=0.01)
    c = 0.02 / (60.0 ** q - 40.0 ** q)
    model = (60.0 ** q + 0.15 / c) ** (1.0 / q) - 60.0
    assert SHARE_WINDOW == 0.2 and SHARE_WINDOW_MIN_S == 20.0 and model == pytest.approx(414.0, abs=0.1)
    assert clock.left(60.0, share(60)) == pytest.approx(model)
    assert steady.left(60.0, share(60)) == pytest.approx(150.0)
    # early on, the window (at least 20 s) reaches back to the start
    early = ShareClock(0.0, 0.0, decay=0.0)
    early.left(5.0, share(5))
    assert early.left(12.0, share(12)) == pytest.approx(12.0 * (1.0 - share(12)) / share(12))


def test_a_resumed_share_clock_keeps_the_jobs_time():
    """A job on the decaying share 0.05 tau^0.3, stopped at tau = 400 s and resumed at t = 7
    (another clock): ShareClock.resumed(7, 400, share) tells the model's time left at its first
    sample after the resume (anchored at the job's start, share 0), as the uninterrupted clock
    does, and goes on telling it; a clock that restarted at the resume (tau from 0) says a
    different time. The first session's samples are gone, so the window reaches back to the
    start until its start passes the resume."""
    def share(tau):
        return 0.05 * tau ** 0.3

    end = 20.0 ** (1.0 / 0.3)
    clock = ShareClock.resumed(7.0, 400.0, share(400.0))
    restarted = ShareClock(7.0, share(400.0))
    for tau in (401.0, 410.0, 500.0, 3000.0):
        assert clock.left(7.0 + tau - 400.0, share(tau)) == pytest.approx(end - tau, rel=1e-9)
    told = restarted.left(7.0 + 2600.0, share(3000.0))
    assert told is not None and not told == pytest.approx(end - 3000.0, rel=0.1)


def test_share_clock_says_nothing_before_the_share_moved():
    """No time left while the share has grown less than SHARE_GROWTH_MIN since the start, or
    not at all over the window (samples at uneven times, one repeated); a share that all but
    stalled tells at most SHARE_LEFT_MAX_S."""
    clock = ShareClock(0.0, 0.5, decay=0.0)
    assert clock.left(5.0, 0.5 + 0.5 * SHARE_GROWTH_MIN) is None
    assert clock.left(10.0, 0.6) == pytest.approx(40.0)
    assert clock.left(10.0, 0.6) == pytest.approx(40.0)
    assert clock.left(100.0, 0.6) is None                  # stalled over the window
    assert ShareClock(0.0, 0.0).left(0.0, 0.5) is None      # no time passed
    crawl = ShareClock(0.0, 0.0)
    crawl.left(1.0, 0.02)
    assert crawl.left(1e4, 0.02 + 1e-12) == SHARE_LEFT_MAX_S
    with pytest.raises(ValueError):
        ShareClock(0.0, 0.0, decay=1.0)


def test_progress_every_s_sets_the_lines_of_a_batch_log(tmp_path):
    """`run.progress_every_s` sets how often a batch run (stderr a pipe) prints its line: the
    3D pattern search of plug3d 3 x 6 (a few seconds) gives several at 0.3 s, with the share
    of the tree decided, and the time left once 1 % is decided; at the default 10 s none in a
    run of less than 10 s (one on a loaded machine where it took 11 s)."""
    import re
    lines, wall = {}, {}
    for every in (0.3, None):
        t0 = time.monotonic()
        scene = tmp_path / f"s{every}.toml"
        run = "" if every is None else f"[run]\nprogress_every_s = {every}\nsymmetry = false\n"
        scene.write_text('name = "p"\ndim = 3\n[model]\nkind = "plug3d"\nlevels = 3\nring = 6\n'
                         '[friction]\nmu = [0.65]\n[compute]\nmu_c = "none"\n'
                         + (run or "[run]\nsymmetry = false\n"))
        p = subprocess.run(command(None, "run", str(scene), "-o", str(tmp_path / "r.h5")), env=env(),
                           capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
        wall[every] = time.monotonic() - t0
        assert p.returncode == 0, p.stderr
        lines[every] = [ln for ln in p.stderr.splitlines() if "% of the tree decided" in ln]
    assert len(lines[0.3]) >= 3 and len(lines[None]) <= wall[None] // 10.0
    shares = [float(re.search(r"([\d.]+) % of the tree decided", ln).group(1)) for ln in lines[0.3]]
    assert shares == sorted(shares)
    # the first task opens the tree's top levels: no time left told until 1 % is decided
    assert shares[0] < 100 * SHARE_GROWTH_MIN and shares[-1] > 50
    assert all("left" not in ln for ln, s in zip(lines[0.3], shares) if s < 100 * SHARE_GROWTH_MIN)
    assert any("left" in ln for ln, s in zip(lines[0.3], shares) if 100 * SHARE_GROWTH_MIN <= s < 99)


def test_guard_on_3d_pattern_stage(tmp_path):
    """The engine checks the guard after its merges: a 3D pattern run (plug3d m = 10, its
    condensed K given as a stiffness scene, so that no condensation is checked first) with
    run.max_memory_gb below what the process holds stops at the first merge, in one line
    naming the key and the stage (exit 2, nothing written)."""
    from hpcwedge.run.pipeline import condense
    from hpcwedge.scene.constructors import builtin_scene
    problem = condense(builtin_scene("plug3d")).problem
    scene = tmp_path / "s.toml"
    scene.write_text(f'name = "p"\ndim = 3\n[model]\nkind = "stiffness"\nK = {problem.K.tolist()!r}\n'
                     f'null_space = {problem.N.tolist()!r}\n[friction]\nmu = [1.0]\n'
                     '[compute]\nenumerate = true\nmu_c = "none"\n[run]\nmax_memory_gb = 0.01\n')
    out = tmp_path / "r.h5"
    p = subprocess.run(command(None, "run", str(scene), "-o", str(out), "-q"), env=env(), capture_output=True,
                       text=True, timeout=300)
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hpcwedge: error: run.max_memory_gb: the 'patterns' stage")
    assert not out.exists()
