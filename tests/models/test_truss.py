"""Trusses (hpcwedge/models/truss.py): bar stiffness by hand in 2D and 3D, validation of
every input with the key named."""
import numpy as np
import pytest

from hpcwedge.models import truss_model, truss_stiffness

X2 = [[0, 0], [1, 0], [1, 1], [0, 1]]
B2 = [[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]]
N2 = [[0, 1], [0, 1]]


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
    # before: an internal error from the condensation (MUMPS INFOG(1) = -2), exit 1
    ({"nodes": [[0, 0], [1, 0], [1, 1], [0, 1], [5, 5]]}, r"model.nodes: node 4 is in no bar"),
])
def test_truss_validation(kw, msg):
    args = dict(nodes=X2, bars=B2, EA=1.0, supports=None, contact_nodes=[2, 3], normals=N2)
    args.update(kw)
    with pytest.raises(ValueError, match=msg):
        truss_model(**args)
