"""The public Python API (hpcwedge/api.py, issue 14): the acceptance one-liners as real
processes, scenes from arrays against the same scenes as TOML files, errors naming the key,
Result.to_dict() against `show --json`, results of Python-made scenes usable by the command
line, a light `import hpcwedge`, and the module's doctests."""
import doctest
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from instances import python_calls

import hpcwedge as hw
import hpcwedge.api
from hpcwedge.contact.build import contact_problem

TAN10 = math.tan(math.radians(10))


def python(code: str, cwd=None) -> str:
    """Run `code` in a fresh interpreter (this one's PYTHONPATH); its stdout."""
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, cwd=cwd)
    assert p.returncode == 0, p.stderr
    return p.stdout


def cli(*args, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hpcwedge", *args], capture_output=True, text=True,
                          timeout=600, cwd=cwd)


# --------------------------------------------------------------------------- acceptance

def test_acceptance_builtin_prints_tan_10():
    out = python("import hpcwedge as hw; r = hw.solve(hw.Scene.builtin('plug2d', rows=4)); print(r.mu_c)")
    assert abs(float(out) - TAN10) <= 1e-12


def test_acceptance_stiffness_array_prints_tan_10():
    """plug2d rows 4 condensed (build.contact_problem), given back as a K array and its
    rigid modes: the same mu^c, also as numpy arrays built in the process."""
    out = python("import hpcwedge as hw; from hpcwedge.contact.build import contact_problem\n"
                 "p = contact_problem(hw.Scene.builtin('plug2d', rows=4))\n"
                 "r = hw.solve(hw.Scene.from_stiffness(p.K, null_space=p.N, dim=2)); print(r.mu_c)")
    assert abs(float(out) - TAN10) <= 1e-12


def test_stiffness_array_gives_the_builtin_answers():
    """Same zero sets, cones and mu^c from the K array as from the model."""
    scene = hw.Scene.builtin("plug2d", rows=4)
    p = contact_problem(scene)
    a, b = hw.solve(scene), hw.solve(hw.Scene.from_stiffness(p.K, null_space=p.N, dim=2))
    assert b.scene.kind == "stiffness" and a.m == b.m == 8
    assert abs(b.mu_c - TAN10) <= 1e-12
    for ra, rb in zip(a.runs, b.runs):
        assert ra.n_wedged_rays == rb.n_wedged_rays == 244
        assert np.array_equal(ra.ray_zero, rb.ray_zero)
        assert [(c.zero_u, c.zero_r) for c in ra.cones] == [(c.zero_u, c.zero_r) for c in rb.cones]


def test_stiffness_as_a_scipy_sparse_matrix():
    """A sparse K (csr matrix, csc array) is taken as its dense array: the same scene table
    as from the dense K (before: refused, 'got csr_matrix')."""
    import scipy.sparse as sp
    p = contact_problem(hw.Scene.builtin("plug2d", rows=3))
    dense = hw.Scene.from_stiffness(p.K, null_space=p.N, dim=2)
    for K in (sp.csr_matrix(p.K), sp.csc_array(p.K)):
        assert hw.Scene.from_stiffness(K, null_space=p.N, dim=2).model == dense.model


@pytest.mark.parametrize("data", [
    {"name": "a", "dim": 2, "model": {"kind": "plug2d", "rows": 3, "taper_deg": 0.1},
     "friction": {"mu": (0.3, 0.65)}, "compute": {"mu_c": "global", "enumerate": False},
     "run": {"max_memory_gb": 1.5, "symmetry": True}},
    {"name": "b \"q\" \u00e9", "dim": 3, "model": {"kind": "stiffness",
     "K": np.array([[2.0, -1e-300, 0.0], [-1e-300, 1e300, -0.0], [0.0, -0.0, 3.0]]),
     "null_space": None}, "friction": {"mu": np.float64(0.5)}},
    {"name": "c", "dim": 2, "model": {"kind": "truss", "nodes": [[0, 0], [1, 0.5]], "bars": np.array([[0, 1]]),
     "EA": [1.0, 2 ** 70], "supports": [(1, 0)]}, "contact": {"nodes": [0], "normals": [[0.0, 1.0]]},
     "friction": {"mu": [1e-6, 1e6]}},
])
def test_scene_text_reads_back_as_the_table_validated(data):
    """scene_from_dict validates the plain table without parsing its TOML text again: the text
    must read back as exactly that table (types included), or Scene.text would describe
    another scene than the one solved."""
    import tomllib

    from hpcwedge.scene.tables import _plain
    back, plain = tomllib.loads(hw.Scene.from_dict(data).text), _plain(data, "")

    def typed(v):                   # the value with every leaf's type, -0.0 told from 0.0
        if isinstance(v, dict):
            return {k: typed(x) for k, x in v.items()}
        if isinstance(v, list):
            return [typed(x) for x in v]
        return (type(v).__name__, repr(v))
    assert typed(back) == typed(plain)


def test_a_large_stiffness_table_is_converted_row_by_row():
    """A 200 x 200 K from numpy: its conversion, TOML text and boolean check take calls per
    row, not per entry (before: about 3 Python calls per entry, and the text parsed again:
    8.7 s for 1,000 x 1,000), and the text holds K exactly."""
    import tomllib
    rng = np.random.default_rng(0)
    A = rng.standard_normal((200, 200))
    K = A @ A.T
    hw.Scene.from_stiffness(K[:4, :4], dim=2)          # the modules it imports on first use
    calls = python_calls(lambda: hw.Scene.from_stiffness(K, dim=2))
    assert calls < 20 * 200, calls                       # measured: 2,659 (before: 1,546,004)
    assert tomllib.loads(hw.Scene.from_stiffness(K, dim=2).text)["model"]["K"] == K.tolist()


# --------------------------------------------------------------------------- scenes

def _plug_truss():
    """plug2d rows 3's truss as arrays (nodes, bars, contact nodes, normals), bars of unequal EA."""
    from hpcwedge.models.library import plug2d
    m = plug2d(rows=3)
    bars = np.asarray(m.cells["line"])
    return m.coords, bars, np.asarray(m.contact_nodes), m.normals, np.linspace(1.0, 2.0, len(bars))


def test_truss_from_arrays_equals_the_toml_scene(tmp_path):
    nodes, bars, contact, normals, EA = _plug_truss()
    rows = lambda a: "[" + ", ".join("[" + ", ".join(repr(float(x)) for x in r) + "]" for r in a) + "]"  # noqa: E731
    (tmp_path / "t.toml").write_text(
        f'name = "truss"\ndim = 2\n[model]\nkind = "truss"\nnodes = {rows(nodes)}\n'
        f"bars = {bars.tolist()}\nEA = {[float(x) for x in EA]}\n"
        f"[contact]\nnodes = {contact.tolist()}\nnormals = {rows(normals)}\n"
        f"[friction]\nmu = [0.3, 0.65]\n")
    a = hw.solve(hw.Scene.load(str(tmp_path / "t.toml")))
    b = hw.solve(hw.Scene.from_truss(nodes, bars, contact_nodes=contact, normals=normals, EA=EA, mu=[0.65, 0.3]))
    assert a.mu_c is not None and a.mu_c == b.mu_c and a.mu_c_status == b.mu_c_status == "found"
    assert [r.mu for r in a.runs] == [r.mu for r in b.runs] == [0.3, 0.65]
    for ra, rb in zip(a.runs, b.runs):
        assert ra.n_wedged_rays > 0 and ra.cones
        for name in ("rays", "trivial_rays", "ray_zero"):
            assert np.array_equal(getattr(ra, name), getattr(rb, name)), name
        assert ra.cones == rb.cones
    da, db = a.to_dict(), b.to_dict()
    for d in (da, db):
        for k in ("timings", "stats", "scene_hash"):
            d.pop(k)
    assert da == db


def test_scene_text_reads_back_as_the_same_scene(tmp_path):
    """A scene made in Python keeps its table as TOML text (hashed, stored in results): the
    text, as a scene file in the same folder, is the same scene."""
    nodes, bars, contact, normals, EA = _plug_truss()
    s = hw.Scene.from_truss(nodes, bars, contact_nodes=contact, normals=normals, EA=EA, name="a \"b\"\u00e9",
                            mu=np.float64(0.5), mu_c="global", symmetry=False)
    (tmp_path / "s.toml").write_text(s.text)
    t = hw.Scene.load(str(tmp_path / "s.toml"))
    assert t == s.__class__(**{**s.__dict__, "base_dir": t.base_dir}) and t.hash == s.hash
    assert s.name == 'a "b"\u00e9' and s.mu == (0.5,) and s.mu_c == "global" and s.symmetry is False
    assert hw.Scene.builtin("plug2d").hash != hw.Scene.builtin("plug2d", rows=3).hash


def test_python_scene_result_serves_the_command_line(tmp_path):
    """show --json of a result written by the API is Result.to_dict(); export rebuilds the
    body from the stored scene text alone."""
    r = hw.solve(hw.Scene.builtin("plug2d", rows=3, mu=[0.3, 0.65]))
    path = str(tmp_path / "r.h5")
    hw.write_result(r, path)
    p = cli("show", path, "--json")
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout) == r.to_dict() == hw.read_result(path).to_dict()
    assert r.to_dict(with_rays=False)["runs"][1]["rays"] is None
    p = cli("export", path, "--cone", "0", "-o", str(tmp_path / "c.vtu"), cwd=str(tmp_path))
    assert p.returncode == 0 and os.path.getsize(tmp_path / "c.vtu") > 0, p.stderr
    hw.plot(r, tmp_path / "f.png", ray=1)
    assert (tmp_path / "f.png").read_bytes()[:4] == b"\x89PNG"
    c = hw.export_vtu(path, tmp_path / "p.vtu", run=0, ray=2)
    assert c.displacement.shape == (9, 2) and np.isfinite(c.displacement).all()


def test_file_scene_and_dict_scene_agree(tmp_path):
    (tmp_path / "s.toml").write_text('name = "v"\ndim = 2\n[model]\nkind = "vgroove_bar"\ntheta_deg = 20.0\n'
                                     '[friction]\nmu = 1.0\n')
    d = {"name": "v", "dim": 2, "model": {"kind": "vgroove_bar", "theta_deg": 20.0}, "friction": {"mu": 1.0}}
    for scene in (str(tmp_path / "s.toml"), d, hw.Scene.from_dict(d)):
        assert abs(hw.solve(scene).mu_c - math.tan(math.radians(20))) <= 1e-12


def test_relative_files_of_a_dict_scene(tmp_path, monkeypatch):
    """model.file of a dict scene is relative to base_dir (default: the current folder at
    the call), and its bytes are part of the scene's identity as for a scene file."""
    np.savez(tmp_path / "k.npz", K=np.array(K2))
    d = {"name": "k", "dim": 2, "model": {"kind": "stiffness", "file": "k.npz"}, "friction": {"mu": 5.0}}
    a = hw.Scene.from_dict(d, base_dir=str(tmp_path))
    monkeypatch.chdir(tmp_path)
    b = hw.Scene.from_dict(d)
    monkeypatch.chdir(tmp_path.parent)
    for s in (a, b):
        assert s.input_files == (str(tmp_path / "k.npz"),) and len(s.input_digests) == 1
        assert abs(hw.solve(s).mu_c - 4.0) <= 1e-12
    with pytest.raises(hw.SceneError, match="model.file: k.npz not found"):
        hw.solve(hw.Scene.from_dict(d))


def test_the_result_records_the_files_as_solved(tmp_path):
    """A file the scene names that changes between hw.solve and hw.write_result: the result
    records the digest of the bytes that were solved (before: of the file at the write, so
    that a later export rebuilt the body from the changed file without a word)."""
    import hashlib
    k = tmp_path / "k.npz"
    np.savez(k, K=np.array(K2))
    solved = hashlib.sha256(k.read_bytes()).hexdigest()
    s = hw.Scene.from_dict({"name": "k", "dim": 2, "model": {"kind": "stiffness", "file": "k.npz"},
                            "friction": {"mu": 5.0}}, base_dir=str(tmp_path))
    r = hw.solve(s)
    np.savez(k, K=2.0 * np.array(K2))
    hw.write_result(r, str(tmp_path / "r.h5"))
    assert hw.read_result(str(tmp_path / "r.h5"), with_rays=False).scene.input_digests == {"model.file k.npz": solved}


def test_progress_goes_to_stderr_only_when_asked(capfd):
    hw.solve(hw.Scene.builtin("plug2d", rows=2))
    assert capfd.readouterr() == ("", "")
    hw.solve(hw.Scene.builtin("plug2d", rows=2), progress=True)
    out, err = capfd.readouterr()
    assert out == "" and "rays" in err


# --------------------------------------------------------------------------- errors

K2 = [[2.0, 1.0], [1.0, 4.0]]


@pytest.mark.parametrize("make,key", [
    (lambda: hw.Scene.builtin("plug2d", rows=0), "model.rows"),
    (lambda: hw.Scene.builtin("plug2d", rows=2.5), "model.rows"),
    (lambda: hw.Scene.builtin("plug2d", colz=3), "model.colz"),
    (lambda: hw.Scene.builtin("nope"), "model.kind"),
    (lambda: hw.Scene.builtin("plug2d", mu=-1.0), "friction.mu"),
    (lambda: hw.Scene.builtin("plug2d", mu=[]), "friction.mu"),
    (lambda: hw.Scene.builtin("plug2d", mu_c="sometimes"), "compute.mu_c"),
    (lambda: hw.Scene.builtin("plug2d", task_budget=0), "run.task_budget"),
    (lambda: hw.Scene.from_stiffness(K2, dim=2, bogus=1), "bogus"),
    (lambda: hw.Scene.from_stiffness(K2, dim=4), "dim"),
    (lambda: hw.Scene.from_stiffness({1, 2}, dim=2), "model.K"),
    (lambda: hw.Scene.from_truss([1.0, 2.0], [[0, 1]], contact_nodes=[0], normals=[[1.0, 0.0]]), "model.nodes"),
    (lambda: hw.Scene.from_dict([1, 2]), "scene"),
    (lambda: hw.Scene.from_dict({"name": "x", "dim": 2, "model": {"kind": "plug2d", "rows": object()},
                                 "friction": {"mu": 1.0}}), "model.rows"),
    (lambda: hw.Scene.from_dict({"name": "x", "dim": 2, "model": {"kind": "plug2d"}}), "friction.mu"),
    (lambda: hw.Scene.load("/nonexistent/s.toml"), "/nonexistent/s.toml"),
    (lambda: hw.solve(hw.Scene.from_stiffness([[1.0, np.nan], [np.nan, 1.0]], dim=2)), "model.K"),
    (lambda: hw.solve(hw.Scene.from_stiffness([[1.0, 2.0], [0.0, 1.0]], dim=2)), "model.K"),
    (lambda: hw.solve(hw.Scene.from_truss([[0.0, 0.0], [1.0, 0.0]], [[0, 5]], contact_nodes=[0, 1],
                                          normals=[[1.0, 0.0], [-1.0, 0.0]])), "bars"),
    (lambda: hw.solve(42), "scene"),
])
def test_bad_arguments_are_scene_errors_naming_the_key(make, key):
    with pytest.raises(hw.SceneError) as e:
        make()
    msg = str(e.value)
    assert key in msg and "\n" not in msg, msg


def test_bad_result_file_is_a_file_error(tmp_path):
    (tmp_path / "x.h5").write_bytes(b"not a result" * 100)
    with pytest.raises(hw.FileError, match="x.h5"):
        hw.read_result(tmp_path / "x.h5")


# --------------------------------------------------------------------------- the module

def test_import_is_light_and_exports_resolve():
    out = python("import sys, hpcwedge as hw\nlight = 'numpy' not in sys.modules\n"
                 "names = [getattr(hw, n) for n in hw.__all__]\n"
                 "from hpcwedge import *\nprint(light, 'numpy' in sys.modules, solve is hw.solve)")
    assert out.split() == ["True", "True", "True"]
    with pytest.raises(AttributeError):
        hw.no_such_name  # noqa: B018


def test_doctests():
    import hpcwedge.scene.constructors
    res = [doctest.testmod(hpcwedge.api),        # the constructors' examples solve through the API
           doctest.testmod(hpcwedge.scene.constructors, extraglobs={"solve": hpcwedge.api.solve, "math": math})]
    assert sum(r.attempted for r in res) >= 20 and sum(r.failed for r in res) == 0


def test_plot_stays_the_function_after_the_plot_module_is_imported():
    """hw.plot is api.plot even after hpcwedge.post.plot (the module, which api.plot imports on
    its first call) is loaded: a notebook calls it twice (docs/examples/cork.md). No module of
    the package is named after a public name, so no import can rebind one."""
    out = python("import hpcwedge as hw\nimport hpcwedge.post.plot\nfrom hpcwedge.post.plot import plot_result\n"
                 "from hpcwedge import plot\nprint(hw.plot is hw.api.plot, plot is hw.plot, callable(plot_result))")
    assert out.split() == ["True", "True", "True"]


def test_writers_check_their_output_as_the_command_line_does(tmp_path):
    """hw.write_result, hw.plot and hw.export_vtu refuse, in one line naming the path and before
    any work, what `hpcwedge run -o`, `plot` and `export` refuse: a file that is not HDF5 (a
    scene, a mesh), a missing folder (before: made, even at the file system's root), a
    directory (before: a raw OSError), the result file itself; an index that is not a whole
    number is refused, not truncated (ray=1.9 drew ray 1)."""
    r = hw.solve(hw.Scene.builtin("plug2d", rows=2))
    scene = tmp_path / "s.toml"
    scene.write_text('name = "s"\n')
    for bad, phrase in ((scene, "not an HDF5 file"), (tmp_path / "no" / "r.h5", "does not exist"),
                        (tmp_path, "is a directory")):
        with pytest.raises(hw.FileError, match=phrase):
            hw.write_result(r, bad)
    assert scene.read_text() == 'name = "s"\n' and sorted(os.listdir(tmp_path)) == ["s.toml"]
    with pytest.raises(TypeError, match="Result"):
        hw.write_result("x", tmp_path / "x.h5")
    res = tmp_path / "r.h5"
    hw.write_result(r, res)
    with pytest.raises(hw.FileError, match="is the input"):
        hw.plot(res, res)
    with pytest.raises(hw.FileError, match="does not exist"):
        hw.export_vtu(r, tmp_path / "no" / "x.vtu", ray=0)
    for bad in (1.9, "1", True):
        with pytest.raises(ValueError, match="ray: a whole number"):
            hw.export_vtu(r, tmp_path / "x.vtu", ray=bad)
        with pytest.raises(ValueError, match="ray: a whole number"):
            hw.plot(r, tmp_path / "x.png", ray=bad)
    with pytest.raises(hw.SceneError, match="model.kind"):
        hw.Scene.builtin(["plug2d"])
    assert sorted(os.listdir(tmp_path)) == ["r.h5", "s.toml"]
