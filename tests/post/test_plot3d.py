"""plot3d.py: figures of 3D result files (pipeline -> write_result -> plot_result): the body
at a pattern's feasible point with C and G marked, the patterns' mu^c, the count against mu."""
import os
import shutil

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from instances import check_png, result_file

from hpcwedge.cli import main
from hpcwedge.post.plot import plot_result
from hpcwedge.results.hdf5 import write_result
from hpcwedge.run.pipeline import run_scene

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
EXAMPLES = os.path.join(ROOT, "scripts", "examples")


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
    assert check_png(png) == (1500, 750)
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
    from hpcwedge.post.plot import _load
    from hpcwedge.post.recovery import AXIAL_FORCE
    h5 = result_file(tmp_path, PLUG3D_TOML)
    d = _load(h5, -1, pattern=0)
    assert d["dim"] == 3 and d["config"] is not None and d["config_note"] is None
    assert d["config"].element_values[AXIAL_FORCE]["line"].shape == (len(d["model"].cells["line"]),)
    counts = [n for _, n in d["counts"]]
    assert len(counts) == 2 and counts[0] < counts[1]             # mu 0.3 < 1: more patterns feasible
    contact = d["patterns"][0].contact
    assert 0 < len(contact) < d["m"]                             # both C and G nodes to draw
    png = tmp_path / "plug.png"
    plot_result(h5, str(png))
    _check_3d_png(png)
    assert main(["plot", h5, "-o", str(tmp_path / "cli.png"), "--run", "0", "--pattern", "-1"]) == 0
    _check_3d_png(tmp_path / "cli.png", contact_and_gap=False)   # mu 0.3: all nodes in contact
    assert capsys.readouterr().err.startswith("[hpcwedge] run 0 (mu = 0.3), sign pattern ")
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
    from hpcwedge.models.obstacle import Cone
    from hpcwedge.post.plot import _load
    from hpcwedge.post.recovery import VON_MISES
    from hpcwedge.scene.parse import load_scene
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
    h5 = result_file(tmp_path, PLUG3D_TOML.replace("mu = [0.3, 1.0]", "mu = [1.0]"), compute=compute)
    png = tmp_path / "fig.png"
    plot_result(h5, str(png))
    assert check_png(png) == (1500, 750)


def test_stiffness_3d_bars(tmp_path, capsys):
    """A raw-stiffness 3D scene (no body): bars of r_n and u_n of the pattern's feasible
    point; a run without patterns says so; an index into none is one line."""
    from hpcwedge.post.plot import _load
    h5 = result_file(tmp_path, NODE3D_TOML)
    d = _load(h5, -1, pattern=0)
    assert d["model"] is None and d["point"] is not None
    u, r = d["point"]
    assert r[0] == pytest.approx(1.0) and u[0] == pytest.approx(0.0, abs=1e-9)   # node 0 in contact
    png = tmp_path / "node.png"
    plot_result(h5, str(png))
    left = _left_panel(png)
    assert check_png(png) == (1500, 750) and _pixels_near(left, TAB_RED) > 2000   # the r_n bar
    plot_result(h5, str(png), run=0)                                            # mu 4 < mu^c: none
    check_png(png)
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


@pytest.mark.parametrize("counts,mu,mu_c", [([(0.1, 0)], 0.1, 0.1763),              # every run below mu^c
                                            ([(0.3, 2), (1.0, 131)], 1.0, 0.1763),  # mu^c below every run
                                            ([(0.3, 2), (1.0, 7)], 0.3, None)])
def test_counts_panel_shows_the_global_mu_c_and_whole_counts(counts, mu, mu_c):
    """The count-against-mu panel keeps every run and the global mu^c line in view (before:
    a mu^c above every run's mu was drawn off the axes, listed only in the legend) and
    ticks its counts at whole numbers."""
    from matplotlib.figure import Figure

    from hpcwedge.post.plot3d import _counts_panel
    ax = Figure().add_subplot()
    _counts_panel(ax, {"counts": counts, "mu": mu, "mu_c": mu_c})
    lo, hi = ax.get_xlim()
    for v in [c[0] for c in counts] + ([mu_c] if mu_c is not None else []):
        assert lo < v < hi
    ticks = [t for t in ax.get_yticks() if ax.get_ylim()[0] <= t <= ax.get_ylim()[1]]
    assert len(ticks) >= 2 and all(float(t).is_integer() for t in ticks)
