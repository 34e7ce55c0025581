"""kind = "matrix": a stiffness assembled outside hpcwedge (scikit-fem plane stress in 2D, a
truss in 3D), read from MatrixMarket, .npz and PETSc binary, against the same body condensed
by dense numpy and given as kind = "stiffness" (tests/matrix_bodies.py)."""
import os

import numpy as np
import pytest
import scipy.sparse as sp
from matrix_bodies import matrix_scene, plug_2d, plug_3d, stiffness_scene, write_matrix
from mpi_helpers import needs_mpirun, run, show_json

from hpcwedge import api
from hpcwedge.models.matrix import check_stiffness, largest_entry, read_nodes, read_stiffness
from hpcwedge.scene.parse import load_scene

REL = 1e-9
FORMATS = ("mtx", "npz", "petsc")


@pytest.fixture(scope="module")
def body2d():
    return plug_2d()


@pytest.fixture(scope="module")
def reference2d(tmp_path_factory, body2d):
    return api.solve(stiffness_scene(tmp_path_factory.mktemp("ref2d"), body2d))


def _cones(result):
    """Per run: {zero_u of the cone: its mu^c} and the counts of wedged rays and cones."""
    return [({tuple(c.zero_u): c.mu_c for c in run.cones}, len(run.rays), len(run.cones)) for run in result.runs]


def _same_2d(got, ref):
    assert got.mu_c == pytest.approx(ref.mu_c, rel=REL)
    for (cones, rays, n), (cones_ref, rays_ref, n_ref) in zip(_cones(got), _cones(ref)):
        assert (rays, n) == (rays_ref, n_ref)
        assert cones.keys() == cones_ref.keys()
        for key, mu_c in cones_ref.items():
            assert (cones[key] is None) == (mu_c is None)
            if mu_c is not None:
                assert cones[key] == pytest.approx(mu_c, rel=REL)


@pytest.mark.parametrize("fmt", FORMATS)
def test_2d_formats_give_the_condensed_routes_answers(tmp_path, body2d, reference2d, fmt):
    got = api.solve(matrix_scene(tmp_path, body2d, fmt))
    assert sum(n for _, _, n in _cones(reference2d)) > 1            # cones to compare
    _same_2d(got, reference2d)


def test_3d_truss_as_a_matrix_gives_the_condensed_routes_answers(tmp_path):
    body = plug_3d()
    got = api.solve(matrix_scene(tmp_path, body, "petsc", mu=(0.6,)))
    ref = api.solve(stiffness_scene(tmp_path, body, mu=(0.6,)))
    assert got.mu_c == pytest.approx(ref.mu_c, rel=REL)
    pats = {tuple(p.contact): p.mu_c for p in got.runs[0].patterns}
    pats_ref = {tuple(p.contact): p.mu_c for p in ref.runs[0].patterns}
    assert pats.keys() == pats_ref.keys() and len(pats) > 1
    for key, mu_c in pats_ref.items():
        assert pats[key] == pytest.approx(mu_c, rel=REL)


def _answers(path):
    d = show_json(path, rays=False)
    return d["mu_c"], [[(c["zero_u"], c["mu_c"]) for c in r.get("cones") or []] +
                       [(p["contact"], p["mu_c"]) for p in r.get("patterns") or []] for r in d["runs"]]


@pytest.mark.mpi
@needs_mpirun
@pytest.mark.parametrize("fmt,condense", [("petsc", "distributed"), ("mtx", "distributed"), ("npz", "serial")])
def test_2d_under_mpirun_n3(tmp_path, body2d, fmt, condense):
    # under mpirun -n 3 (PETSc binary: each rank MatLoads its third of the rows) the answers of
    # the condensed-K route run serially
    ref = str(tmp_path / "ref.h5")
    run(None, "run", stiffness_scene(tmp_path, body2d), "-o", ref, "-q")
    out = str(tmp_path / "m.h5")
    run(3, "run", matrix_scene(tmp_path, body2d, fmt, extra=f'[run]\ncondense = "{condense}"\n'), "-o", out, "-q",
        timeout=300)
    _compare(_answers(out), _answers(ref))


@pytest.mark.mpi
@needs_mpirun
def test_3d_truss_under_mpirun_n3_distributed(tmp_path):
    body = plug_3d()
    ref = str(tmp_path / "ref.h5")
    run(None, "run", stiffness_scene(tmp_path, body, mu=(0.6,)), "-o", ref, "-q")
    out = str(tmp_path / "m.h5")
    run(3, "run", matrix_scene(tmp_path, body, "petsc", mu=(0.6,), extra='[run]\ncondense = "distributed"\n'),
        "-o", out, "-q", timeout=300)
    _compare(_answers(out), _answers(ref))


def _compare(got, ref):
    assert got[0] == pytest.approx(ref[0], rel=REL)
    for a, b in zip(got[1], ref[1]):
        assert [k for k, _ in a] == [k for k, _ in b] and a
        assert [v for _, v in a] == pytest.approx([v for _, v in b], rel=REL)


def test_the_three_formats_read_the_same_matrix(tmp_path, body2d):
    K = body2d[0]
    for fmt, rel in (("mtx", 1e-15), ("npz", 0)):
        # symmetric storage keeps one triangle: skfem's K is symmetric to rounding only
        write_matrix(K, tmp_path / f"k.{fmt}")
        assert abs(read_stiffness(str(tmp_path / f"k.{fmt}"), "k") - K).max() <= rel * abs(K).max()
    write_matrix(K, tmp_path / "k.petsc")
    from hpcwedge.contact.condense import load_petsc
    assert abs(load_petsc(str(tmp_path / "k.petsc")) - K).max() == 0
    # the streamed largest entry of the PETSc file against scipy's
    assert largest_entry(str(tmp_path / "k.petsc")) == abs(K).max()


def test_nodes_csv_with_and_without_header_npy_and_inline(tmp_path):
    X = np.array([[0.0, 1.5], [2.0, -1.0], [3.25, 0.5]])
    (tmp_path / "h.csv").write_text("x,y\n" + "\n".join(f"{a},{b}" for a, b in X))
    (tmp_path / "n.csv").write_text("\n".join(f"{a},{b}" for a, b in X))
    np.save(tmp_path / "n.npy", X)
    for value in ("h.csv", "n.csv", "n.npy", X.tolist()):
        assert np.array_equal(read_nodes(value, str(tmp_path), 2), X)
    with pytest.raises(ValueError, match="model.nodes: expected"):
        read_nodes(X.tolist(), str(tmp_path), 3)


def test_check_stiffness_symmetrises_and_refuses():
    K = sp.csr_matrix(np.array([[2.0, -1.0], [-1.0 + 1e-14, 2.0]]))
    S = check_stiffness(K, 2)
    assert abs(S - S.T).max() == 0 and abs(S - K).max() <= 1e-14
    for bad, what in [(np.array([[1.0, 2.0], [0.0, 1.0]]), "not symmetric"), (np.zeros((2, 2)), "all zero"),
                      (np.array([[np.nan, 0], [0, 1.0]]), "NaN"), (np.ones((2, 3)), "square")]:
        with pytest.raises(ValueError, match=f"model.K: .*{what}"):
            check_stiffness(sp.csr_matrix(bad), 2)
    with pytest.raises(ValueError, match="size 2, expected dim x nodes = 4"):
        check_stiffness(K, 4)


def test_the_identity_covers_every_file(tmp_path, body2d):
    path = matrix_scene(tmp_path, body2d, "mtx", extra="")
    scene = load_scene(path)
    assert [os.path.basename(f) for f in scene.input_files] == ["body.mtx", "nodes.csv"]
    before = scene.input_digests
    assert set(before) == {"model.K body.mtx", "model.nodes nodes.csv"}
    with open(tmp_path / "nodes.csv", "a") as f:
        f.write("\n")
    assert load_scene(path).input_digests["model.nodes nodes.csv"] != before["model.nodes nodes.csv"]
    assert load_scene(path).input_digests["model.K body.mtx"] == before["model.K body.mtx"]


def _with_isolated_node(body):
    """body with one more node, not connected to anything: two zero modes beyond the rigid ones."""
    K, X, contact, normals = body
    return sp.block_diag([K, sp.csr_matrix((2, 2))]).tocsr(), np.vstack([X, [0.0, 0.5]]), contact, normals


def _bad_cases(body):
    K, X, contact, normals = body
    n = K.shape[0]
    asym = K.tolil()
    asym[0, 1] += 1e-3 * abs(K).max()
    nan = K.tolil()
    nan[3, 3] = np.nan
    grounded = K + sp.csr_matrix(([abs(K).max()], ([0], [0])), shape=K.shape)
    return {
        "missing file": ({"K": "nothere.mtx"}, None, "model.K: nothere.mtx not found"),
        "garbage .mtx": ({}, ("body.mtx", b"%%MatrixMarket garbage\n"), "model.K: cannot read body.mtx"),
        "garbage .petsc": ({"K": "body.petsc"}, ("body.petsc", b"\x00" * 64), "model.K: body.petsc is not a PETSc"),
        "unknown format": ({"K": "body.txt"}, ("body.txt", b"1 2\n"), "model.K: body.txt: unsupported"),
        "not square": ({"K": "k.npz"}, ("k.npz", sp.random(n, n + 2, density=0.1)), "model.K: must be square"),
        "wrong size": ({"K": "k.npz"}, ("k.npz", sp.eye(n + 2)), f"model.K: size {n + 2}, expected dim x nodes"),
        "not symmetric": ({"K": "k.npz"}, ("k.npz", asym.tocsr()), "model.K: not symmetric"),
        "NaN": ({"K": "k.npz"}, ("k.npz", nan.tocsr()), "model.K: NaN"),
        "grounded without supports": ({"K": "k.npz"}, ("k.npz", grounded), "model.K: does not annihilate"),
        "nodes missing": ({"nodes": "nothere.csv"}, None, "model.nodes: nothere.csv not found"),
        "node out of range": ({"contact.nodes": [len(X)] + contact[1:].tolist()}, None,
                              f"contact.nodes: node {len(X)} does not exist"),
        "normals count": ({"contact.normals": normals[1:].tolist()}, None, "contact.normals: expected shape"),
    }


def _bad_scene(tmp_path, body, change, content):
    path = matrix_scene(tmp_path, body, "mtx")
    text = open(path).read()
    for key, value in change.items():
        table, _, name = key.rpartition(".")
        old = next(ln for ln in text.splitlines() if ln.startswith(f"{name} = ") and
                   text.index(ln) > text.index(f"[{table or 'model'}]"))
        text = text.replace(old, f"{name} = {value!r}".replace("'", '"'))
    open(path, "w").write(text)
    if content is not None:
        name, data = content
        if isinstance(data, bytes):
            (tmp_path / name).write_bytes(data)
        else:
            write_matrix(data, tmp_path / name)
    return path


@pytest.mark.parametrize("case", list(_bad_cases(plug_2d(2, 1))))
def test_bad_input_is_one_line_exit_2_nothing_written(tmp_path, capsys, case):
    from hpcwedge.cli import main
    body = plug_2d(2, 1)
    change, content, message = _bad_cases(body)[case]
    path = _bad_scene(tmp_path, body, change, content)
    out = tmp_path / "r.h5"
    capsys.readouterr()
    assert main(["run", path, "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not [f for f in os.listdir(tmp_path) if f.startswith("r.h5")]


@pytest.mark.parametrize("fmt", ["mtx", "petsc"])
def test_a_mechanism_names_its_extra_zero_modes(tmp_path, capsys, fmt):
    from hpcwedge.cli import main
    path = matrix_scene(tmp_path, _with_isolated_node(plug_2d(2, 1)), fmt)
    capsys.readouterr()
    assert main(["run", path, "-o", str(tmp_path / "r.h5"), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "model.K" in err[0] and "2 null pivot(s)" in err[0], err


def _distributed_bad(body, case):
    """(body, message) of a bad PETSc binary K for the distributed checks (condense._check_loaded)."""
    K, X, contact, normals = body
    if case == "mechanism":
        return _with_isolated_node(body), "2 null pivot(s)"
    K = K.tolil()
    if case == "not symmetric":
        K[0, 1] += 1e-3 * abs(K).max()
    elif case == "NaN":
        K[3, 3] = np.nan
    else:                                   # a spring to ground that no support lists
        K[0, 0] += abs(K).max()
    return (K.tocsr(), X, contact, normals), {"grounded": "does not annihilate"}.get(case, case)


@pytest.mark.mpi
@needs_mpirun
@pytest.mark.parametrize("case", ["mechanism", "not symmetric", "NaN", "grounded"])
def test_bad_matrix_distributed_is_one_line_exit_2(tmp_path, case):
    # checked on the ranks' rows (no rank holds the whole K): one message from the master
    # (mpirun adds its MPI_ABORT banner), status 2, no hang, nothing written
    body, message = _distributed_bad(plug_2d(2, 1), case)
    path = matrix_scene(tmp_path, body, "petsc", extra='[run]\ncondense = "distributed"\n')
    p = run(3, "run", path, "-o", str(tmp_path / "r.h5"), "-q", check=False, timeout=120)
    assert p.returncode == 2 and p.stderr.count("hpcwedge: error: model.K: ") == 1, p.stderr
    assert message in p.stderr
    assert not [f for f in os.listdir(tmp_path) if f.startswith("r.h5")]


def test_pictures_of_nodes_only_and_with_a_mesh(tmp_path, body2d):
    # plot and export: without model.mesh the nodes (no cells), with it the whole body
    import meshio
    import skfem

    from hpcwedge.cli import main
    K, X, contact, normals = body2d
    grid = skfem.MeshTri.init_tensor(np.linspace(0, 1, 5), np.linspace(0, 1, 4))     # plug_2d's cells
    meshio.write(tmp_path / "body.vtu", meshio.Mesh(np.column_stack([X, np.zeros(len(X))]), [("triangle", grid.t.T)]))
    for name, extra in (("nodes", ""), ("mesh", 'mesh = "body.vtu"\n')):
        path = matrix_scene(tmp_path, body2d, "npz", mu=(0.8,), name=name)
        text = open(path).read().replace('nodes = "nodes.csv"\n', 'nodes = "nodes.csv"\n' + extra)
        open(path, "w").write(text)
        out = str(tmp_path / f"{name}.h5")
        assert main(["run", path, "-o", out, "-q"]) == 0
        assert main(["plot", out, "-o", str(tmp_path / f"{name}.png"), "--ray", "0"]) == 0
        assert (tmp_path / f"{name}.png").stat().st_size > 0
        assert main(["export", out, "-o", str(tmp_path / f"{name}.vtu"), "--ray", "0"]) == 0
        vtu = meshio.read(tmp_path / f"{name}.vtu")
        assert len(vtu.points) == len(X)
        assert np.abs(vtu.point_data["reaction"][contact]).max() > 0
        kinds = {b.type: len(b.data) for b in vtu.cells}
        assert kinds == ({"triangle": grid.t.shape[1]} if name == "mesh" else {"vertex": len(X)})


def test_3d_picture_of_nodes_only(tmp_path):
    # a 3D matrix body without a mesh: no cells, its nodes drawn (undeformed and at the
    # pattern's point) and the pattern's contact set
    from hpcwedge.cli import main
    path = matrix_scene(tmp_path, plug_3d(), "npz", mu=(0.6,))
    out = str(tmp_path / "r.h5")
    assert main(["run", path, "-o", out, "-q"]) == 0
    assert main(["plot", out, "-o", str(tmp_path / "p.png"), "--pattern", "0"]) == 0
    assert (tmp_path / "p.png").stat().st_size > 0


def test_a_result_is_another_scenes_once_a_files_bytes_change(tmp_path):
    # the identity of a run (checkpoints, results: SPEC §5) covers model.K and model.nodes
    from hpcwedge.cli import main
    from hpcwedge.results.hdf5 import result_state
    body = plug_2d(2, 1)
    path = matrix_scene(tmp_path, body, "petsc", mu=(0.8,))
    out = str(tmp_path / "r.h5")
    assert main(["run", path, "-o", out, "-q"]) == 0
    assert result_state(out, load_scene(path)) == "complete"
    for name, change in (("nodes.csv", lambda b: b + b"\n"), ("body.petsc", lambda b: b[:-8] + bytes(8))):
        before = (tmp_path / name).read_bytes()
        (tmp_path / name).write_bytes(change(before))
        assert result_state(out, load_scene(path)) == "other-scene"
        (tmp_path / name).write_bytes(before)
        assert result_state(out, load_scene(path)) == "complete"
