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
