"""`hpcwedge plot` (plot.py): figures of 2D result files (pipeline -> write_result -> plot_result);
3D figures (plot3d.py): test_plot3d.py."""
import tomllib

import h5py
import numpy as np
import pytest

pytest.importorskip("matplotlib")

from instances import check_png, result_file

from hpcwedge.cli import main
from hpcwedge.files import seal
from hpcwedge.post.plot import plot_result
from hpcwedge.results.hdf5 import write_result
from hpcwedge.results.record import Cone, Result, Run
from hpcwedge.scene.parse import parse_scene

STIFFNESS_TOML = """\
name = "two-dof"
dim = 2
[model]
kind = "stiffness"
K = [[2.0, 0.5], [0.5, 1.0]]
[friction]
mu = [2.5]
"""

PLUG2D_TOML = """\
name = "plug2d-rows2"
dim = 2
[model]
kind = "plug2d"
rows = 2
[friction]
mu = [0.65]
"""


@pytest.fixture
def stiffness_h5(tmp_path):
    return result_file(tmp_path, STIFFNESS_TOML)


def _plug2d_available() -> str | None:
    try:
        from hpcwedge.models import library
        library.plug2d
    except (ImportError, AttributeError) as e:
        return f"hpcwedge.models.library.plug2d not importable ({e})"
    try:
        import petsc4py  # noqa: F401
    except ImportError as e:
        return f"petsc4py not importable ({e}); condensation of a model needs it"
    return None


# ---------------------------------------------------------------- raw stiffness scene

def test_stiffness_scene_png(stiffness_h5, tmp_path):
    with h5py.File(stiffness_h5, "r") as f:
        assert "model" not in f                   # -> bar chart of r_n, u_n
        assert len(f["runs/000/rays"]) >= 1
    png = tmp_path / "fig.png"
    plot_result(stiffness_h5, str(png))
    check_png(png)


@pytest.mark.parametrize("name,head", [("fig.svg", b"<?xml"), ("FIG.PDF", b"%PDF-"), ("fig", b"\x89PNG")])
def test_format_from_the_suffix(stiffness_h5, tmp_path, name, head):
    out = tmp_path / name
    plot_result(stiffness_h5, str(out))
    with open(out, "rb") as f:
        data = f.read()
    assert data.startswith(head) and len(data) > 5_000, data[:40]
    if head == b"<?xml":
        assert b"<svg" in data[:2000]


@pytest.mark.parametrize("name", ["fig.jpeg", "fig.h5", "fig.png.bak"])
def test_unknown_suffix_refused_before_anything(stiffness_h5, tmp_path, capsys, name):
    with pytest.raises(ValueError, match="no figure format"):
        plot_result(stiffness_h5, str(tmp_path / name))
    assert main(["plot", stiffness_h5, "-o", str(tmp_path / name)]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith("hpcwedge: error: plot:") and ".png, .pdf, .svg" in err
    assert not (tmp_path / name).exists()
    assert main(["plot", str(tmp_path / "missing.h5"), "-o", str(tmp_path / name)]) == 2
    assert "no figure format" in capsys.readouterr().err    # the output is checked first


def test_run_and_ray_indices(stiffness_h5, tmp_path):
    png = tmp_path / "fig.png"
    plot_result(stiffness_h5, str(png), run=0, ray=-1)
    check_png(png)
    with pytest.raises(ValueError, match=r"^plot: ray 5 out of range") as e:
        plot_result(stiffness_h5, str(tmp_path / "bad.png"), ray=5)
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match=r"^plot: run 3 out of range"):
        plot_result(stiffness_h5, str(tmp_path / "bad.png"), run=3)
    with pytest.raises(ValueError, match=r"^plot: run -2 out of range"):
        plot_result(stiffness_h5, str(tmp_path / "bad.png"), run=-2)
    assert not (tmp_path / "bad.png").exists()
    assert [p.name for p in tmp_path.iterdir() if p.suffix == ".png"] == ["fig.png"]


@pytest.mark.parametrize("compute", [{"mu_c": "none"}, {"enumerate": "rays"},
                                     {"enumerate": False, "mu_c": "global"}])
def test_missing_answers_are_said_in_text(tmp_path, compute):
    # mu^c not computed / no cones / no rays: the panels say so, the figure is still written
    h5 = result_file(tmp_path, STIFFNESS_TOML, compute=compute)
    png = tmp_path / "fig.png"
    plot_result(h5, str(png))
    check_png(png)


def test_run_without_wedged_rays(tmp_path):
    # K = identity: u = r at every node, no wedged configuration at any mu
    text = STIFFNESS_TOML.replace("[[2.0, 0.5], [0.5, 1.0]]", "[[1.0, 0.0], [0.0, 1.0]]")
    h5 = result_file(tmp_path, text)
    with h5py.File(h5, "r") as f:
        n_wedged = int(f["runs/000"].attrs["n_wedged_rays"])
    assert n_wedged == 0
    png = tmp_path / "fig.png"
    plot_result(h5, str(png))                      # ray 0 of none: the panel says so
    check_png(png)
    with pytest.raises(ValueError, match="out of range"):
        plot_result(h5, str(tmp_path / "bad.png"), ray=1)


def test_pattern_option_refused_for_2d(stiffness_h5, tmp_path, capsys):
    """--pattern is the 3D item: on a 2D result it is a one-line error, nothing written."""
    with pytest.raises(ValueError, match=r"^plot: --pattern is for 3D results; this result is 2D") as e:
        plot_result(stiffness_h5, str(tmp_path / "bad.png"), pattern=0)
    assert "\n" not in str(e.value)
    assert main(["plot", stiffness_h5, "-o", str(tmp_path / "bad.png"), "--pattern", "0"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("hpcwedge: error: plot: --pattern") and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "bad.png").exists()


# ---------------------------------------------------------------- command line

def test_cli_plot(stiffness_h5, tmp_path, capsys):
    png = str(tmp_path / "cli.png")
    assert main(["plot", stiffness_h5, "-o", png]) == 0
    check_png(png)
    assert capsys.readouterr().err == f"[hpcwedge] run 0 (mu = 2.5), wedged ray 0: wrote {png}\n"
    bad = str(tmp_path / "bad.png")
    assert main(["plot", stiffness_h5, "-o", bad, "--ray", "7"]) == 2
    err = capsys.readouterr().err
    assert "ray 7 out of range" in err and len(err.strip().splitlines()) == 1
    assert main(["plot", stiffness_h5, "-o", bad, "--run", "9"]) == 2
    assert not (tmp_path / "bad.png").exists()


# ---------------------------------------------------------------- a model (geometry)

@pytest.mark.skipif(_plug2d_available() is not None, reason=str(_plug2d_available()))
def test_plug2d_png(tmp_path):
    h5 = result_file(tmp_path, PLUG2D_TOML)
    with h5py.File(h5, "r") as f:
        assert "model" in f and "cells_line" in f["model"]
        assert len(f["runs/000/rays"]) >= 1
    png = tmp_path / "plug.png"
    plot_result(h5, str(png))
    check_png(png)
    assert main(["plot", h5, "-o", str(tmp_path / "cli.png"), "--ray", "-1"]) == 0
    check_png(tmp_path / "cli.png")
    assert main(["plot", h5, "-o", str(tmp_path / "bad.png"), "--ray", "100000"]) == 2


def test_model_panel_without_condensation(tmp_path):
    """The body drawing on a real plug2d Model (no PETSc needed): the result holds the
    model and hand-made rays instead of enumerated ones."""
    library = pytest.importorskip("hpcwedge.models.library")
    model = library.plug2d(rows=2)
    scene = parse_scene(tomllib.loads(PLUG2D_TOML), PLUG2D_TOML)
    m = model.m
    rng = np.random.default_rng(0)
    rays = np.abs(rng.normal(size=(3, 4 * m)))
    rays[:, m:2 * m] -= 0.5                                   # tangential u of both signs
    rays[:, 3 * m:] -= 0.5
    rays[:, 2 * m:3 * m] /= rays[:, 2 * m:3 * m].sum(axis=1, keepdims=True)   # sum r_n = 1
    cones = [Cone(rays=[0, 1], trivial_rays=[], zero_u=[0], zero_r=[1], mu_c=0.4),
             Cone(rays=[2], trivial_rays=[], zero_u=[1], zero_r=[0])]
    result = Result(scene=scene, m=m, model=model, mu_c=0.176, mu_c_status="found",
                    runs=[Run(mu=0.65, rays=rays, trivial_rays=np.zeros((0, 4 * m)),
                              ray_zero=np.zeros((3, 3 * m), dtype=bool), cones=cones)],
                    timings={"condense": 0.0, "enumerate": 0.0, "mu_c": 0.0, "total": 0.0})
    h5 = str(tmp_path / "synthetic.h5")
    write_result(h5, result)
    for ray in (0, 2):
        png = tmp_path / f"ray{ray}.png"
        plot_result(h5, str(png), ray=ray)
        check_png(png)
    with pytest.raises(ValueError, match=r"^plot: ray 3 out of range"):
        plot_result(h5, str(tmp_path / "bad.png"), ray=3)


BLOCK2D_TOML = PLUG2D_TOML.replace('"plug2d"', '"block2d"').replace("plug2d-rows2", "block2d")


@pytest.mark.skipif(_plug2d_available() is not None, reason=str(_plug2d_available()))
def test_block2d_whole_body_von_mises(tmp_path):
    """A continuum body is drawn whole (interior nodes displaced too), coloured by von Mises;
    when the body cannot be rebuilt the contact-only drawing remains and the title says why."""
    from hpcwedge.post.plot import _load
    from hpcwedge.post.recovery import VON_MISES
    h5 = result_file(tmp_path, BLOCK2D_TOML)
    d = _load(h5, -1, 1)
    cfg = d["config"]
    assert cfg is not None and d["config_note"] is None
    assert cfg.element_values[VON_MISES]["quad"].shape == (len(d["model"].cells["quad"]),)
    interior = np.setdiff1d(np.arange(len(cfg.displacement)), d["model"].contact_nodes)
    assert np.abs(cfg.displacement[interior]).max() > 0
    png = tmp_path / "block.png"
    plot_result(h5, str(png), ray=1)
    check_png(png)
    with h5py.File(h5, "r+") as f:
        f["model/coords"][0, 0] += 0.5                 # no longer the scene's body
    seal(h5)
    d = _load(h5, -1, 1)
    assert d["config"] is None and "differs" in d["config_note"]
    plot_result(h5, str(png), ray=1)
    check_png(png)


def test_2d_patterns_result_panel_says_what_was_enumerated(tmp_path):
    """A 2D result of enumerate = "patterns" (no rays): the configuration panel names the
    patterns and the command that draws one (before: "compute.enumerate = false", which is
    not what the scene asked), and --pattern's refusal points to it too."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hpcwedge.post.plot import _config_panel, _load
    h5 = result_file(tmp_path, PLUG2D_TOML.replace("[friction]", '[compute]\nenumerate = "patterns"\n[friction]'))
    d = _load(h5, -1)
    assert d["rays"] is None and d["patterns"]
    fig, ax = plt.subplots()
    _config_panel(ax, d)
    shown = " ".join(t.get_text() for t in ax.texts)
    plt.close(fig)
    assert f'compute.enumerate = "patterns": {len(d["patterns"])} sign patterns' in shown
    assert "export --pattern" in shown and "= false" not in shown
    with pytest.raises(ValueError, match="export --pattern J"):
        plot_result(h5, str(tmp_path / "bad.png"), pattern=0)
