"""`hpcwedge plot`: figures from real result files (pipeline -> write_result -> plot_result)."""
import os
import shutil
import struct
import tomllib

import h5py
import numpy as np
import pytest

pytest.importorskip("matplotlib")

from hpcwedge.cli import main
from hpcwedge.pipeline import run_scene
from hpcwedge.plot import plot_result
from hpcwedge.files import seal
from hpcwedge.results import Result, Run
from hpcwedge.resultfile import write_result
from hpcwedge.scene import parse_scene

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLES = os.path.join(ROOT, "scripts", "examples")

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


def _result_file(tmp_path, text: str, name: str = "result.h5", compute: dict | None = None) -> str:
    data = tomllib.loads(text)
    if compute:
        data["compute"] = compute
    result = run_scene(parse_scene(data, text))
    path = str(tmp_path / name)
    write_result(path, result)
    return path


def _check_png(path) -> tuple[int, int]:
    with open(path, "rb") as f:
        head = f.read(24)
        f.seek(0, 2)
        size = f.tell()
    assert head[:8] == PNG_SIGNATURE
    assert head[12:16] == b"IHDR"
    width, height = struct.unpack(">II", head[16:24])
    assert 600 <= width <= 4000 and 300 <= height <= 3000, (width, height)
    assert size > 10_000, size                     # two drawn panels, not an empty canvas
    return width, height


@pytest.fixture
def stiffness_h5(tmp_path):
    return _result_file(tmp_path, STIFFNESS_TOML)


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
    _check_png(png)


def test_run_and_ray_indices(stiffness_h5, tmp_path):
    png = tmp_path / "fig.png"
    plot_result(stiffness_h5, str(png), run=0, ray=-1)
    _check_png(png)
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
    h5 = _result_file(tmp_path, STIFFNESS_TOML, compute=compute)
    png = tmp_path / "fig.png"
    plot_result(h5, str(png))
    _check_png(png)


def test_run_without_wedged_rays(tmp_path):
    # K = identity: u = r at every node, no wedged configuration at any mu
    text = STIFFNESS_TOML.replace("[[2.0, 0.5], [0.5, 1.0]]", "[[1.0, 0.0], [0.0, 1.0]]")
    h5 = _result_file(tmp_path, text)
    with h5py.File(h5, "r") as f:
        n_wedged = int(f["runs/000"].attrs["n_wedged_rays"])
    assert n_wedged == 0
    png = tmp_path / "fig.png"
    plot_result(h5, str(png))                      # ray 0 of none: the panel says so
    _check_png(png)
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
    _check_png(png)
    bad = str(tmp_path / "bad.png")
    assert main(["plot", stiffness_h5, "-o", bad, "--ray", "7"]) == 2
    err = capsys.readouterr().err
    assert "ray 7 out of range" in err and len(err.strip().splitlines()) == 1
    assert main(["plot", stiffness_h5, "-o", bad, "--run", "9"]) == 2
    assert not (tmp_path / "bad.png").exists()


# ---------------------------------------------------------------- a model (geometry)

@pytest.mark.skipif(_plug2d_available() is not None, reason=str(_plug2d_available()))
def test_plug2d_png(tmp_path):
    h5 = _result_file(tmp_path, PLUG2D_TOML)
    with h5py.File(h5, "r") as f:
        assert "model" in f and "cells_line" in f["model"]
        assert len(f["runs/000/rays"]) >= 1
    png = tmp_path / "plug.png"
    plot_result(h5, str(png))
    _check_png(png)
    assert main(["plot", h5, "-o", str(tmp_path / "cli.png"), "--ray", "-1"]) == 0
    _check_png(tmp_path / "cli.png")
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
    cones = [{"rays": [0, 1], "trivial_rays": [], "zero_u": [0], "zero_r": [1], "mu_c": 0.4},
             {"rays": [2], "trivial_rays": [], "zero_u": [1], "zero_r": [0], "mu_c": None}]
    result = Result(scene=scene, m=m, model=model, mu_c=0.176, mu_c_status="found",
                    runs=[Run(mu=0.65, rays=rays, trivial_rays=np.zeros((0, 4 * m)),
                              ray_zero=np.zeros((3, 3 * m), dtype=bool), cones=cones)],
                    timings={"condense": 0.0, "enumerate": 0.0, "mu_c": 0.0, "total": 0.0})
    h5 = str(tmp_path / "synthetic.h5")
    write_result(h5, result)
    for ray in (0, 2):
        png = tmp_path / f"ray{ray}.png"
        plot_result(h5, str(png), ray=ray)
        _check_png(png)
    with pytest.raises(ValueError, match=r"^plot: ray 3 out of range"):
        plot_result(h5, str(tmp_path / "bad.png"), ray=3)


BLOCK2D_TOML = PLUG2D_TOML.replace('"plug2d"', '"block2d"').replace("plug2d-rows2", "block2d")


@pytest.mark.skipif(_plug2d_available() is not None, reason=str(_plug2d_available()))
def test_block2d_whole_body_von_mises(tmp_path):
    """A continuum body is drawn whole (interior nodes displaced too), coloured by von Mises;
    when the body cannot be rebuilt the contact-only drawing remains and the title says why."""
    from hpcwedge.recovery import VON_MISES
    from hpcwedge.plot import _load
    h5 = _result_file(tmp_path, BLOCK2D_TOML)
    d = _load(h5, -1, 1)
    cfg = d["config"]
    assert cfg is not None and d["config_note"] is None
    assert cfg.element_values[VON_MISES]["quad"].shape == (len(d["model"]["cells"]["quad"]),)
    interior = np.setdiff1d(np.arange(len(cfg.displacement)), d["model"]["contact_nodes"])
    assert np.abs(cfg.displacement[interior]).max() > 0
    png = tmp_path / "block.png"
    plot_result(h5, str(png), ray=1)
    _check_png(png)
    with h5py.File(h5, "r+") as f:
        f["model/coords"][0, 0] += 0.5                 # no longer the scene's body
    seal(h5)
    d = _load(h5, -1, 1)
    assert d["config"] is None and "differs" in d["config_note"]
    plot_result(h5, str(png), ray=1)
    _check_png(png)


# ---------------------------------------------------------------- 3D results

PLUG3D_TOML = """\
name = "plug3d-2x4"
dim = 3
[model]
kind = "plug3d"
levels = 2
ring = 4
[friction]
mu = [0.3, 1.0]
[compute]
enumerate = true
mu_c = "cones"
"""

TAB_RED, TAB_BLUE = (214, 39, 40), (31, 119, 180)     # contact set C / reactions, gap set G


def _left_panel(png) -> np.ndarray:
    """The RGB pixels (0..255) of the left half of the figure: the body panel."""
    from matplotlib.image import imread
    img = imread(str(png))[..., :3]
    return np.round(255 * img[:, : img.shape[1] // 2]).astype(int)


def _pixels_near(rgb: np.ndarray, colour, tol: int = 40) -> int:
    return int((np.abs(rgb - np.array(colour)).sum(axis=-1) < tol).sum())


def _check_3d_png(png, contact_and_gap: bool = True) -> np.ndarray:
    """A 3D figure of the expected size whose body panel is drawn (not blank); with
    contact_and_gap, red (C nodes, reactions) and blue (G nodes) marks are in it."""
    assert _check_png(png) == (1500, 750)
    left = _left_panel(png)
    assert left.std() > 20, left.std()                 # an empty 3D axes measures 16
    colour = (left.max(axis=-1) - left.min(axis=-1) > 60).mean()
    assert colour > 0.005, colour                      # the coloured body (an empty 3D axes: 0)
    if contact_and_gap:
        assert _pixels_near(left, TAB_RED) > 50
        assert _pixels_near(left, TAB_BLUE) > 20
    return left


def _petsc_missing() -> str | None:
    try:
        import petsc4py  # noqa: F401
    except ImportError as e:
        return f"petsc4py not importable ({e}); condensation of a model needs it"
    return None


@pytest.mark.skipif(_petsc_missing() is not None, reason=str(_petsc_missing()))
def test_plug3d_png(tmp_path, capsys):
    """plug3d: the whole truss at pattern J's feasible point, C and G marked, reactions,
    wall squares; the patterns' mu^c; the count against mu. Index errors are one line."""
    from hpcwedge.recovery import AXIAL_FORCE
    from hpcwedge.plot import _load
    h5 = _result_file(tmp_path, PLUG3D_TOML)
    d = _load(h5, -1, pattern=0)
    assert d["dim"] == 3 and d["config"] is not None and d["config_note"] is None
    assert d["config"].element_values[AXIAL_FORCE]["line"].shape == (len(d["model"]["cells"]["line"]),)
    counts = [n for _, n in d["counts"]]
    assert len(counts) == 2 and counts[0] < counts[1]             # mu 0.3 < 1: more patterns feasible
    contact = d["patterns"][0]["contact"]
    assert 0 < len(contact) < d["m"]                             # both C and G nodes to draw
    png = tmp_path / "plug.png"
    plot_result(h5, str(png))
    _check_3d_png(png)
    assert main(["plot", h5, "-o", str(tmp_path / "cli.png"), "--run", "0", "--pattern", "-1"]) == 0
    _check_3d_png(tmp_path / "cli.png", contact_and_gap=False)   # mu 0.3: all nodes in contact
    bad = str(tmp_path / "bad.png")
    for args, say in ((["--pattern", "100000"], "pattern 100000 out of range (run 1 has "),
                      (["--run", "5"], "run 5 out of range (the result has 2 run(s)"),
                      (["--ray", "0"], "--ray is for 2D results; this result is 3D")):
        assert main(["plot", h5, "-o", bad] + args) == 2
        err = capsys.readouterr().err
        assert err.startswith("hpcwedge: error: plot: ") and say in err, err
        assert len(err.strip().splitlines()) == 1
    assert not os.path.exists(bad)


@pytest.mark.skipif(_petsc_missing() is not None, reason=str(_petsc_missing()))
def test_gmsh_plug_png(tmp_path):
    """The Gmsh plug (scripts/examples/plug3d.*): the tetra mesh's boundary by von Mises and
    the scene's conical hole; with its mesh file gone, the contact nodes alone, still a figure."""
    from hpcwedge.recovery import VON_MISES
    from hpcwedge.models.obstacle import Cone
    from hpcwedge.plot import _load
    from hpcwedge.scene import load_scene
    for name in ("plug3d.toml", "plug3d.msh"):
        shutil.copy(os.path.join(EXAMPLES, name), tmp_path / name)
    h5 = str(tmp_path / "gmsh.h5")
    write_result(h5, run_scene(load_scene(str(tmp_path / "plug3d.toml"))))
    d = _load(h5, -1, pattern=3)
    assert [type(ob) for ob in d["obstacles"]] == [Cone]
    assert d["config"] is not None and "tetra" in d["config"].element_values[VON_MISES]
    png = tmp_path / "gmsh.png"
    plot_result(h5, str(png), pattern=3)
    _check_3d_png(png)
    os.unlink(tmp_path / "plug3d.msh")
    d = _load(h5, -1, pattern=3)
    assert d["config"] is None and "plug3d.msh not found" in d["config_note"]
    plot_result(h5, str(png), pattern=3)
    _check_3d_png(png, contact_and_gap=False)


@pytest.mark.skipif(_petsc_missing() is not None, reason=str(_petsc_missing()))
@pytest.mark.parametrize("compute", [{"mu_c": "none"}, {"enumerate": False, "mu_c": "global"}])
def test_3d_missing_answers_are_said_in_text(tmp_path, compute):
    # patterns' mu^c not computed / no patterns: the panels say so, the figure is still written
    h5 = _result_file(tmp_path, PLUG3D_TOML.replace("mu = [0.3, 1.0]", "mu = [1.0]"), compute=compute)
    png = tmp_path / "fig.png"
    plot_result(h5, str(png))
    assert _check_png(png) == (1500, 750)


def test_stiffness_3d_bars(tmp_path, capsys):
    """A raw-stiffness 3D scene (no body): bars of r_n and u_n of the pattern's feasible
    point; a run without patterns says so; an index into none is one line."""
    from hpcwedge.plot import _load
    h5 = _result_file(tmp_path, NODE3D_TOML)
    d = _load(h5, -1, pattern=0)
    assert d["model"] is None and d["point"] is not None
    u, r = d["point"]
    assert r[0] == pytest.approx(1.0) and u[0] == pytest.approx(0.0, abs=1e-9)   # node 0 in contact
    png = tmp_path / "node.png"
    plot_result(h5, str(png))
    left = _left_panel(png)
    assert _check_png(png) == (1500, 750) and _pixels_near(left, TAB_RED) > 2000   # the r_n bar
    plot_result(h5, str(png), run=0)                                            # mu 4 < mu^c: none
    _check_png(png)
    assert main(["plot", h5, "-o", str(tmp_path / "bad.png"), "--run", "0", "--pattern", "1"]) == 2
    err = capsys.readouterr().err
    assert "pattern 1 out of range (run 0 has 0 sign pattern(s)" in err and len(err.strip().splitlines()) == 1


NODE3D_TOML = """\
# One contact node in 3D, raw stiffness in block order (n, t1, t2) (shared/scenes/node3d.toml).
name = "node3d"
dim = 3
[model]
kind = "stiffness"
K = [[3.0, 0.4, 0.2],
     [0.4, 2.0, 0.3],
     [0.2, 0.3, 1.5]]
[friction]
mu = [4.0, 5.0]
[compute]
enumerate = true
mu_c = "cones"
"""
