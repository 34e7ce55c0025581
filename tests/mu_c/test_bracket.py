"""mu_bracket.py: the 2D route of a pattern's mu^c (bisection on LP feasibility, then the
pencil polish), through mu_critical's dispatch: analytic single-node values, polished."""
import numpy as np
import pytest

from hpcwedge.contact.problem import ContactProblem, parametrize
from hpcwedge.mu_c.critical import mu_critical


@pytest.mark.parametrize("seed", range(12))
def test_single_node_formula(seed):
    rng = np.random.default_rng(seed)
    G = rng.standard_normal((2, 2))
    K = G @ G.T + 0.1 * np.eye(2)
    p = parametrize(ContactProblem(2, K, np.zeros((2, 0))))
    r = mu_critical(p, 1, np.array([True]), np.array([False]), mu_max=1e4)
    want = K[1, 1] / abs(K[0, 1])
    if want > 1e4:
        assert r.mu_c is None
    else:
        assert r.polished and abs(r.mu_c - want) <= 1e-10 * want
