"""The master/worker engine: the same answers serially, in-process and under the
real mpirun with 1-4 ranks; subtrees really move (budgets, hand-backs); the 2D
rays split over faces (tasks "face") give the unsplit answers and survive a
checkpoint (bit for bit on 1-4 ranks: tests/test_determinism.py); idle ranks sleep
(CPU time from /proc); 2D sign patterns agree with
the rays; the SLURM_NTASKS check."""
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from hpcwedge import parallel
from hpcwedge.dd import complementary_rays
from hpcwedge.faces import branching_nodes, face_task, run_faces
from hpcwedge.mu_critical import mu_critical, run_mu_c
from hpcwedge.nodesets import canonical_order, pattern_key, to_bits
from hpcwedge.parallel.checkpoint import CheckpointError, read_checkpoint
from hpcwedge.nodesets import bits_to_words, words_to_bits
from hpcwedge.patterns import PatternTree, explore_task, run_patterns, sign_patterns
from hpcwedge.pipeline import run_scene
from hpcwedge.problem import friction_rows_2d, parametrize
from hpcwedge.scene import parse_scene
from instances import random_problem
from mpi_helpers import (MPIRUN, ROOT, THREADS_1, THREADS_2, THREADS_UNSET, answers, env, needs_mpirun, run, show,
                         show_json, write_scene)


def _tree_factory(seed, m=5, free=False):
    prob = random_problem(np.random.default_rng(seed), m, free=free)
    from functools import partial
    return partial(PatternTree, parametrize(prob), m), prob


# ---------------------------------------------------------------- in-process


@pytest.mark.parametrize("seed,budget", [(0, 1), (1, 3), (2, 1000)])
def test_run_patterns_equals_serial_search(seed, budget):
    make, prob = _tree_factory(700 + seed, free=bool(seed % 2))
    mus = [0.5, 2.0, 8.0]
    out = run_patterns(make, mus, budget=budget)
    for k, mu in enumerate(mus):
        tree = make(mu)
        whole = tree.explore(tree.root())
        # the engine's order is the one canonical order (nodesets.pattern_key), whatever the split
        assert out.found[k] == sorted(whole.found, key=lambda s: pattern_key(s.contact))
        masks = [s.masks(tree.m) for s in out.found[k]]
        ref = sorted(sign_patterns(tree.param, tree.m, mu), key=lambda ab: pattern_key(to_bits(np.flatnonzero(ab[0]))))
        assert [(a.tolist(), b.tolist()) for a, b in masks] == [(a.tolist(), b.tolist()) for a, b in ref]
    # every tree node is visited exactly once, however the work is split
    nodes = sum(make(mu).explore(make(mu).root()).stats.nodes for mu in mus)
    assert out.counters["nodes"] == nodes
    if budget == 1:
        assert out.counters["handed_back"] > 0


def test_subtree_job_checkpoint_state_round_trip():
    """Stop a job half-way with tasks 'in flight', save, load into a fresh job,
    finish: the same patterns and node count as one pass."""
    make, _ = _tree_factory(31, m=6)
    mus = [1.0, 4.0]
    ref = run_patterns(make, mus, budget=2)
    job = parallel.SubtreeJob("p", make, mus, budget=2)
    handler = parallel.handler_for("subtree")
    in_flight = []
    for _ in range(7):
        token, payload = job.take(1)
        job.merge(token, handler(job.context, payload))
    for _ in range(2):                                    # taken, never merged
        token, _ = job.take(1)
        in_flight.append(token)
    state = job.save(in_flight)
    again = parallel.SubtreeJob("p", make, mus, budget=2)
    again.load(state)
    again.counters.update({k: v for k, v in job.counters.items()})
    out = parallel.Engine().run(again).output()
    assert out.found == ref.found
    assert out.counters["nodes"] == ref.counters["nodes"]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGUSR1])
def test_engine_signal_checkpoint_resume_in_process(tmp_path, sig):
    """A signal in the middle of a job (sent by a task to its own process):
    SIGTERM -> Interrupted at the next safe point, checkpoint, a new engine
    resumes; SIGUSR1 -> a checkpoint and the job goes on. Same patterns, every
    tree node counted once."""
    make, _ = _tree_factory(41, m=6)
    mus = [1.0, 4.0]
    ref = run_patterns(make, mus, budget=2)
    ckpt = str(tmp_path / "x.ckpt")
    calls = []

    def task(ctx, payload):
        calls.append(1)
        if len(calls) == 5:
            os.kill(os.getpid(), sig)
        return explore_task(ctx, payload)

    eng = parallel.Engine()
    eng.use_checkpoint(ckpt, "hash", "scene", 1000.0, resume=False)
    eng.install_signals()
    try:
        with parallel.registered("subtree", task):
            if sig == signal.SIGTERM:
                with pytest.raises(parallel.Interrupted):
                    run_patterns(make, mus, engine=eng, budget=2)
                assert eng.write_checkpoint("SIGTERM")
            else:
                out = run_patterns(make, mus, engine=eng, budget=2)
                assert eng.checkpoints_written == 1 and eng.checkpoint_reason == "SIGUSR1"
    finally:
        eng.close()
    if sig == signal.SIGTERM:
        assert len(calls) == 5                          # stopped at the safe point after the 5th task
        eng = parallel.Engine()
        assert eng.use_checkpoint(ckpt, "hash", "scene", 1000.0, resume=True)
        out = run_patterns(make, mus, engine=eng, budget=2)
        with pytest.raises(CheckpointError, match="another scene"):
            parallel.Engine().use_checkpoint(ckpt, "other", "scene", 1000.0, resume=True)
    assert out.found == ref.found and out.counters["nodes"] == ref.counters["nodes"]


def test_bit_words_beyond_64_nodes():
    vals = [0, 1, (1 << 64) | 5, (1 << 130) - 1, 1 << 127]
    words = bits_to_words(vals, 3)
    assert words.shape == (5, 3) and words.dtype == np.uint64
    assert words_to_bits(words) == vals
    assert words_to_bits(np.zeros((0, 1), dtype=np.uint64)) == []


def test_run_mu_c_equals_direct_calls():
    rng = np.random.default_rng(5)
    m = 4
    param = parametrize(random_problem(rng, m, free=False))
    from functools import partial
    items = []
    for zu_bits in range(1, 1 << m, 3):
        zu = np.array([(zu_bits >> i) & 1 for i in range(m)], dtype=bool)
        items.append((zu, ~zu, 50.0))
    got = run_mu_c(partial(mu_critical, param, m, mu_max=100.0), items)
    for (zu, zr, mu_hi), r in zip(items, got):
        want = mu_critical(param, m, zu, zr, mu_hi=mu_hi, mu_max=100.0)
        assert (r.mu_c, r.polished, r.solves, r.undecided) == (want.mu_c, want.polished, want.solves, want.undecided)


def test_task_job_state_round_trip_with_arrays():
    job = parallel.TaskJob("t", "x", None, list(range(5)))
    for k, res in [(0, {"a": 1.5, "v": np.arange(3.0)}), (3, {"a": -2.0, "v": np.zeros((0,))}),
                   (4, {"a": 7.0, "v": np.ones(2)})]:
        job.merge(k, res)
    again = parallel.TaskJob("t", "x", None, list(range(5)))
    again.load({"attrs": job.save([])["attrs"], "data": job.save([])["data"]})
    assert again.pending() == 2 and [again.take(1)[0], again.take(1)[0]] == [1, 2]
    assert again.results[0]["a"] == 1.5 and again.results[0]["v"].tolist() == [0, 1, 2]
    assert again.results[3]["v"].tolist() == [] and again.results[4]["v"].tolist() == [1, 1]


def test_worker_error_in_serial_mode_propagates():
    parallel.register("boom", lambda ctx, p: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        parallel.run_tasks("boom", None, [1])


def _plug_rows(rows: int, mus, exact: bool = False):
    """friction_rows_2d of plug2d (rows x 3, taper 10 deg) at every mu; m = 2 rows."""
    from hpcwedge.condense import condense
    from hpcwedge.models.library import plug2d
    from hpcwedge.problem import ContactProblem
    param = parametrize(ContactProblem(2, *condense(plug2d(rows, 3, 10.0))), exact=exact)
    return [friction_rows_2d(param, mu, 2 * rows, exact=exact) for mu in mus]


def test_branching_nodes():
    assert branching_nodes(16) == [13, 14, 15] and branching_nodes(15) == []    # "auto"
    assert branching_nodes(12, 2) == [10, 11] and branching_nodes(12, 0) == []
    assert branching_nodes(3, 4) == [1, 2] and branching_nodes(1, 4) == []


@pytest.mark.parametrize("exact", [False, True])
def test_face_tasks_checkpoint_resume_in_process(tmp_path, exact):
    """run_faces gives the unsplit DD's zero flags (and, exact, its rays). SIGTERM
    during the 5th face task: the task is dropped at its first task_tick(), the
    checkpoint holds the 4 finished faces (HDF5 round trip: float rays, exact ones
    as decimal strings), and a resumed engine asked for another split (as another
    rank count would choose) keeps the saved one, runs only the 12 missing faces
    and gives bit for bit the uninterrupted answer."""
    rows_n, nodes = (3, [3, 4, 5]) if exact else (5, [7, 8, 9])
    m, mus = 2 * rows_n, [0.65, 1.0]
    rows = _plug_rows(rows_n, mus, exact)
    ref = run_faces(rows, m, exact, nodes=nodes)
    for A, dd in zip(rows, ref):
        full = complementary_rays(A, m, exact=exact)
        order = canonical_order(full.zero)
        assert dd.stats["faces"] == 8 and dd.stats["branching_nodes"] == nodes
        assert np.array_equal(dd.zero, full.zero[order])
        if exact:
            assert dd.X.dtype == object and np.array_equal(dd.X, full.X[order])
        else:
            assert np.allclose(dd.X, full.X[order], rtol=0, atol=1e-11)
    ckpt = str(tmp_path / "f.ckpt")
    calls, kill_at = [], [5]

    def task(ctx, payload):
        calls.append(payload)
        if len(calls) in kill_at:
            os.kill(os.getpid(), signal.SIGTERM)
        return face_task(ctx, payload)

    eng = parallel.Engine(tick_every_s=0.0)                # cancel at the first tick
    eng.use_checkpoint(ckpt, "hash", "scene", 1000.0, resume=False)
    eng.install_signals()
    try:
        with parallel.registered("face", task), pytest.raises(parallel.Interrupted):
            run_faces(rows, m, exact, engine=eng, nodes=nodes)
        assert eng.write_checkpoint("SIGTERM")
    finally:
        eng.close()
    saved = read_checkpoint(ckpt)["jobs"]["rays"]
    assert not saved["attrs"]["finished"]
    assert saved["data"]["done"].tolist() == [0, 1, 2, 3]
    assert saved["data"]["X"].dtype.kind == ("S" if exact else "f")
    assert json.loads(saved["attrs"]["layout"]) == {"branching_nodes": nodes}
    calls.clear()
    kill_at.clear()
    eng = parallel.Engine()
    assert eng.use_checkpoint(ckpt, "hash", "scene", 1000.0, resume=True) and eng.restored("rays")
    with parallel.registered("face", task):
        out = run_faces(rows, m, exact, engine=eng, nodes=[m - 1])
    assert len(calls) == 2 * 8 - 4
    for a, b in zip(out, ref):
        assert a.stats["branching_nodes"] == nodes and a.stats["faces"] == 8
        assert np.array_equal(a.zero, b.zero) and np.array_equal(a.X, b.X) and a.X.dtype == b.X.dtype
    # without payloads_for, another layout is refused
    with pytest.raises(CheckpointError, match="layout"):
        job = parallel.TaskJob("rays", "face", None, [], layout={"branching_nodes": [1]})
        job.load(read_checkpoint(ckpt)["jobs"]["rays"])


@pytest.mark.parametrize("rows,taper,mus", [(2, 10.0, [0.2, 0.65]), (3, 10.0, [0.65]),
                                            (3, 31.0, [0.62, 2.0]), (4, 20.0, [0.5])])
def test_2d_patterns_agree_with_rays(rows, taper, mus):
    """SPEC §2: (C, G) is feasible iff some wedged ray has supp(r_n) in C and
    supp(u_n) in G — the engine's patterns against the double description's rays."""
    from hpcwedge.reference import patterns_of_supports

    def scene(enum):
        return parse_scene({"name": "t", "dim": 2, "model": {"kind": "plug2d", "rows": rows, "taper_deg": taper},
                            "friction": {"mu": mus}, "compute": {"enumerate": enum, "mu_c": "cones"},
                            "run": {"task_budget": 3}})
    pat, ray = run_scene(scene("patterns")), run_scene(scene(True))
    m = pat.m
    assert pat.stages == ["condense", "enumerate", "mu_c"]
    assert abs(pat.mu_c - ray.mu_c) <= 1e-9 * ray.mu_c
    for rp, rr in zip(pat.runs, ray.runs):
        assert rp.rays is None and rp.cones is None and rr.patterns is None
        un, rn = rr.rays[:, :m], rr.rays[:, 2 * m:3 * m]
        scale = np.abs(rr.rays).max(axis=1, keepdims=True)
        supp_u, supp_r = np.abs(un) > 1e-9 * scale, np.abs(rn) > 1e-9 * scale
        want = [[i for i in range(m) if bits >> i & 1]                   # canonical: by contact bits
                for bits in sorted(patterns_of_supports(supp_r, supp_u, m))]
        assert [p["contact"] for p in rp.patterns] == want
        for p in rp.patterns:               # a pattern's mu^c: at most the run's mu, at least the global one
            assert ray.mu_c * (1 - 1e-9) <= p["mu_c"] <= rp.mu * (1 + 1e-9)


def test_plan_patterns_2d():
    s = parse_scene({"name": "t", "dim": 2, "model": {"kind": "plug2d"}, "friction": {"mu": [1.0]},
                     "compute": {"enumerate": "patterns"}})
    p = s.plan()
    assert p.patterns and not p.rays and not p.cones and s.task_budget == 64


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
