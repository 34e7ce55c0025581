"""The command line on real files: run/show round trip, exit 2 on bad input with
nothing written, and the public reference scenes."""
import json
import math
import os
import subprocess
import sys

import pytest

from hpcwedge.cli import main

SHARED = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "scenes")


def write(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def run_show_json(tmp_path, capsys, text):
    """`run` a scene text quietly, then `show --json` its result: (result path, JSON)."""
    s = write(tmp_path, text)
    out = str(tmp_path / "r.h5")
    assert main(["run", s, "-o", out, "-q"]) == 0
    capsys.readouterr()
    assert main(["show", out, "--json"]) == 0
    return out, json.loads(capsys.readouterr().out)


def test_run_show_json(tmp_path, capsys):
    out, got = run_show_json(tmp_path, capsys, 'name = "n"\ndim = 2\n[model]\nkind = "stiffness"\n'
                             'K = [[2.0, 0.5], [0.5, 1.0]]\n[friction]\nmu = [2.5, 1.5]\n')
    assert got["name"] == "n" and got["m"] == 1 and got["complete"] is True
    assert abs(got["mu_c"] - 2.0) < 1e-12
    assert [r["mu"] for r in got["runs"]] == [1.5, 2.5]
    r = got["runs"][1]
    assert r["n_wedged_rays"] == 1 and r["n_cones"] == 1 and r["n_patterns"] is None
    assert abs(sum(r["rays"][0][2:3]) - 1.0) < 1e-12          # sum r_n = 1
    assert r["cones"][0]["zero_u"] == [0] and abs(r["cones"][0]["mu_c"] - 2.0) < 1e-12
    assert set(got["timings"]) >= {"condense", "enumerate", "mu_c", "total"}
    assert main(["show", out]) == 0


@pytest.mark.parametrize("text,key", [
    ('name = "x"\ndim = 2\n[model]\nkind = "stiffness"\nK = [[1.0, 2.0], [2.0, 1.0]]\n[friction]\nmu = [1.0]\n', "model.K"),
    ('name = "x"\ndim = 2\n[model]\nkind = "plug2d"\n[friction]\nmu = [-1.0]\n', "friction.mu"),
    ('name = "x"\ndim = 2\n[model\n', "not valid TOML"),
])
def test_bad_input_exit_2_nothing_written(tmp_path, capsys, text, key):
    out = tmp_path / "r.h5"
    assert main(["run", write(tmp_path, text), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert key in err and len(err.splitlines()) == 1
    assert not out.exists() and not [p for p in os.listdir(tmp_path) if p.startswith(".tmp")]


def test_show_missing_file(tmp_path):
    assert main(["show", str(tmp_path / "none.h5")]) == 2


@pytest.mark.skipif(not os.path.isdir(SHARED), reason="../shared/scenes not beside the checkout")
def test_public_scenes(tmp_path):
    """The console script on every public scene (2D and 3D)."""
    exe = os.path.join(os.path.dirname(sys.executable), "hpcwedge")
    want = json.load(open(os.path.join(SHARED, "expected.json")))
    for name, exp in want.items():
        if name.startswith("_"):
            continue
        out = str(tmp_path / (name + ".h5"))
        subprocess.run([exe, "run", os.path.join(SHARED, name), "-o", out, "-q"], check=True)
        got = json.loads(subprocess.run([exe, "show", out, "--json"], check=True,
                                        capture_output=True, text=True).stdout)
        if exp["mu_c"] is None:
            assert got["mu_c"] is None
        else:
            assert math.isclose(got["mu_c"], exp["mu_c"], rel_tol=1e-9), name
        for k, run in enumerate(exp["runs"]):
            for key, v in run.items():
                assert got["runs"][k][key] == v if key != "mu" else math.isclose(got["runs"][k][key], v)


def test_run_show_json_3d(tmp_path, capsys):
    out, got = run_show_json(tmp_path, capsys, 'name = "n3"\ndim = 3\n[model]\nkind = "stiffness"\n'
                             'K = [[3.0, 0.4, 0.2], [0.4, 2.0, 0.3], [0.2, 0.3, 1.5]]\n'
                             '[friction]\nmu = [5.0, 4.0]\n')
    assert got["dim"] == 3 and math.isclose(got["mu_c"], 4.784010530585897, rel_tol=1e-9)
    r4, r5 = got["runs"]
    assert (r4["mu"], r4["n_patterns"], r4["patterns"]) == (4.0, 0, [])
    assert r5["n_patterns"] == 1 and r5["patterns"][0]["contact"] == [0]
    assert math.isclose(r5["patterns"][0]["mu_c"], 4.784010530585897, rel_tol=1e-9)
    for key in ("rays", "trivial_rays", "cones", "n_wedged_rays", "n_trivial_rays", "n_cones"):
        assert r5[key] is None
    assert "socp_statuses" in got["stats"]
    assert main(["show", out]) == 0
    assert "pattern" in capsys.readouterr().out


# ----------------------------------------------------------------------------- export

def _run_quiet(tmp_path, text, name):
    s = write(tmp_path, text, name + ".toml")
    out = str(tmp_path / (name + ".h5"))
    assert main(["run", s, "-o", out, "-q"]) == 0
    return out


def test_export_vtu(tmp_path, capsys):
    """`export` writes a VTU that meshio reads back: displacement and reaction (n, 3) point
    data, von Mises (block2d, Q4) or axial force (plug3d, bars) per cell."""
    import meshio
    import numpy as np
    b2 = _run_quiet(tmp_path, 'name = "b"\ndim = 2\n[model]\nkind = "block2d"\nrows = 2\n'
                    '[friction]\nmu = [0.65]\n', "b2")
    p3 = _run_quiet(tmp_path, 'name = "p"\ndim = 3\n[model]\nkind = "plug3d"\nring = 4\n'
                    '[friction]\nmu = [0.65]\n', "p3")
    for res, args, n, cells, field in ((b2, ["--ray", "0"], 9, ("quad", 4), "von_mises"),
                                       (b2, ["--cone", "-1", "--run", "0"], 9, ("quad", 4), "von_mises"),
                                       (p3, ["--pattern", "2"], 10, ("line", 37), "axial_force")):
        vtu = str(tmp_path / "out.vtu")
        assert main(["export", res, *args, "-o", vtu]) == 0
        assert "wrote" in capsys.readouterr().err
        got = meshio.read(vtu)
        assert got.points.shape == (n, 3)
        assert got.point_data["displacement"].shape == (n, 3) and got.point_data["reaction"].shape == (n, 3)
        assert np.abs(got.point_data["displacement"]).max() > 0
        assert (got.cells[0].type, len(got.cells[0].data)) == cells
        assert got.cell_data[field][0].shape == (cells[1],) and np.isfinite(got.cell_data[field][0]).all()


@pytest.mark.parametrize("args,phrase", [
    (["--run", "4", "--ray", "0"], "run 4 out of range"),
    (["--ray", "500"], "ray 500 out of range"),
    (["--pattern", "0"], "has no patterns"),
    (["--cone", "7"], "cone 7 out of range"),
])
def test_export_errors_exit_2(tmp_path, capsys, args, phrase):
    res = _run_quiet(tmp_path, 'name = "p"\ndim = 2\n[model]\nkind = "plug2d"\nrows = 2\n'
                     '[friction]\nmu = [0.65]\n', "p2")
    vtu = tmp_path / "x.vtu"
    assert main(["export", res, *args, "-o", str(vtu)]) == 2
    err = capsys.readouterr().err.strip()
    assert phrase in err and err.startswith("hpcwedge: error: export:") and len(err.splitlines()) == 1
    assert not vtu.exists() and not [p for p in os.listdir(tmp_path) if p.startswith(".tmp")]


def test_export_stiffness_scene_and_missing_file(tmp_path, capsys):
    res = _run_quiet(tmp_path, 'name = "k"\ndim = 2\n[model]\nkind = "stiffness"\n'
                     'K = [[2.0, 0.5], [0.5, 1.0]]\n[friction]\nmu = [2.5]\n', "k")
    assert main(["export", res, "--ray", "0", "-o", str(tmp_path / "x.vtu")]) == 2
    err = capsys.readouterr().err.strip()
    assert "no body to export" in err and len(err.splitlines()) == 1
    assert main(["export", str(tmp_path / "none.h5"), "--ray", "0", "-o", str(tmp_path / "x.vtu")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert not (tmp_path / "x.vtu").exists()


@pytest.mark.parametrize("chunk", [1, 7, 16384])
def test_show_json_streams_the_same_object_as_read_result(tmp_path, capsys, monkeypatch, chunk):
    """`show --json` streams the rays in chunks; the object equals read_result's (ray
    vectors to the last bit: repr round-trips floats) whatever the chunk size."""
    from hpcwedge import results
    monkeypatch.setattr(results, "RAY_CHUNK", chunk)
    out, got = run_show_json(tmp_path, capsys, 'name = "p"\ndim = 2\n[model]\nkind = "plug2d"\n'
                             'rows = 3\n[friction]\nmu = [0.65, 2.0]\n[compute]\nmu_c = "cones"\n')
    want = results.read_result(out)
    assert got == want and len(got["runs"][0]["rays"]) == got["runs"][0]["n_wedged_rays"] > 7
    assert main(["show", out, "--json", "--no-rays"]) == 0
    assert json.loads(capsys.readouterr().out) == results.read_result(out, with_rays=False)
