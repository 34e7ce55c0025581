"""Whole-body configurations (hpcwedge.post.recovery): the recovered displacement against
an independently assembled full stiffness, uniqueness on supported bodies, the items
(ray, cone, pattern), element values, and one-line errors (the VTU file: test_export.py)."""
import json
import math
import shutil

import h5py
import meshio
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from hpcwedge.models import block2d, plug2d, q4_stiffness
from hpcwedge.models.elements import lame
from hpcwedge.post.recovery import (
    AXIAL_FORCE,
    VON_MISES,
    ConfigurationError,
    element_values,
    load_configuration,
    whole_body,
)
from hpcwedge.results.hdf5 import write_result
from hpcwedge.run.pipeline import run_scene
from hpcwedge.scene.parse import load_scene

PLUG2D = 'name = "plug2d"\ndim = 2\n[model]\nkind = "plug2d"\nrows = 3\n[friction]\nmu = [0.65]\n'
BLOCK2D = ('name = "block2d"\ndim = 2\n[model]\nkind = "block2d"\nrows = 2\nrefine = 2\nE = 2.0\nnu = 0.25\n'
           '[friction]\nmu = [0.65]\n')
PLUG3D = 'name = "plug3d"\ndim = 3\n[model]\nkind = "plug3d"\nring = 4\n[friction]\nmu = [0.65]\n'
STIFFNESS = 'name = "k"\ndim = 2\n[model]\nkind = "stiffness"\nK = [[2.0, 0.5], [0.5, 1.0]]\n[friction]\nmu = [2.5]\n'


def _supported_truss() -> str:
    """plug2d rows 3 as a `truss` scene, its middle column's centre node pinned and the top
    middle node held horizontally: no rigid mode left, interior DOFs present."""
    mdl = plug2d(rows=3)
    return ('name = "pinned"\ndim = 2\n[model]\nkind = "truss"\n'
            f"nodes = {mdl.coords.tolist()}\nbars = {mdl.cells['line'].tolist()}\nEA = 1.0\n"
            "supports = [[4, 0], [4, 1], [7, 0]]\n"
            f"[contact]\nnodes = {mdl.contact_nodes.tolist()}\nnormals = {mdl.normals.tolist()}\n"
            "[friction]\nmu = [2.0]\n")


def solve(folder, text, name="s.toml", out="r.h5"):
    """Run a scene text written into folder; return the result path."""
    p = folder / name
    p.write_text(text)
    res = run_scene(load_scene(str(p)))
    path = str(folder / out)
    write_result(path, res)
    return path


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    d = tmp_path_factory.mktemp("configuration")
    return {k: solve(d, text, f"{k}.toml", f"{k}.h5") for k, text in
            [("plug2d", PLUG2D), ("plug2d_patterns", PLUG2D + '[compute]\nenumerate = "patterns"\n'),
             ("block2d", BLOCK2D), ("plug3d", PLUG3D), ("pinned", _supported_truss()),
             ("stiffness", STIFFNESS)]}


# ----------------------------------------------------------------------------- references

def _truss_K(coords, bars, EA):
    """Full truss stiffness by a plain loop over bars (independent of truss_stiffness)."""
    n, d = coords.shape
    K = np.zeros((n * d, n * d))
    for a, b in bars:
        e = coords[b] - coords[a]
        L = np.linalg.norm(e)
        e /= L
        k = EA / L * np.outer(e, e)
        for i, j, s in ((a, a, 1), (b, b, 1), (a, b, -1), (b, a, -1)):
            K[d * i:d * i + d, d * j:d * j + d] += s * k
    return K


def _full_K(model, kind):
    if kind.startswith("block2d"):
        return q4_stiffness(model.coords, model.cells["quad"], E=2.0, nu=0.25).toarray()
    return _truss_K(model.coords, model.cells["line"], 1.0)


def _frame_vectors(model, v_local):
    """Local block-ordered contact vector -> (m, dim) global, from the normals and tangents."""
    m, d = model.m, model.dim
    comps = v_local.reshape(d, m).T                         # (m, dim): n, t (, t2) components
    axes = np.concatenate([model.normals[:, None, :], model.tangents], axis=1)
    return np.einsum("ia,iaj->ij", comps, axes)


CASES = [("plug2d", {"ray": 5}), ("plug2d", {"cone": 0}), ("plug2d_patterns", {"pattern": 0}), ("block2d", {"ray": -1}),
         ("block2d", {"cone": 1}), ("plug3d", {"pattern": 0}), ("plug3d", {"pattern": -1}),
         ("pinned", {"ray": 0})]


@pytest.mark.parametrize("kind,item", CASES)
def test_full_stiffness_equilibrium(results, kind, item):
    """K u = f at every free DOF, with K assembled anew, f = 0 off the contact nodes and
    f = the item's reactions rotated to global axes at them; u at the contact nodes is the
    item's u rotated to global axes."""
    cfg = load_configuration(results[kind], **item)
    mdl = cfg.model
    K = _full_K(mdl, kind)
    u, f = cfg.displacement.ravel(), cfg.reaction.ravel()
    free = np.setdiff1d(np.arange(mdl.n_dofs), mdl.fixed_dofs)
    scale = np.abs(K).max() * np.abs(u).max()
    assert np.abs((K @ u - f)[free]).max() <= 1e-10 * scale
    off = np.ones(mdl.coords.shape[0], bool)
    off[mdl.contact_nodes] = False
    assert not cfg.reaction[off].any()
    np.testing.assert_allclose(cfg.reaction[mdl.contact_nodes], _frame_vectors(mdl, cfg.r_local), atol=1e-14)
    np.testing.assert_allclose(cfg.displacement[mdl.contact_nodes], _frame_vectors(mdl, cfg.u_local), atol=1e-14)
    assert np.abs(u[mdl.fixed_dofs]).max(initial=0.0) == 0.0
    # the interior moves (not only the contact nodes)
    assert np.abs(cfg.displacement[off]).max() > 1e-3 * np.abs(cfg.displacement).max()
    # a wedged configuration: sum r_n = 1, u_n >= 0, r_n >= 0, complementarity, friction
    m, d = mdl.m, mdl.dim
    un, rn = cfg.u_local[:m], cfg.r_local[:m]
    rt = np.linalg.norm(cfg.r_local[m:].reshape(d - 1, m), axis=0)
    assert math.isclose(rn.sum(), 1.0, rel_tol=1e-9)
    tol = 1e-7 * np.abs(cfg.u_local).max()
    assert un.min() >= -tol and rn.min() >= -1e-9 and np.abs(un * rn).max() <= tol
    mu = 2.0 if kind == "pinned" else 0.65
    assert (rt <= mu * rn + 1e-7).all()


def test_fails_without_the_interior(results):
    """The equilibrium check can fail: contact nodes displaced, interior left at zero."""
    cfg = load_configuration(results["block2d"], ray=0)
    mdl = cfg.model
    u = np.zeros_like(cfg.displacement)
    u[mdl.contact_nodes] = cfg.displacement[mdl.contact_nodes]
    r = _full_K(mdl, "block2d") @ u.ravel() - cfg.reaction.ravel()
    assert np.abs(r).max() > 1e-3 * np.abs(cfg.reaction).max()


def test_supported_body_is_the_unique_solution(results):
    """Supported body (no rigid modes): u is K_ff^-1 f_ff, no rigid motion to add."""
    cfg = load_configuration(results["pinned"], ray=0)
    mdl = cfg.model
    assert mdl.rigid_modes.shape[1] == 0 and len(mdl.fixed_dofs) == 3
    free = np.setdiff1d(np.arange(mdl.n_dofs), mdl.fixed_dofs)
    K = sp.csc_matrix(_full_K(mdl, "pinned")[np.ix_(free, free)])
    u = spla.spsolve(K, cfg.reaction.ravel()[free])
    assert np.abs(u - cfg.displacement.ravel()[free]).max() <= 1e-10 * np.abs(u).max()


def test_free_body_differs_from_a_solution_by_a_rigid_motion(results):
    """Free body: u minus the least-squares solution of K u = f is a rigid motion."""
    cfg = load_configuration(results["plug2d"], ray=3)
    mdl = cfg.model
    K = _full_K(mdl, "plug2d")
    u0 = np.linalg.lstsq(K, cfg.reaction.ravel(), rcond=1e-12)[0]
    w = cfg.displacement.ravel() - u0
    Q = np.linalg.qr(mdl.rigid_modes)[0]
    assert np.linalg.norm(w - Q @ (Q.T @ w)) <= 1e-9 * np.linalg.norm(cfg.displacement)


def test_bar_forces_balance_the_reactions(results):
    """Truss: at every node, sum over its bars of N e (pointing away from the node) + f = 0."""
    for kind, item in (("plug2d", {"ray": 1}), ("plug3d", {"pattern": 2})):
        cfg = load_configuration(results[kind], **item)
        mdl = cfg.model
        N = cfg.element_values[AXIAL_FORCE]["line"]
        acc = cfg.reaction.copy()
        for (a, b), Nb in zip(mdl.cells["line"], N):
            e = mdl.coords[b] - mdl.coords[a]
            e /= np.linalg.norm(e)
            acc[a] += Nb * e
            acc[b] -= Nb * e
        assert np.abs(acc).max() <= 1e-10 * np.abs(N).max()
        assert set(cfg.element_values) == {AXIAL_FORCE}


def test_von_mises_of_a_uniform_strain():
    """block2d with an imposed uniform strain: every element has the analytic von Mises
    stress (plane stress, E = 2, nu = 0.25)."""
    mdl = block2d(rows=2, cols=2, refine=2, E=2.0, nu=0.25)
    G = np.array([[1e-3, 4e-4], [-1e-4, -2e-3]])
    vm = element_values(mdl, mdl.coords @ G.T)[VON_MISES]["quad"]
    eps = 0.5 * (G + G.T)
    lam, mu = lame(2.0, 0.25, 2)
    s = lam * np.trace(eps) * np.eye(2) + 2 * mu * eps
    ref = math.sqrt(s[0, 0] ** 2 - s[0, 0] * s[1, 1] + s[1, 1] ** 2 + 3 * s[0, 1] ** 2)
    assert len(vm) == len(mdl.cells["quad"])
    np.testing.assert_allclose(vm, ref, rtol=1e-12)


def test_rigid_motion_of_the_contact_nodes_moves_the_body_rigidly():
    """Contact nodes moved by a rigid motion (no reactions): every node follows it, no stress."""
    mdl = block2d(rows=2, refine=2)
    u = (mdl.rigid_modes @ np.array([0.3, -0.2, 0.5])).reshape(-1, 2)
    cfg = whole_body(mdl, mdl.local_map() @ u[mdl.contact_nodes].ravel(), np.zeros(2 * mdl.m))
    np.testing.assert_allclose(cfg.displacement, u, atol=1e-12)
    assert cfg.element_values[VON_MISES]["quad"].max() <= 1e-12


def test_cone_is_the_mean_of_its_rays(results):
    with h5py.File(results["plug2d"], "r") as f:
        rays = f["runs/000/rays"][()]
        cone = json.loads(f["runs/000/cones_json"][()])[0]
    cfg = load_configuration(results["plug2d"], cone=0)
    n = rays.shape[1] // 2
    np.testing.assert_allclose(cfg.u_local, rays[cone["rays"], :n].mean(0), atol=1e-15)
    np.testing.assert_allclose(cfg.r_local, rays[cone["rays"], n:].mean(0), atol=1e-15)


def test_pattern_point_matches_the_pattern(results):
    """plug3d: r = 0 at the gap nodes, u_n = 0 at the contact nodes, in the cones at mu."""
    with h5py.File(results["plug3d"], "r") as f:
        pats = json.loads(f["runs/000/patterns_json"][()])
    for j in (0, 3):
        cfg = load_configuration(results["plug3d"], pattern=j)
        m = cfg.model.m
        C = np.isin(np.arange(m), pats[j]["contact"])
        r = cfg.r_local.reshape(3, m)
        scale = np.abs(cfg.u_local).max()
        assert np.abs(cfg.u_local[:m][C]).max() <= 1e-7 * scale
        assert np.abs(r[:, ~C]).max(initial=0.0) <= 1e-7
        assert (np.linalg.norm(r[1:, C], axis=0) <= 0.65 * r[0, C] + 1e-7).all()


# ----------------------------------------------------------------------------- errors

@pytest.mark.parametrize("kind,kw,phrase", [
    ("plug2d", {"run": 1, "ray": 0}, "run 1 out of range"),
    ("plug2d", {"run": -2, "ray": 0}, "run -2 out of range"),
    ("plug2d", {"ray": 10 ** 6}, "ray 1000000 out of range"),
    ("plug2d", {"cone": 1}, "cone 1 out of range"),
    ("plug2d", {"pattern": 0}, "has no patterns"),
    ("plug3d", {"ray": 0}, "has no wedged rays"),
    ("plug3d", {"cone": 0}, "has no cones"),
    ("plug3d", {"pattern": 999}, "pattern 999 out of range"),
    ("stiffness", {"ray": 0}, "no body to export"),
])
def test_errors(results, kind, kw, phrase):
    with pytest.raises(ConfigurationError, match=phrase) as e:
        load_configuration(results[kind], **kw)
    assert "\n" not in str(e.value)


def test_mesh_file_found_beside_the_scene_or_the_result(tmp_path):
    """A mesh scene: the file is looked up beside the scene (recorded in the result), then
    beside the result; a changed mesh is refused."""
    ref = block2d(rows=2)
    scene_dir, out_dir = tmp_path / "scene", tmp_path / "out"
    scene_dir.mkdir()
    out_dir.mkdir()
    meshio.write(str(scene_dir / "body.vtu"), meshio.Mesh(ref.coords, [("quad", ref.cells["quad"])]))
    text = ('name = "m"\ndim = 2\n[model]\nkind = "mesh"\nfile = "body.vtu"\n[contact]\n'
            f"nodes = {ref.contact_nodes.tolist()}\nnormals = {ref.normals.tolist()}\n[friction]\nmu = [0.65]\n")
    (scene_dir / "s.toml").write_text(text)
    res = str(out_dir / "r.h5")
    write_result(res, run_scene(load_scene(str(scene_dir / "s.toml"))))
    cfg = load_configuration(res, ray=0)
    assert VON_MISES in cfg.element_values
    shutil.move(str(scene_dir / "body.vtu"), str(tmp_path / "elsewhere.vtu"))
    with pytest.raises(ConfigurationError, match=r"model.file: body.vtu not found"):
        load_configuration(res, ray=0)
    shutil.copy(str(tmp_path / "elsewhere.vtu"), str(out_dir / "body.vtu"))
    np.testing.assert_allclose(load_configuration(res, ray=0).displacement, cfg.displacement)
    moved = ref.coords.copy()
    moved[0] += 0.01
    meshio.write(str(out_dir / "body.vtu"), meshio.Mesh(moved, [("quad", ref.cells["quad"])]))
    with pytest.raises(ConfigurationError, match="model.file body.vtu changed since the result was written"):
        load_configuration(res, ray=0)
