"""Element matrices (hpcwedge/models/elements.py) against independent references: B^T D B
with Voigt matrices and shape gradients by differences, the rigid motions as exact null
space, the patch test of constant strain on distorted patches of every cell type, exact
energy of a non-affine hexahedron, re-entrant elements rejected."""
import math

import numpy as np
import pytest
from model_cases import distorted_patch

from hpcwedge.models import continuum_stiffness
from hpcwedge.models.elements import REFERENCE, element_stiffness

E, NU, T = 2.0, 0.27, 0.6


# ----------------------------------------------------------------------------- references
def _voigt_D(dim):
    """Plane-stress (3x3) / 3D (6x6) elasticity matrix, engineering shear strains."""
    if dim == 2:
        return E / (1 - NU ** 2) * np.array([[1, NU, 0], [NU, 1, 0], [0, 0, (1 - NU) / 2]])
    lam, mu = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
    D = np.zeros((6, 6))
    D[:3, :3] = lam
    D[np.arange(3), np.arange(3)] += 2 * mu
    D[np.arange(3, 6), np.arange(3, 6)] = mu
    return D


def _voigt(eps):
    """Strain tensor -> Voigt vector (engineering shears: xy | yz, xz, xy)."""
    if len(eps) == 2:
        return np.array([eps[0, 0], eps[1, 1], 2 * eps[0, 1]])
    return np.array([eps[0, 0], eps[1, 1], eps[2, 2], 2 * eps[1, 2], 2 * eps[0, 2], 2 * eps[0, 1]])


def _shape(cell, xi):
    """Shape functions written out, (nen,) at the reference point xi."""
    x, y = xi[0], xi[1]
    if cell == "triangle":
        return np.array([1 - x - y, x, y])
    if cell == "tetra":
        return np.array([1 - x - y - xi[2], x, y, xi[2]])
    if cell == "quad":
        return 0.25 * np.array([(1 - x) * (1 - y), (1 + x) * (1 - y), (1 + x) * (1 + y), (1 - x) * (1 + y)])
    z = xi[2]
    b = [(1 - x) * (1 - y), (1 + x) * (1 - y), (1 + x) * (1 + y), (1 - x) * (1 + y)]
    return 0.125 * np.array([v * (1 - z) for v in b] + [v * (1 + z) for v in b])


RULES = {"triangle": ([[1 / 3, 1 / 3]], [0.5]), "tetra": ([[0.25, 0.25, 0.25]], [1 / 6]),
         "quad": ([[s * a, s * b] for a, b in [(-1, -1), (1, -1), (1, 1), (-1, 1)] for s in [3 ** -0.5]], [1] * 4),
         "hexahedron": ([[a * 3 ** -0.5, b * 3 ** -0.5, c * 3 ** -0.5] for c in (-1, 1) for b in (-1, 1)
                         for a in (-1, 1)], [1] * 8)}


def _reference_ke(cell, Xe, t=T):
    """B^T D B with Voigt matrices; shape gradients by central differences (exact: the shape
    functions are linear in each reference coordinate)."""
    nen, dim = Xe.shape
    pts, wts = RULES[cell]
    k = np.zeros((nen * dim, nen * dim))
    for xi, w in zip(np.array(pts), wts):
        dN = np.stack([(_shape(cell, xi + 0.5 * e) - _shape(cell, xi - 0.5 * e)) for e in np.eye(dim)], 1)
        J = Xe.T @ dN
        G = dN @ np.linalg.inv(J)                                      # (nen, dim) dN/dx
        B = np.zeros((3 if dim == 2 else 6, nen * dim))
        for a in range(nen):
            g = G[a]
            if dim == 2:
                B[:, 2 * a:2 * a + 2] = [[g[0], 0], [0, g[1]], [g[1], g[0]]]
            else:
                B[:, 3 * a:3 * a + 3] = [[g[0], 0, 0], [0, g[1], 0], [0, 0, g[2]],
                                         [0, g[2], g[1]], [g[2], 0, g[0]], [g[1], g[0], 0]]
        k += w * np.linalg.det(J) * (t if dim == 2 else 1.0) * B.T @ _voigt_D(dim) @ B
    return k


CELLS = ["triangle", "quad", "tetra", "hexahedron"]


@pytest.mark.parametrize("cell", CELLS)
def test_element_matches_voigt_reference(cell):
    X, C, _, _ = distorted_patch(cell)
    dim = X.shape[1]
    ne = len(C)
    ke = element_stiffness(cell, X[C], np.full(ne, E), np.full(ne, NU), np.full(ne, T))
    for e in range(ne):
        ref = _reference_ke(cell, X[C[e]])
        assert np.abs(ke[e] - ref).max() <= 1e-12 * np.abs(ref).max(), (cell, e)
    assert np.array_equal(ke, ke.transpose(0, 2, 1))
    assert ke.shape == (ne, REFERENCE[cell].nen * dim, REFERENCE[cell].nen * dim)


@pytest.mark.parametrize("cell", CELLS)
def test_element_rigid_modes_are_the_null_space(cell):
    X, C, _, _ = distorted_patch(cell)
    dim = X.shape[1]
    ke = element_stiffness(cell, X[C], np.full(len(C), E), np.full(len(C), NU), np.full(len(C), T))
    for e in range(len(C)):
        Xe = X[C[e]]
        d = Xe - Xe.mean(0)
        if dim == 2:
            R = [np.tile([1, 0], len(Xe)), np.tile([0, 1], len(Xe)), np.c_[-d[:, 1], d[:, 0]].ravel()]
        else:
            R = [np.tile(np.eye(3)[a], len(Xe)) for a in range(3)] + \
                [np.cross(np.eye(3)[a], d).ravel() for a in range(3)]
        R = np.array(R).T
        assert np.abs(ke[e] @ R).max() <= 1e-13 * np.abs(ke[e]).max()
        ev = np.linalg.eigvalsh(ke[e])
        assert int((np.abs(ev) <= 1e-10 * ev[-1]).sum()) == (3 if dim == 2 else 6), (cell, e, ev[:8])
        assert ev[0] > -1e-12 * ev[-1]


@pytest.mark.parametrize("cell", CELLS)
def test_patch_constant_strain(cell):
    """A linear displacement field: the interior node is in balance, the energy is exact,
    and (simplices, quads) every element's nodal forces are the exact sigma . int grad N."""
    X, C, interior, volume = distorted_patch(cell)
    dim = X.shape[1]
    rng = np.random.default_rng(3)
    G = rng.normal(size=(dim, dim))
    u = (X @ G.T + rng.normal(size=dim)).ravel()                   # u(x) = G x + c
    K = continuum_stiffness(X, {cell: C}, E, NU, T if dim == 2 else 1.0)
    f = K @ u
    eps = 0.5 * (G + G.T)
    s_v = _voigt_D(dim) @ _voigt(eps)
    thick = T if dim == 2 else 1.0
    assert math.isclose(0.5 * u @ f, 0.5 * thick * volume * s_v @ _voigt(eps), rel_tol=1e-12)
    for i in interior:
        assert np.abs(f[dim * i:dim * i + dim]).max() <= 1e-12 * np.abs(f).max()
    if cell in ("triangle", "tetra", "quad"):
        sig = np.zeros((dim, dim))
        if dim == 2:
            sig[[0, 1, 0, 1], [0, 1, 1, 0]] = s_v[[0, 1, 2, 2]]
        else:
            sig[[0, 1, 2, 1, 2, 0, 2, 0, 1], [0, 1, 2, 2, 1, 2, 0, 1, 0]] = s_v[[0, 1, 2, 3, 3, 4, 4, 5, 5]]
        ke = element_stiffness(cell, X[C], np.full(len(C), E), np.full(len(C), NU), np.full(len(C), T))
        for e, conn in enumerate(C):
            Xe = X[conn]
            if cell == "quad":       # int grad N_a = 1/2 sum over the two edges at a of (outward normal * length)
                nxt, prv = np.roll(Xe, -1, 0), np.roll(Xe, 1, 0)
                gN = 0.5 * ((nxt - Xe) @ [[0, -1], [1, 0]] + (Xe - prv) @ [[0, -1], [1, 0]])
            else:                    # simplex: volume * grad N_a from the affine interpolation
                A = np.c_[np.ones(dim + 1), Xe]
                vol = abs(np.linalg.det(A)) / math.factorial(dim)
                gN = vol * np.linalg.inv(A)[1:].T
            exact = thick * gN @ sig                                   # f_a = t sigma . int grad N_a
            assert np.allclose(ke[e] @ u.reshape(-1, dim)[conn].ravel(), exact.ravel(),
                               rtol=0, atol=1e-12 * np.abs(exact).max())


def test_hexahedron_frustum_volume():
    """A non-affine hexahedron (square frustum): energy of a uniform dilatation is exact."""
    a, b, h = 1.0, 0.6, 0.8
    sq = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) / 2
    X = np.vstack([np.c_[a * sq, np.zeros(4)], np.c_[b * sq, np.full(4, h)]])
    K = continuum_stiffness(X, {"hexahedron": [list(range(8))]}, E, NU)
    V = h / 3 * (a * a + b * b + a * b)
    u = X.ravel()                                                   # eps = I
    bulk = E / (3 * (1 - 2 * NU))
    assert math.isclose(0.5 * u @ K @ u, 0.5 * V * 9 * bulk, rel_tol=1e-13)


def test_reentrant_element_rejected():
    """det J > 0 at every Gauss point but < 0 at a node (a dart-shaped quad, and the
    hexahedron extruded from it): rejected, naming the element."""
    X = np.array([[0, 0], [1, 0], [0.4, 0.4], [0, 1], [1, 1]], float)
    with pytest.raises(ValueError, match=r"model.cells: quad element 1 has a non-positive Jacobian"):
        continuum_stiffness(X, {"quad": [[0, 1, 4, 3], [0, 1, 2, 3]]})
    X3 = np.r_[np.c_[X[:4], np.zeros(4)], np.c_[X[:4], np.ones(4)]]
    with pytest.raises(ValueError, match=r"model.cells: hexahedron element 0 has a non-positive Jacobian"):
        continuum_stiffness(X3, {"hexahedron": [list(range(8))]})
