"""Condensation onto the contact DOFs: PETSc (MUMPS / native LU) against dense numpy, by hand."""
import dataclasses
import json
import math
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from model_cases import make_model
from mpi_helpers import MPIRUN, ROOT, alive, all_gone, children, env, launch, needs_mpirun, rank_pids

from hpcwedge.contact.condense import condense, condense_distributed, schur_dense, split_dofs
from hpcwedge.models import block2d, plug2d, plug3d, truss_model, vgroove_bar


def _supported_truss(pins):
    """plug2d(3, 3) geometry as a truss with supports at the bottom middle node (node 1)."""
    m = plug2d(3, 3)
    return truss_model(m.coords, m.cells["line"], 1.0, pins, m.contact_nodes, m.normals)


CASES = {
    "plug2d-r3": lambda: plug2d(3),
    "plug2d-r4c4": lambda: plug2d(4, 4, 20.0),
    "block2d-r2f2": lambda: block2d(2, 2, 2),
    "plug3d": lambda: plug3d(),
    "plug3d-l3": lambda: plug3d(3, 4, 5.0),
    "truss-pinned": lambda: _supported_truss([[1, 0], [1, 1]]),            # k = 1 (rotation about node 1)
    "truss-held": lambda: _supported_truss([[1, 0], [1, 1], [4, 0]]),      # k = 0
    "vgroove": lambda: vgroove_bar(25.0),
    "vgroove-eps": lambda: vgroove_bar(25.0, eps=0.3),
}
K_EXPECTED = {"plug2d-r3": 3, "plug2d-r4c4": 3, "block2d-r2f2": 3, "plug3d": 6, "plug3d-l3": 6,
              "truss-pinned": 1, "truss-held": 0, "vgroove": 3, "vgroove-eps": 0}


@pytest.fixture(scope="module", params=sorted(CASES))
def case(request):
    m = CASES[request.param]()
    return request.param, m, condense(m), schur_dense(m)


def test_condensed_psd_with_rigid_null_space(case):
    name, m, (K, N), _ = case
    n = m.dim * m.m
    k = K_EXPECTED[name]
    assert K.shape == (n, n) and N.shape == (n, k)
    assert np.array_equal(K, K.T)
    np.testing.assert_allclose(N.T @ N, np.eye(k), atol=1e-13)
    if k:
        assert np.abs(K @ N).max() <= 1e-12 * np.abs(K).max()
    ev = np.linalg.eigvalsh(K)
    assert ev[0] >= -1e-12 * ev[-1]
    assert int((ev <= 1e-10 * ev[-1]).sum()) == k          # null space = rigid modes, nothing else


def test_petsc_matches_dense(case):
    name, m, (K, N), (Kd, Nd) = case
    assert np.abs(K - Kd).max() <= 1e-12 * np.abs(Kd).max()
    # same rigid subspace (bases equal up to rounding: same QR of the same T R_c)
    np.testing.assert_allclose(N @ N.T, Nd @ Nd.T, atol=1e-12)


@pytest.mark.parametrize("name", ["plug2d-r3", "block2d-r2f2", "plug3d", "truss-held"])
def test_native_petsc_lu_matches_dense(name):
    m = CASES[name]()
    K, _ = condense(m, solver="petsc")
    Kd, _ = schur_dense(m)
    assert np.abs(K - Kd).max() <= 1e-12 * np.abs(Kd).max()


def test_block_ordering_and_frames():
    # K_local = T S T^T: entry (n_i, n_j) is n_i^T S_ij n_j for the global node-major S
    m = plug2d(3)
    K, _ = schur_dense(m)
    sp_ = split_dofs(m)
    S = sp_.T.T @ K @ sp_.T                                  # back to global node-major
    i, j = 1, 4
    Sij = S[2 * i:2 * i + 2, 2 * j:2 * j + 2]
    assert math.isclose(K[i, j], m.normals[i] @ Sij @ m.normals[j], rel_tol=1e-12, abs_tol=1e-14)
    assert math.isclose(K[m.m + i, j], m.tangents[i, 0] @ Sij @ m.normals[j], rel_tol=1e-12, abs_tol=1e-14)


@pytest.mark.parametrize("eps", [0.0, 0.3])
def test_vgroove_by_hand(eps):
    th, EA = 25.0, 3.0
    k = EA / 2.0
    c, s = math.cos(math.radians(th)), math.sin(math.radians(th))
    m = vgroove_bar(th, eps=eps, EA=EA)
    K, N = condense(m)
    # block order (n1, n2, t1, t2); bar elongation = u_x2 - u_x1 = a . u_local with
    # u_x1 = c u_n1 + s u_t1 (left frame n = (c, s), t = (s, -c)),
    # u_x2 = -c u_n2 + s u_t2 (right frame n = (-c, s), t = (s, c))
    a = np.array([-c, -c, -s, s])
    np.testing.assert_allclose(K, k * np.outer(a, a) + eps * np.eye(4), atol=1e-15)
    assert N.shape == (4, 0 if eps > 0 else 3)
    # symmetric wedge: both nodes held normally, sliding down the walls -> |r_t| / r_n = mu^c
    u = np.array([0.0, 0.0, 1.0, -1.0])
    r = K @ u
    assert r[0] > 0 and math.isclose(r[0], r[1], rel_tol=1e-14)
    mu_c = math.tan(math.radians(th)) + eps / (k * math.sin(math.radians(2 * th)))
    assert math.isclose(abs(r[2]) / r[0], mu_c, rel_tol=1e-13)


def test_upward_translation_is_a_trivial_lift_off():
    # lifting the plug straight up opens every contact (u_n = sin τ > 0) at no force
    m = plug2d(2, 2, 10.0)
    K, N = condense(m)
    # upward rigid translation: in every local frame u_n = sin τ > 0 -> a trivial lift-off ray
    up = np.zeros(m.n_dofs)
    up[1::2] = 1.0
    u_loc = m.local_map() @ up[m.contact_dofs()]
    assert np.all(u_loc[:m.m] > 0)
    assert np.abs(K @ u_loc).max() < 1e-13 * np.abs(K).max()
    assert np.allclose(N @ (N.T @ u_loc), u_loc, atol=1e-13)


def test_no_interior_dofs_skips_petsc():
    m = plug2d(2, 2)                                          # every node is a contact node
    assert split_dofs(m).interior.size == 0
    K, _ = condense(m)
    T = m.local_map()
    c = m.contact_dofs()
    np.testing.assert_allclose(K, T @ m.K.toarray()[np.ix_(c, c)] @ T.T, atol=1e-15)


def _floppy_truss():
    # bottom cell braced, top row of cells without diagonals: interior nodes 7 form a mechanism
    X = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1], [0, 2], [1, 2], [2, 2]], float)
    a = 0.3
    X = X @ np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]]) * 1.37   # floating entries
    bars = [[0, 1], [1, 2], [0, 3], [1, 4], [2, 5], [3, 4], [4, 5], [0, 4], [1, 5],
            [3, 6], [4, 7], [5, 8], [6, 7], [7, 8]]
    return truss_model(X, bars, 1.0, None, [0, 1, 2], [[0, 1]] * 3)


@pytest.mark.parametrize("make", [lambda: plug3d(1, 5), _floppy_truss], ids=["flat-plug3d", "floppy-truss"])
@pytest.mark.parametrize("route", ["mumps", "petsc", "dense"])
def test_singular_interior_raises(make, route):
    m = make()
    with pytest.raises(ValueError, match=r"condense: the stiffness of the non-contact DOFs \(K_ii\) is singular"):
        schur_dense(m) if route == "dense" else condense(m, solver=route)


def test_fixed_contact_dof_rejected():
    m = plug2d(3)
    bad = dataclasses.replace(m, fixed_dofs=np.array([2 * int(m.contact_nodes[1]) + 1]))
    with pytest.raises(ValueError, match=r"model.supports: contact node 3 .* has fixed dof 1"):
        condense(bad)


def test_wrong_rigid_modes_detected():
    m = plug2d(3)
    bad = dataclasses.replace(m, rigid_modes=np.linalg.qr(np.random.default_rng(0).normal(size=(m.n_dofs, 3)))[0])
    with pytest.raises(ValueError, match=r"does not annihilate the rigid modes"):
        condense(bad)


DISTRIBUTED = {"block2d-r2c2f4": ("block2d", {"rows": 2, "cols": 2, "refine": 4}),
               "plug3d-l3r4": ("plug3d", {"levels": 3, "ring": 4, "taper_deg": 5.0}),
               "hexblock": ("hexblock", {})}
#: contact patches: rows of T^T K T from the incident elements (compared on 2 and 3 ranks)
DISTRIBUTED_PATCHED = {"block2d-foot": ("block2d", {"rows": 3, "refine": 4, "contact_patch": 0.15}),
                       "block2d-hat": ("block2d", {"rows": 3, "refine": 4, "contact_patch": 0.15,
                                                   "contact_patch_kind": "hat"}),
                       "hexblock-foot": ("hexblock", {"contact_patch": 1.05}),
                       "hexblock-hat": ("hexblock", {"contact_patch": 1.05, "contact_patch_kind": "hat"})}


def _condense_under_mpirun(tmp_path, kind, kw, ranks):
    """condense_driver.py under the real mpirun -n ranks: its npz (K, N, per-rank assembly counts)."""
    out = tmp_path / "k.npz"
    cmd = [MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks), "-x", "PYTHONPATH",
           sys.executable, os.path.join(ROOT, "tests", "condense_driver.py"), str(out), kind, json.dumps(kw)]
    p = subprocess.run(cmd, env=env(), capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    got = np.load(out)
    assert int(got["ranks"]) == ranks and float(got["spread"]) == 0.0
    return got


def _assert_rows_only(got, model, ranks):
    """No rank assembled the whole K; with several ranks each assembled a share of the elements."""
    if model.assembly is None:                     # trusses: rows sliced from the whole K
        assert list(got["full"]) == [-1] * ranks
        return
    assert list(got["full"]) == [0] * ranks
    share = got["row_elements"]
    assert np.all(share > 0)
    if ranks > 1:
        assert share.max() < int(got["n_elements"])


@pytest.mark.mpi
@needs_mpirun
@pytest.mark.parametrize("ranks", [1, 2, 3])
@pytest.mark.parametrize("name", sorted(DISTRIBUTED))
def test_distributed_matches_dense_under_mpirun(tmp_path, name, ranks):
    # condense_distributed collective over the real mpirun's world (K_ii rows split between the
    # ranks, each assembled from its own elements, parallel MUMPS): every rank gets the same
    # K_local, equal to a dense Schur complement
    kind, kw = DISTRIBUTED[name]
    got = _condense_under_mpirun(tmp_path, kind, kw, ranks)
    model = make_model(kind, kw)
    Kd, Nd = schur_dense(model)
    assert np.abs(got["K"] - Kd).max() <= 1e-10 * np.abs(Kd).max()
    np.testing.assert_allclose(got["N"] @ got["N"].T, Nd @ Nd.T, atol=1e-12)
    _assert_rows_only(got, model, ranks)


@pytest.mark.mpi
@needs_mpirun
@pytest.mark.parametrize("ranks", [2, 3])
@pytest.mark.parametrize("name", sorted(DISTRIBUTED_PATCHED))
def test_distributed_patched_matches_serial_under_mpirun(tmp_path, name, ranks):
    kind, kw = DISTRIBUTED_PATCHED[name]
    got = _condense_under_mpirun(tmp_path, kind, kw, ranks)
    model = make_model(kind, kw)
    assert model.tie is not None
    K, N = condense(model)
    assert np.abs(got["K"] - K).max() <= 1e-10 * np.abs(K).max()
    np.testing.assert_allclose(got["N"] @ got["N"].T, N @ N.T, atol=1e-12)
    Kd, _ = schur_dense(model)
    assert np.abs(got["K"] - Kd).max() <= 1e-10 * np.abs(Kd).max()
    _assert_rows_only(got, model, ranks)


def test_distributed_without_comm_is_condense():
    m = block2d(2, 2, 2)
    K, N = condense_distributed(m, None)
    K0, N0 = condense(m)
    assert np.array_equal(K, K0) and np.array_equal(N, N0)


PLUG_SCENE = """name = "plug-dist"
dim = 2
[model]
kind = "plug2d"
rows = 4
[friction]
mu = [0.65, 1.0]
[compute]
enumerate = "patterns"
mu_c = "cones"
[run]
condense = "{mode}"
"""


@pytest.mark.mpi
@needs_mpirun
def test_run_condense_distributed_on_the_command_line(tmp_path):
    # run.condense = "distributed" under mpirun -n 2: the same answers as a serial run (the
    # condensed K agrees to rounding, so mu^c values to ~1e-12)
    from mpi_helpers import run, show
    outs = {}
    for ranks, mode in [(None, "serial"), (2, "distributed")]:
        scene = tmp_path / f"{mode}.toml"
        scene.write_text(PLUG_SCENE.format(mode=mode))
        outs[mode] = str(tmp_path / f"{mode}.h5")
        run(ranks, "run", str(scene), "-o", outs[mode], "-q", timeout=120)
    a, b = show(outs["serial"]), show(outs["distributed"])
    assert b["mu_c"] == pytest.approx(a["mu_c"], rel=1e-10)
    assert len(a["runs"]) == len(b["runs"]) == 2
    for ra, rb in zip(a["runs"], b["runs"]):
        assert [p["contact"] for p in ra["patterns"]] == [p["contact"] for p in rb["patterns"]]
        assert [p["mu_c"] for p in rb["patterns"]] == pytest.approx([p["mu_c"] for p in ra["patterns"]], rel=1e-10)
        assert len(ra["patterns"]) > 0


@pytest.mark.mpi
@needs_mpirun
def test_run_condense_distributed_singular_exit_2_once(tmp_path):
    # a singular K_ii found collectively: one message from the master, status 2, no hang
    from mpi_helpers import run
    scene = tmp_path / "flat.toml"
    scene.write_text('name = "flat"\ndim = 3\n[model]\nkind = "plug3d"\nlevels = 1\n'
                     '[friction]\nmu = [1.0]\n[run]\ncondense = "distributed"\n')
    p = run(2, "run", str(scene), "-o", str(tmp_path / "r.h5"), timeout=60, check=False)
    assert p.returncode == 2, p.stderr
    assert p.stderr.count("hpcwedge: error: model: condense: the stiffness of the non-contact DOFs") == 1


def test_run_condense_key_checked():
    from hpcwedge.scene.parse import parse_scene
    from hpcwedge.scene.values import SceneError
    base = {"name": "p", "dim": 2, "model": {"kind": "plug2d"}, "friction": {"mu": 1.0}}
    assert parse_scene(base).condense == "auto"
    assert parse_scene({**base, "run": {"condense": "distributed"}}).condense == "distributed"
    with pytest.raises(SceneError, match=r"run.condense: one of auto, serial, distributed, got 'mumps'"):
        parse_scene({**base, "run": {"condense": "mumps"}})


@pytest.mark.parametrize("user, expected", [(None, "ob1"), ("^ucx", "^ucx")])
def test_serial_petsc_starts_mpi_with_the_ob1_layer_unless_the_user_chose(user, expected):
    """A serial run's PETSc starts MPI as a singleton with Open MPI's ob1 message layer
    (its default probes UCX's devices first, for nothing); OMPI_MCA_pml set by the user
    stands. The condensation's answer is the same either way."""
    env = {k: v for k, v in os.environ.items() if k != "OMPI_MCA_pml" and not k.startswith(("OMPI_COMM", "PMIX"))}
    if user is not None:
        env["OMPI_MCA_pml"] = user
    code = ("import os, json; from hpcwedge.contact.condense import condense; from hpcwedge.models import plug3d; "
            "K, N = condense(plug3d(levels=2, ring=3)); "
            "print(json.dumps([os.environ.get('OMPI_MCA_pml'), float(abs(K).sum())]))")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    pml, size = json.loads(out.stdout.strip().splitlines()[-1])
    assert pml == expected
    K, _ = condense(plug3d(levels=2, ring=3))
    assert size == pytest.approx(float(abs(K).sum()), rel=1e-12)


def test_a_condensation_in_a_child_gives_the_bits_of_one_made_here_and_its_errors():
    """Above CHILD_MIN_DOFS a serial process that has not started PETSc factors K_ii in a forked
    child (forked.in_child), above SPAWN_MIN_DOFS one that has (an MPI run's master) in a spawned interpreter
    (forked.in_spawned): K_local bit for bit as condensed in the process itself, and
    interior_response too; a singular K_ii's error comes back the same. Run in a fresh
    interpreter, as a serial run is (the suite's own process has PETSc started)."""
    code = """
import json, sys
import numpy as np
from hpcwedge.contact import condense as C
from hpcwedge.models import block2d, plug3d
m = block2d(3, 2, 6)
uc = np.linspace(-1.0, 1.0, 2 * len(m.contact_nodes))
out = []
routes = []
spawned = C.forked.in_spawned
def counted(*args, **kwargs):
    routes[-1] += 1
    return spawned(*args, **kwargs)
C.forked.in_spawned = counted
for limit in (0, 10 ** 9, 0):           # forked (PETSc not started here), here, spawned
    C.CHILD_MIN_DOFS = C.SPAWN_MIN_DOFS = limit
    routes.append(0)
    K, N = C.condense(m)
    u = C.interior_response(m, uc)
    try:
        C.condense(plug3d(1, 5))
        err = None
    except ValueError as e:
        err = str(e)
    out.append([K.tobytes().hex(), N.tobytes().hex(), u.tobytes().hex(), err, "petsc4py.PETSc" in sys.modules])
print(json.dumps([out, routes]))
"""
    out = subprocess.run([sys.executable, "-c", code], env=env(), capture_output=True, text=True, timeout=300,
                         stdin=subprocess.DEVNULL)
    assert out.returncode == 0, out.stderr
    (forked, here, spawned), routes = json.loads(out.stdout.strip().splitlines()[-1])
    assert not forked[-1] and here[-1]     # the first calls ran in forked children, then here
    assert routes == [0, 0, 3]             # the last ones in spawned children
    assert forked[:4] == here[:4] == spawned[:4]
    assert forked[3].startswith("condense: the stiffness of the non-contact DOFs (K_ii) is singular")


def _big_block2d(tmp_path):
    """A block2d of 290,000 DOFs (seconds of condensation; below run.condense's distributed size)."""
    scene = tmp_path / "big.toml"
    scene.write_text('name = "big"\ndim = 2\n[model]\nkind = "block2d"\nrows = 5\ncols = 2\nrefine = 120\n'
                     '[friction]\nmu = [0.65]\n[compute]\nmu_c = "none"\n')
    return scene


@pytest.mark.parametrize("ranks", [None, pytest.param(2, marks=[pytest.mark.mpi, needs_mpirun])],
                         ids=["serial", "mpirun-2"])
def test_sigterm_while_a_child_condenses_ends_the_run_within_2_s(tmp_path, ranks):
    """`hpcwedge run` of a block2d of 290,000 DOFs, signalled while a child process factors K_ii
    (seconds of PETSc that keep the interpreter's lock: before, a SIGTERM waited up to 30 s for
    them). Serially the child is forked; under mpirun -n 2 the master condenses alone in a
    spawned interpreter (MPI and PETSc are started in it, so no fork; before: 8 s measured on
    refine 160) and SIGTERM goes to every rank, as SLURM sends it. The run (its master) exits
    within 2 s, with 75, its one line and no traceback, and the child is gone."""
    p = launch(ranks, "run", str(_big_block2d(tmp_path)), "-o", str(tmp_path / "r.h5"))
    try:
        pids = {0: p.pid} if ranks is None else rank_pids(p.pid, ranks)
        kids = _condensing_children(p, pids[0], spawned=ranks is not None)
        assert kids, "no child process seen while condensing"
        _stop_and_check(p, pids)
        assert all_gone(kids)
    finally:
        p.kill()
        p.wait()


@pytest.mark.mpi
@needs_mpirun
def test_sigterm_during_a_collective_condensation_ends_the_master_within_2_s(tmp_path):
    """mpirun -n 2 with run.condense = "distributed": MUMPS factors K_ii over both ranks, a call
    no child process can make. KSPSetUp and MatMatSolve go through ctypes in a thread
    (factor._released), so the master serves SIGTERM within a step (before: 5.7 s on refine
    160, the rest of the factorisation). The thread shows as one more task of the master
    (counted in /proc) once its count has settled after MPI's start: SIGTERM to every rank
    then; the master exits within 2 s, mpirun 75, one line, no traceback."""
    scene = _big_block2d(tmp_path)
    scene.write_text(scene.read_text() + '[run]\ncondense = "distributed"\n')
    p = launch(2, "run", str(scene), "-o", str(tmp_path / "r.h5"))
    try:
        ranks = rank_pids(p.pid, 2)
        master = ranks[0]
        deadline = time.monotonic() + 120
        last, since, settled, in_call = None, time.monotonic(), None, False
        while not in_call and p.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
            try:
                count, now = len(os.listdir(f"/proc/{master}/task")), time.monotonic()
            except OSError:                      # the run ended
                break
            if count != last:
                in_call = settled is not None and count > settled
                last, since = count, now
            elif settled is None and count > 1 and now - since > 0.5:
                settled = count
        assert in_call, "the master's released PETSc call was not seen"
        _stop_and_check(p, ranks)
    finally:
        p.kill()
        p.wait()


def _stop_and_check(p: subprocess.Popen, pids: dict[int, int]) -> None:
    """SIGTERM to every process of the run ({rank: pid}; serially {0: the run}): the master
    (rank 0) exits within 2 s, the run with 75, the master's one line on stderr, no traceback."""
    start = time.monotonic()
    for pid in pids.values():
        os.kill(pid, signal.SIGTERM)
    while alive(pids[0]) and time.monotonic() - start < 60:
        time.sleep(0.01)
    assert time.monotonic() - start < 2.0
    _, err = p.communicate(timeout=60)
    assert p.returncode == 75, err
    assert "[hpcwedge] SIGTERM: checkpoint written to" in err, err
    assert "Traceback" not in err, err


def _condensing_children(p: subprocess.Popen, parent: int, spawned: bool = False) -> list[int]:
    """The child processes of `parent` (spawned: only forked.in_spawned's) once there are any,
    while the run p goes on (at most 120 s); [] if none appeared."""
    deadline = time.monotonic() + 120
    while p.poll() is None and time.monotonic() < deadline:
        kids = [k for k in children(parent) if not spawned or _is_spawned_child(k)]
        if kids:
            return kids
        time.sleep(0.02)
    return []


def _is_spawned_child(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return b"hpcwedge.forked" in f.read()
    except OSError:
        return False
