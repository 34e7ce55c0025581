"""The built-in bodies (hpcwedge/models/library.py): their rigid modes are the kernel of K,
frames orthonormal and right-handed, normals into the body, geometry by hand, validation."""
import math

import numpy as np
import pytest
from instances import kernel_dim, python_calls

from hpcwedge.models import block2d, builtin, plug2d, plug3d, vgroove_bar

# ---------------------------------------------------------------- truss element


# ---------------------------------------------------------------- Q4 element


# ---------------------------------------------------------------- rigid modes


# ---------------------------------------------------------------- built-ins
BUILTIN_CASES = [
    ("vgroove_bar", {}), ("vgroove_bar", {"eps": 0.1}), ("plug2d", {}), ("plug2d", {"rows": 5, "cols": 4}),
    ("plug3d", {}), ("plug3d", {"levels": 3, "ring": 6}), ("block2d", {"rows": 2, "refine": 2}),
]


@pytest.mark.parametrize("kind,params", BUILTIN_CASES)
def test_builtin_rigid_modes_are_kernel(kind, params):
    m = builtin(kind, params)
    K = m.K
    assert (K != K.T).nnz == 0
    k = m.rigid_modes.shape[1]
    if k:
        assert np.abs(K @ m.rigid_modes).max() < 1e-13 * abs(K).max()
        np.testing.assert_allclose(m.rigid_modes.T @ m.rigid_modes, np.eye(k), atol=1e-13)
    nk, ev = kernel_dim(K)
    assert nk == k and ev[0] > -1e-12 * ev[-1]          # no mechanism beyond the rigid modes
    # frames orthonormal and right-handed
    F = m.frames()
    np.testing.assert_allclose(F @ F.transpose(0, 2, 1), np.broadcast_to(np.eye(m.dim), F.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(F), 1.0 if m.dim == 3 else -1.0, atol=1e-14)


def _into_body(m):
    """Normals point into the body: from the contact node towards the centroid (inward) and up."""
    c = m.coords.mean(axis=0)
    x = m.coords[m.contact_nodes]
    horiz = (c - x)
    horiz[:, -1] = 0.0
    inward = (m.normals * horiz).sum(1)
    return np.all(inward > 0) and np.all(m.normals[:, -1] > 0)


def test_vgroove_bar():
    th = 30.0
    m = vgroove_bar(th)
    c, s = math.cos(math.radians(th)), math.sin(math.radians(th))
    np.testing.assert_allclose(m.normals, [[c, s], [-c, s]], atol=1e-15)
    np.testing.assert_allclose(m.tangents[:, 0], [[s, -c], [s, c]], atol=1e-15)
    assert m.rigid_modes.shape == (4, 3) and _into_body(m)
    assert m.K[0, 0] == 0.5
    me = vgroove_bar(th, eps=0.2)
    assert me.rigid_modes.shape == (4, 0)
    np.testing.assert_allclose(me.K.toarray() - m.K.toarray(), 0.2 * np.eye(4), atol=1e-15)


def test_plug2d_geometry():
    rows, cols, tau = 4, 3, 10.0
    m = plug2d(rows, cols, tau)
    assert m.coords.shape == (12, 2) and m.m == 8 and m.rigid_modes.shape == (24, 3)
    assert m.cells["line"].shape == (rows * (cols - 1) + (rows - 1) * cols + 2 * (rows - 1) * (cols - 1), 2)
    t = math.tan(math.radians(tau))
    x = m.coords[m.contact_nodes]
    np.testing.assert_allclose(x[:rows, 0], -(0.5 + x[:rows, 1] * t), atol=1e-15)   # on the left wall
    np.testing.assert_allclose(x[rows:, 0], 0.5 + x[rows:, 1] * t, atol=1e-15)
    np.testing.assert_allclose(x[:rows, 1], np.linspace(0, 1, rows), atol=1e-15)    # bottom to top
    np.testing.assert_allclose(np.linalg.norm(m.normals, axis=1), 1.0)
    wall = np.array([-math.sin(math.radians(tau)), math.cos(math.radians(tau))])    # left wall direction
    np.testing.assert_allclose(m.normals[:rows] @ wall, 0.0, atol=1e-15)
    assert _into_body(m)


def test_plug3d_geometry():
    m = plug3d(2, 5, 10.0)
    assert m.coords.shape == (12, 3) and m.m == 10 and m.rigid_modes.shape == (36, 6)
    t = math.tan(math.radians(10.0))
    x = m.coords[m.contact_nodes]
    np.testing.assert_allclose(np.hypot(x[:, 0], x[:, 1]), 0.5 + x[:, 2] * t, atol=1e-15)
    np.testing.assert_allclose(x[:, 2], np.repeat([0.0, 1.0], 5))
    np.testing.assert_allclose(np.linalg.norm(m.normals, axis=1), 1.0)
    # normal perpendicular to the cone generator and to the ring; t1 counter-clockwise
    er = np.c_[x[:, :2], np.zeros(10)] / np.hypot(x[:, 0], x[:, 1])[:, None]
    gen = math.sin(math.radians(10.0)) * er + math.cos(math.radians(10.0)) * np.array([0, 0, 1.0])
    np.testing.assert_allclose((m.normals * gen).sum(1), 0.0, atol=1e-15)
    assert np.all(np.cross(er, m.tangents[:, 0])[:, 2] > 0)
    np.testing.assert_allclose(m.tangents[:, 1], np.cross(m.normals, m.tangents[:, 0]), atol=1e-15)
    assert _into_body(m)
    assert plug3d(1, 4).coords.shape == (5, 3)


def test_block2d_geometry():
    rows, cols, refine = 5, 2, 3
    m = block2d(rows, cols, refine)
    R, C = rows * refine, cols * refine
    assert m.coords.shape == ((R + 1) * (C + 1), 2) and m.cells["quad"].shape == (R * C, 4)
    assert m.m == 2 * (rows + 1) and m.rigid_modes.shape == (m.n_dofs, 3)
    x = m.coords[m.contact_nodes]
    t = math.tan(math.radians(10.0))
    np.testing.assert_allclose(x[: rows + 1], np.c_[-(0.5 + np.linspace(0, 1, rows + 1) * t), np.linspace(0, 1, rows + 1)],
                               atol=1e-15)
    np.testing.assert_allclose(x[rows + 1:, 0], 0.5 + x[rows + 1:, 1] * t, atol=1e-15)
    np.testing.assert_allclose(m.normals, plug2d(rows + 1, 3).normals, atol=1e-15)
    assert _into_body(m)
    # refined mesh = bilinear subdivision: coarse nodes of refine=1 reappear
    m1 = block2d(rows, cols, 1)
    J, I = np.meshgrid(np.arange(rows + 1) * refine, np.arange(cols + 1) * refine, indexing="ij")
    np.testing.assert_allclose(m.coords[(J * (C + 1) + I).ravel()], m1.coords, atol=1e-15)
    # total area = trapezoid
    X = m.coords[m.cells["quad"]]
    area = 0.5 * np.abs(np.einsum("eai,ij,eaj->e", X, [[0, 1], [-1, 0]], np.roll(X, -1, axis=1))).sum()
    assert math.isclose(area, 1.0 + t, rel_tol=1e-13)


def test_block2d_large_is_vectorised():
    """Assembly in numpy, not per element: 36 times the elements take no more Python calls
    (a loop over elements or nodes would take thousands more), and the large model is right."""
    small, large = python_calls(lambda: block2d(5, 2, 10)), python_calls(lambda: block2d(5, 2, 60))
    assert large <= small + 50, (small, large)
    m = block2d(5, 2, 60)          # 216k DOFs
    assert m.n_dofs == 2 * 301 * 121
    assert np.abs(m.K @ m.rigid_modes).max() < 1e-12 * abs(m.K).max()




@pytest.mark.parametrize("kind,params,msg", [
    ("plug2d", {"rows": 1}, r"model.rows: must be a whole number >= 2"),
    ("plug2d", {"rows": 0}, r"model.rows: must be a whole number >= 2"),
    ("plug3d", {"ring": 2}, r"model.ring: must be a whole number >= 3"),
    ("plug2d", {"taper_deg": 95}, r"model.taper_deg: must lie in \[0, 90\)"),
    ("plug2d", {"rosw": 3}, r"model.rosw: unknown parameter for plug2d"),
    ("vgroove_bar", {"eps": -1}, r"model.eps"),
    ("block2d", {"refine": 0}, r"model.refine"),
    ("nope", {}, r"model.kind: unknown built-in 'nope'"),
])
def test_builtin_validation(kind, params, msg):
    with pytest.raises(ValueError, match=msg):
        builtin(kind, params)
