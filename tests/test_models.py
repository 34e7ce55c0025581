"""Model families and built-ins: element stiffness, geometry, contact frames, validation."""
import math

import numpy as np
import pytest

from hpcwedge.models.record import contact_frames
from hpcwedge.models import (block2d, builtin, plug2d, plug3d, q4_stiffness, rigid_modes, truss_model,
                             truss_stiffness, vgroove_bar)


def _kernel_dim(K, rtol=1e-10):
    ev = np.linalg.eigvalsh(K.toarray())
    return int((np.abs(ev) <= rtol * ev[-1]).sum()), ev


# ---------------------------------------------------------------- truss element
def test_truss_two_bars_by_hand():
    # bar 0: (0,0)-(3,4), L = 5, EA = 10 -> k = 2, e = (0.6, 0.8)
    # bar 1: (3,4)-(3,0), L = 4, EA = 8  -> k = 2, e = (0, -1)
    X = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 0.0]])
    K = truss_stiffness(X, [[0, 1], [1, 2]], [10.0, 8.0]).toarray()
    k0 = 2.0 * np.array([[0.36, 0.48], [0.48, 0.64]])
    k1 = 2.0 * np.array([[0.0, 0.0], [0.0, 1.0]])
    ref = np.zeros((6, 6))
    ref[0:2, 0:2] += k0; ref[2:4, 2:4] += k0; ref[0:2, 2:4] -= k0; ref[2:4, 0:2] -= k0
    ref[2:4, 2:4] += k1; ref[4:6, 4:6] += k1; ref[2:4, 4:6] -= k1; ref[4:6, 2:4] -= k1
    np.testing.assert_allclose(K, ref, atol=1e-14)
    assert np.array_equal(K, K.T)


def test_truss_3d_bar_axial():
    X = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 2.0]])  # L = 3
    K = truss_stiffness(X, [[0, 1]], 6.0).toarray()
    e = np.array([1.0, 2.0, 2.0]) / 3
    u = np.concatenate([np.zeros(3), e])          # pure stretch by 1
    np.testing.assert_allclose(K @ u, 2.0 * np.concatenate([-e, e]), atol=1e-14)


# ---------------------------------------------------------------- Q4 element
def _distorted_patch():
    # 3x3 nodes, the interior node moved: 4 distorted elements
    X = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1.2, 0.9], [2, 1], [0, 2], [1, 2], [2, 2.3]], float)
    Q = np.array([[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 7, 6], [4, 5, 8, 7]])
    return X, Q


def test_q4_patch_test_linear_field():
    X, Q = _distorted_patch()
    K = q4_stiffness(X, Q, E=2.0, nu=0.25, t=0.5)
    u = np.stack([0.1 + 0.3 * X[:, 0] - 0.2 * X[:, 1], -0.05 + 0.15 * X[:, 0] + 0.4 * X[:, 1]], 1).ravel()
    f = K @ u
    np.testing.assert_allclose(f[[8, 9]], 0.0, atol=1e-13)   # interior node 4 is in balance
    assert np.abs(f).max() > 1e-3                            # boundary nodes carry the traction


def test_q4_rigid_motions_and_symmetry():
    X, Q = _distorted_patch()
    K = q4_stiffness(X, Q)
    R = rigid_modes(X, 2)
    assert R.shape == (18, 3)
    assert np.abs(K @ R).max() < 1e-14
    assert (K != K.T).nnz == 0
    nk, ev = _kernel_dim(K)
    assert nk == 3 and ev[0] > -1e-14


def test_q4_constant_strain_energy():
    # unit square, uniaxial strain eps_xx = 1, plane stress: energy = 1/2 * E/(1-nu^2) * area * t
    X = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    E, nu, t = 3.0, 0.2, 0.7
    K = q4_stiffness(X, [[0, 1, 2, 3]], E, nu, t).toarray()
    u = np.stack([X[:, 0], np.zeros(4)], 1).ravel()
    assert math.isclose(0.5 * u @ K @ u, 0.5 * E / (1 - nu ** 2) * t, rel_tol=1e-13)


def test_q4_bad_jacobian():
    X = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    with pytest.raises(ValueError, match=r"model.quads: quad element 0 has a non-positive Jacobian"):
        q4_stiffness(X, [[0, 3, 2, 1]])          # clockwise
    with pytest.raises(ValueError, match=r"model.quads: quad element 0 refers to node"):
        q4_stiffness(X, [[0, 1, 2, 7]])


# ---------------------------------------------------------------- rigid modes
def test_rigid_modes_supports():
    X = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    R = rigid_modes(X, 2)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-14)
    R1 = rigid_modes(X, 2, [0, 1])            # pin node 0: only the rotation about it
    assert R1.shape == (6, 1)
    np.testing.assert_allclose(R1[:2, 0], 0.0, atol=1e-14)
    assert rigid_modes(X, 2, [0, 1, 3]).shape == (6, 0)   # pin + roller: held
    X3 = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    assert rigid_modes(X3, 3).shape == (12, 6)
    assert rigid_modes(X3, 3, [0, 1, 2]).shape == (12, 3)
    assert rigid_modes(X3[:2], 3).shape == (6, 5)          # collinear: no rotation about the line


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
    nk, ev = _kernel_dim(K)
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
    import time
    t0 = time.perf_counter()
    m = block2d(5, 2, 60)          # 216k DOFs
    assert time.perf_counter() - t0 < 5.0
    assert m.n_dofs == 2 * 301 * 121
    assert np.abs(m.K @ m.rigid_modes).max() < 1e-12 * abs(m.K).max()


# ---------------------------------------------------------------- validation
X2 = [[0, 0], [1, 0], [1, 1], [0, 1]]
B2 = [[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]]
N2 = [[0, 1], [0, 1]]


@pytest.mark.parametrize("kw,msg", [
    ({"bars": [[0, 1], [1, 12]]}, r"model.bars: bar 1 refers to node 12, only 4 nodes"),
    ({"bars": [[0, 1], [1, 1e300]]}, r"model.bars: bar 1 refers to node 1000000000000000052504760255204420248704"),
    ({"contact_nodes": [2, -1e300]}, r"contact.nodes: node -1000000000000000052504760255204420248704\d* does not"),
    ({"bars": [[0, 1], [1, 1]]}, r"model.bars: bar 1 \(1-1\) has zero length"),
    ({"bars": [[0, 1, 2]]}, r"model.bars: expected \(n_bars, 2\)"),
    ({"nodes": [[0, 0], [1, float("nan")], [1, 1], [0, 1]]}, r"model.nodes: NaN"),
    ({"nodes": [[0, 0], [1, 0, 3]]}, r"model.nodes: not a numeric array"),
    ({"EA": [1.0, 2.0]}, r"model.EA: expected a scalar or one value per bar"),
    ({"EA": -1.0}, r"model.EA: must be > 0"),
    ({"contact_nodes": [2, 2]}, r"contact.nodes: duplicate node 2"),
    ({"contact_nodes": [0, 9]}, r"contact.nodes: node 9 does not exist"),
    ({"normals": [[0, 1], [0, 0]]}, r"contact.normals: zero normal at contact node 1"),
    ({"normals": [[0, 1]]}, r"contact.normals: expected shape \(2, 2\)"),
    ({"supports": [[0, 0], [1, 2]]}, r"model.supports \(dof\): dof 2 does not exist"),
    ({"supports": [[2, 1]]}, r"model.supports: contact node 2 .* has fixed dof 1"),
    ({"tangents": [[-1, 0], [1, 0]]}, r"contact.tangents: 2D tangent must be t = \(n_y, -n_x\)"),
])
def test_truss_validation(kw, msg):
    args = dict(nodes=X2, bars=B2, EA=1.0, supports=None, contact_nodes=[2, 3], normals=N2)
    args.update(kw)
    with pytest.raises(ValueError, match=msg):
        truss_model(**args)


def test_contact_frames_3d():
    n = np.array([[0, 0, 2.0], [1, 1, 0], [0.3, -0.2, 0.9]])
    nn, t = contact_frames(n, 3, 3)
    F = np.concatenate([nn[:, None], t], axis=1)
    np.testing.assert_allclose(F @ F.transpose(0, 2, 1), np.broadcast_to(np.eye(3), F.shape), atol=1e-15)
    np.testing.assert_allclose(np.linalg.det(F), 1.0)
    nn2, t2 = contact_frames(n, 3, 3, tangents=[[1, 0, 5.0], [0, 0, 1], [1, 0, 0]])
    np.testing.assert_allclose(t2[0, 0], [1, 0, 0], atol=1e-15)          # orthogonalised against n
    np.testing.assert_allclose(t2[1, 0], [0, 0, 1], atol=1e-15)
    with pytest.raises(ValueError, match=r"contact.tangents: tangent zero or parallel to the normal at contact node 0"):
        contact_frames(n, 3, 3, tangents=[[0, 0, 1.0], [0, 0, 1], [1, 0, 0]])
    with pytest.raises(ValueError, match=r"contact.tangents: t2 must be n x t1"):
        contact_frames(n[:1], 3, 1, tangents=[[[1, 0, 0], [0, -1, 0]]])


@pytest.mark.parametrize("kind,params,msg", [
    ("plug2d", {"rows": 1}, r"model.rows: must be an integer >= 2"),
    ("plug2d", {"taper_deg": 95}, r"model.taper_deg: must lie in \[0, 90\)"),
    ("plug2d", {"rosw": 3}, r"model.rosw: unknown parameter for plug2d"),
    ("vgroove_bar", {"eps": -1}, r"model.eps"),
    ("block2d", {"refine": 0}, r"model.refine"),
    ("nope", {}, r"model.kind: unknown built-in 'nope'"),
])
def test_builtin_validation(kind, params, msg):
    with pytest.raises(ValueError, match=msg):
        builtin(kind, params)
