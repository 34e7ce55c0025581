"""Rigid modes (hpcwedge/models/rigid.py): orthonormal, reduced by supports, collinear bodies."""
import numpy as np

from hpcwedge.models import rigid_modes


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
