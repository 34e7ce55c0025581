"""Contact patches (models/patch.py): a rigid foot under every contact node, checked against an
independent dense route (patch motions from rigid.rigid_motions, energy minimised by a KKT
solve), on block2d and a 3D hexahedral mesh; a = 0 and empty patches change nothing."""
import numpy as np
import pytest
from model_cases import hex_block as _hex_block

from hpcwedge.cli import main
from hpcwedge.contact.build import build_model
from hpcwedge.contact.condense import condense, schur_dense
from hpcwedge.models import block2d
from hpcwedge.models.mesh import MeshData, mesh_model
from hpcwedge.models.rigid import rigid_motions
from hpcwedge.post.recovery import whole_body
from hpcwedge.run.pipeline import run_scene
from hpcwedge.scene.parse import parse_scene
from hpcwedge.scene.values import SceneError


def _patches_brute(X, boundary, contact, a):
    """Slave nodes per contact node by brute-force distances (no KD-tree, no face tables)."""
    out = []
    for c in contact:
        d = np.linalg.norm(X[boundary] - X[c], axis=1)
        out.append(sorted(set(boundary[d <= a].tolist()) - {int(c)}))
    return out


def _dense_condensed(mdl, patches):
    """K_local by an independent route: admissible motions W = unit DOFs of the nodes in no
    patch + the rigid motions (rigid_motions of the patch's own nodes, independent ones) of
    every patch; the
    energy 1/2 z^T W^T K W z minimised with the contact DOFs prescribed (dense KKT), rotated to
    local frames. Returns (dim*m, dim*m)."""
    X, d = mdl.coords, mdl.dim
    n = len(X)
    in_patch = np.zeros(n, dtype=bool)
    cols = []
    for c, s in zip(mdl.contact_nodes, patches):
        nodes = np.array([c] + list(s))
        if len(s) == 0:
            continue
        in_patch[nodes] = True
        U, sv, _ = np.linalg.svd(rigid_motions(X[nodes], d), full_matrices=False)
        R = U[:, sv > 1e-10 * sv[0]]           # collinear patch nodes in 3D: 5 motions, not 6
        W = np.zeros((n * d, R.shape[1]))
        W[(d * nodes[:, None] + np.arange(d)).ravel()] = R
        cols.append(W)
    free = np.flatnonzero(~in_patch)
    E = np.zeros((n * d, free.size * d))
    E[(d * free[:, None] + np.arange(d)).ravel(), np.arange(free.size * d)] = 1.0
    W = np.hstack([E] + cols)
    KW = W.T @ mdl.K.toarray() @ W
    A = W[mdl.contact_dofs()]                 # contact DOFs as functions of z
    p = A.shape[0]
    KKT = np.block([[KW, A.T], [A, np.zeros((p, p))]])
    S = -np.linalg.inv(KKT)[-p:, -p:]
    T = mdl.local_map()
    return T @ S @ T.T


def _block2d_boundary(rows, cols, refine):
    R, C = rows * refine, cols * refine
    node = np.arange((R + 1) * (C + 1)).reshape(R + 1, C + 1)
    return np.unique(np.concatenate([node[0], node[-1], node[:, 0], node[:, -1]]))


def _rel(A, B):
    return np.abs(A - B).max() / np.abs(B).max()


def test_zero_patch_is_bit_for_bit_the_point_contact():
    ref, zero = block2d(rows=3, refine=3), block2d(rows=3, refine=3, contact_patch=0)
    assert zero.tie is None and (zero.K != ref.K).nnz == 0
    K0, N0 = condense(ref)
    K1, N1 = condense(zero)
    assert np.array_equal(K0, K1) and np.array_equal(N0, N1)
    scene = {"name": "p", "dim": 2, "friction": {"mu": [0.65]}, "model": {"kind": "block2d", "rows": 3}}
    a = run_scene(parse_scene(scene))
    scene["model"]["contact_patch"] = 0.0
    b = run_scene(parse_scene(scene))
    assert a.mu_c == b.mu_c
    assert [c.mu_c for c in a.runs[0].cones] == [c.mu_c for c in b.runs[0].cones]


def test_patch_covering_no_node_changes_nothing():
    """rows 3 refine 2: side nodes 0.169 apart, bottom/top nodes >= 0.25: a = 0.15 holds none."""
    assert _patches_brute(block2d(rows=3, refine=2).coords, _block2d_boundary(3, 2, 2),
                          block2d(rows=3, refine=2).contact_nodes, 0.15) == [[]] * 8
    mdl = block2d(rows=3, refine=2, contact_patch=0.15)
    assert mdl.tie is None
    assert np.array_equal(condense(mdl)[0], condense(block2d(rows=3, refine=2))[0])


@pytest.mark.parametrize("a", [0.09, 0.15])
def test_block2d_patch_matches_dense_route_and_keeps_rigid_modes(a):
    rows, refine = 3, 4
    mdl = block2d(rows=rows, refine=refine, contact_patch=a)
    patches = _patches_brute(mdl.coords, _block2d_boundary(rows, 2, refine), mdl.contact_nodes, a)
    assert all(len(s) > 0 for s in patches)
    slaves = np.concatenate([np.array(s, dtype=np.int64) for s in patches])
    assert np.array_equal(mdl.tie.slave_dofs, np.sort((2 * slaves[:, None] + np.arange(2)).ravel()))
    K, N = condense(mdl)
    assert N.shape[1] == 3
    assert np.abs(K @ N).max() <= 1e-10 * np.abs(K).max()
    assert _rel(K, _dense_condensed(mdl, patches)) < 1e-10
    assert _rel(schur_dense(mdl)[0], K) < 1e-10
    # the foot stiffens the body: K_patch - K_point is positive semidefinite
    lam = np.linalg.eigvalsh(K - condense(block2d(rows=rows, refine=refine))[0])
    assert lam[0] > -1e-10 * lam[-1] and lam[-1] > 0


def test_tie_maps_rigid_motions_to_rigid_motions():
    mdl = block2d(rows=3, refine=4, contact_patch=0.15)
    Q = mdl.tie.T.toarray()
    R = rigid_motions(mdl.coords, 2)
    z = np.linalg.lstsq(Q, R, rcond=None)[0]
    assert np.abs(Q @ z - R).max() < 1e-12


def test_3d_hexahedral_patch_matches_dense_route():
    X, H, nid = _hex_block(4, 4, 4)
    contact = np.array([nid(0, 1, 1), nid(0, 3, 3), nid(4, 2, 2), nid(2, 0, 2), nid(2, 4, 2), nid(2, 2, 0)])
    normals = [[1, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]]
    mesh = MeshData(name="block", points=X, cells={"hexahedron": H}, groups={})
    mdl = mesh_model(mesh, contact_nodes=contact, normals=normals, contact_patch=1.05)
    ids = np.arange(len(X))
    i, j, k = ids % 5, ids // 5 % 5, ids // 25
    bnd = np.flatnonzero(np.isin(i, [0, 4]) | np.isin(j, [0, 4]) | np.isin(k, [0, 4]))
    patches = _patches_brute(X, bnd, contact, 1.05)
    assert all(len(s) >= 2 for s in patches)
    K, N = condense(mdl)
    assert N.shape[1] == 6
    assert np.abs(K @ N).max() <= 1e-10 * np.abs(K).max()
    assert _rel(K, _dense_condensed(mdl, patches)) < 1e-10


def test_whole_body_with_patches_is_in_equilibrium_and_feet_rigid():
    mdl = block2d(rows=3, refine=4, contact_patch=0.15)
    K, _ = condense(mdl)
    u = np.random.default_rng(0).standard_normal(K.shape[0])
    cfg = whole_body(mdl, u, K @ u)
    U = cfg.displacement.ravel()
    res = mdl.tie.T.T @ (mdl.K @ U - cfg.reaction.ravel())
    assert np.abs(res).max() < 1e-9 * np.abs(mdl.K @ U).max()
    patches = _patches_brute(mdl.coords, _block2d_boundary(3, 2, 4), mdl.contact_nodes, 0.15)
    for c, s in zip(mdl.contact_nodes, patches):      # each foot moves rigidly (no strain)
        nodes = [c] + s
        R = rigid_motions(mdl.coords[nodes], 2)
        v = cfg.displacement[nodes].ravel()
        assert np.abs(v - R @ np.linalg.lstsq(R, v, rcond=None)[0]).max() < 1e-10 * np.abs(v).max()


def _scene_text(a, refine=8):
    return (f'name = "p"\ndim = 2\n[model]\nkind = "block2d"\nrows = 5\nrefine = {refine}\n'
            f'contact_patch = {a}\n[friction]\nmu = [0.65]\n')


def test_overlapping_patches_exit_2(tmp_path, capsys):
    """rows 5: contact nodes 0.203 apart on a side; a = 0.15 makes the patches share nodes."""
    path = tmp_path / "s.toml"
    path.write_text(_scene_text(0.15))
    out = tmp_path / "r.h5"
    assert main(["run", str(path), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "model.contact_patch" in err and "overlap" in err and len(err.splitlines()) == 1
    assert not out.exists()
    with pytest.raises(SceneError, match="model.contact_patch: the patches of contact nodes 0 and 1"):
        build_model(parse_scene({"name": "p", "dim": 2, "friction": {"mu": [0.65]},
                                 "model": {"kind": "block2d", "rows": 5, "refine": 8, "contact_patch": 0.15}}))


@pytest.mark.parametrize("model", [{"kind": "block2d", "contact_patch": -0.1},
                                   {"kind": "mesh", "file": "x.msh", "contact_patch": -1},
                                   {"kind": "block2d", "contact_patch": float("nan")}])
def test_negative_patch_rejected_by_the_scene(model):
    scene = {"name": "p", "dim": 2, "friction": {"mu": [0.65]}, "model": model,
             "contact": {"nodes": [0], "normals": [[1, 0]]}}
    with pytest.raises(SceneError, match=r"model.contact_patch: must be"):
        parse_scene(scene)


def test_negative_patch_exit_2(tmp_path, capsys):
    path = tmp_path / "s.toml"
    path.write_text(_scene_text(-0.05))
    assert main(["run", str(path), "-o", str(tmp_path / "r.h5")]) == 2
    assert "model.contact_patch" in capsys.readouterr().err


def test_patch_on_supported_node_rejected():
    X, H, nid = _hex_block(2, 2, 2)
    mesh = MeshData(name="block", points=X, cells={"hexahedron": H}, groups={})
    with pytest.raises(ValueError, match="model.contact_patch: the node at .* is supported"):
        mesh_model(mesh, contact_nodes=[nid(0, 1, 1)], normals=[[1, 0, 0]], contact_patch=1.0,
                   supports=[[nid(0, 1, 2), 0]])


def _hat_dense_condensed(mdl, patches, a):
    """K_local of hat patches by an independent route: minimise 1/2 u^T K u over all nodal
    displacements subject to A u = u_c, A's row (contact node i, component k) holding the
    normalised weights max(0, 1 - d/a) of the patch nodes (dense KKT)."""
    X, d = mdl.coords, mdl.dim
    n, m = len(X), mdl.m
    A = np.zeros((d * m, n * d))
    for i, (c, s) in enumerate(zip(mdl.contact_nodes, patches)):
        nodes = np.array([c] + list(s))
        w = 1 - np.linalg.norm(X[nodes] - X[c], axis=1) / a
        w /= w.sum()
        for k in range(d):
            A[d * i + k, d * nodes + k] = w
    p = A.shape[0]
    KKT = np.block([[mdl.K.toarray(), A.T], [A, np.zeros((p, p))]])
    S = -np.linalg.inv(KKT)[-p:, -p:]
    T = mdl.local_map()
    return T @ S @ T.T


@pytest.mark.parametrize("a", [0.09, 0.15])
def test_hat_patch_matches_dense_route_and_keeps_rigid_modes(a):
    rows, refine = 3, 4
    mdl = block2d(rows=rows, refine=refine, contact_patch=a, contact_patch_kind="hat")
    patches = _patches_brute(mdl.coords, _block2d_boundary(rows, 2, refine), mdl.contact_nodes, a)
    K, N = condense(mdl)
    assert N.shape[1] == 3
    assert np.abs(K @ N).max() <= 1e-10 * np.abs(K).max()
    assert _rel(K, _hat_dense_condensed(mdl, patches, a)) < 1e-10
    assert _rel(K, condense(block2d(rows=rows, refine=refine, contact_patch=a))[0]) > 1e-3  # not the foot


def test_hat_patch_3d_and_whole_body():
    X, H, nid = _hex_block(4, 4, 4)
    contact = np.array([nid(0, 1, 1), nid(0, 3, 3), nid(4, 2, 2), nid(2, 0, 2), nid(2, 4, 2), nid(2, 2, 0)])
    normals = [[1, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]]
    mesh = MeshData(name="block", points=X, cells={"hexahedron": H}, groups={})
    mdl = mesh_model(mesh, contact_nodes=contact, normals=normals, contact_patch=1.05, contact_patch_kind="hat")
    ids = np.arange(len(X))
    i, j, k = ids % 5, ids // 5 % 5, ids // 25
    bnd = np.flatnonzero(np.isin(i, [0, 4]) | np.isin(j, [0, 4]) | np.isin(k, [0, 4]))
    patches = _patches_brute(X, bnd, contact, 1.05)
    K, N = condense(mdl)
    assert N.shape[1] == 6 and np.abs(K @ N).max() <= 1e-10 * np.abs(K).max()
    assert _rel(K, _hat_dense_condensed(mdl, patches, 1.05)) < 1e-10
    # whole body: the contact DOFs are the weighted means of the patch displacements
    u = np.random.default_rng(1).standard_normal(K.shape[0])
    cfg = whole_body(mdl, u, K @ u)
    uc = (mdl.local_map().T @ u).reshape(-1, 3)
    for c, s, want in zip(contact, patches, uc):
        nodes = np.array([c] + s)
        w = 1 - np.linalg.norm(X[nodes] - X[c], axis=1) / 1.05
        np.testing.assert_allclose(w @ cfg.displacement[nodes] / w.sum(), want, atol=1e-10)


def test_patch_kind_checked_by_the_scene():
    scene = {"name": "p", "dim": 2, "friction": {"mu": [0.65]},
             "model": {"kind": "block2d", "contact_patch": 0.05, "contact_patch_kind": "soft"}}
    with pytest.raises(SceneError, match=r"model.contact_patch_kind: one of 'rigid', 'hat', got 'soft'"):
        parse_scene(scene)
    scene["model"]["contact_patch_kind"] = "hat"
    assert parse_scene(scene).model["contact_patch_kind"] == "hat"


def test_run_and_export_with_rigid_patches(tmp_path, capsys):
    """The command line end to end: run a patched block2d, export a ray; every foot moves rigidly."""
    import meshio
    path = tmp_path / "s.toml"
    path.write_text(_scene_text(0.09, refine=4).replace("rows = 5", "rows = 3"))
    out, vtu = str(tmp_path / "r.h5"), str(tmp_path / "c.vtu")
    assert main(["run", str(path), "-o", out, "--quiet"]) == 0
    assert main(["export", out, "--ray", "0", "-o", vtu]) == 0
    U = meshio.read(vtu).point_data["displacement"][:, :2]
    mdl = block2d(rows=3, refine=4, contact_patch=0.09)
    assert np.abs(U).max() > 0
    for c, s in zip(mdl.contact_nodes, _patches_brute(mdl.coords, _block2d_boundary(3, 2, 4),
                                                      mdl.contact_nodes, 0.09)):
        nodes = [c] + s
        R = rigid_motions(mdl.coords[nodes], 2)
        v = U[nodes].ravel()
        assert np.abs(v - R @ np.linalg.lstsq(R, v, rcond=None)[0]).max() < 1e-9 * np.abs(U).max()
