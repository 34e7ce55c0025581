"""Continuum stiffness (hpcwedge/models/continuum.py): the bilinear quadrilateral passes the
patch test, has exactly the rigid motions as kernel, integrates constant strain energy, and
refuses an inverted element."""
import math

import numpy as np
import pytest
from instances import kernel_dim

from hpcwedge.models import q4_stiffness, rigid_modes


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
    nk, ev = kernel_dim(K)
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
