"""The (y, beta) parametrisation (problem.py) in 3D: u = U x, r = R x with
K u = r, N^T r = 0, the lineality (rigid slides with u_n = 0) factored out."""
import numpy as np
import pytest

from hpcwedge.build import contact_problem
from hpcwedge.problem import parametrize
from hpcwedge.scene import parse_scene
from instances import random_problem_3d


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("free", [False, True])
def test_parametrize_3d(seed, free):
    m = [2, 3, 4, 5, 6][seed % 5]
    prob = random_problem_3d(np.random.default_rng(seed), m, free)
    p = parametrize(prob)
    scale = np.abs(prob.K).max()
    assert np.abs(prob.K @ p.U - p.R).max() <= 1e-10 * scale * max(1.0, np.abs(p.U).max())
    if free:
        k = prob.N.shape[1]
        assert k == (6 if m >= 3 else 5)          # two points: no rotation about their line
        assert np.abs(prob.N.T @ p.R).max() <= 1e-12
        assert p.n_alpha == np.linalg.matrix_rank(prob.N[:m])
        assert p.d == 3 * m - k + p.n_alpha
        # the trailing n_alpha coordinates move no reaction and no normal gap is a slide
        assert np.abs(p.R[:, p.d - p.n_alpha:]).max() == 0
        assert np.linalg.matrix_rank(p.U[:m, p.d - p.n_alpha:]) == p.n_alpha
    else:
        assert p.n_alpha == 0 and np.allclose(p.R, np.eye(3 * m))
        assert np.allclose(p.U, np.linalg.inv(prob.K))


def test_plug3d_lineality_is_the_spin_about_the_axis():
    """plug3d: 6 rigid modes; the rotation about the cone's axis slides every ring
    node along its wall (u_n = 0 everywhere): one lineality direction, n_alpha = 5."""
    sc = parse_scene({"name": "p", "dim": 3, "model": {"kind": "plug3d"}, "friction": {"mu": [1.0]}})
    prob = contact_problem(sc)
    p = parametrize(prob)
    assert prob.N.shape[1] == 6 and p.n_alpha == 5 and p.d == 30 - 6 + 5
    assert np.abs(prob.K @ p.U - p.R).max() <= 1e-10 * np.abs(prob.K).max() * np.abs(p.U).max()
