"""Node symmetries (symmetry.py): the group found leaves K invariant (checked
directly on the local stiffness), has the order the geometry predicts (plug3d:
dihedral of its ring; plug2d: the mirror; a planted cyclic symmetry; a generic
or slightly perturbed body: the identity), and orbits of patterns behave."""
import numpy as np
import pytest
from instances import random_problem, random_problem_3d, symmetric_problem_3d

from hpcwedge.contact.build import contact_problem
from hpcwedge.patterns.symmetry import Symmetry, node_symmetries
from hpcwedge.scene.parse import parse_scene


def _problem(model: dict, dim: int):
    return contact_problem(parse_scene({"name": "s", "dim": dim, "friction": {"mu": 1.0}, "model": model}))


def _acts(K: np.ndarray, dim: int, perm: np.ndarray, signs: np.ndarray) -> np.ndarray:
    """S K S^T for the signed node permutation (node i's dofs go to perm[i])."""
    m = K.shape[0] // dim
    n = dim * m
    d = np.concatenate([[1.0], signs.astype(float)])
    S = np.zeros((n, n))
    for a in range(dim):
        S[a * m + perm, a * m + np.arange(m)] = d[a]
    return S @ K @ S.T


def _check_invariant(K, dim, G: Symmetry):
    for perm, signs in zip(G.perms, G.signs):
        assert np.abs(_acts(K, dim, perm, signs) - K).max() <= 1e-9 * np.abs(K).max()


@pytest.mark.parametrize("levels,ring", [(2, 4), (2, 5), (3, 3)])
def test_plug3d_has_the_dihedral_group_of_its_ring(levels, ring):
    prob = _problem({"kind": "plug3d", "levels": levels, "ring": ring}, 3)
    G = node_symmetries(prob.K, 3)
    assert G.order == 2 * ring
    _check_invariant(prob.K, 3, G)
    assert (G.perms[0] == np.arange(prob.m)).all()
    # a ring node's orbit is its ring; levels never mix
    assert G.orbit(0).tolist() == list(range(ring))


def test_plug2d_has_its_mirror():
    prob = _problem({"kind": "plug2d", "rows": 4}, 2)
    G = node_symmetries(prob.K, 2)
    assert G.order == 2 and G.signs[1].tolist() == [-1]
    _check_invariant(prob.K, 2, G)


@pytest.mark.parametrize("seed", range(6))
def test_generic_bodies_have_only_the_identity(seed):
    rng = np.random.default_rng(seed)
    for prob in (random_problem(rng, 5, bool(seed % 2)), random_problem_3d(rng, 5, bool(seed % 2))):
        assert node_symmetries(prob.K, prob.dim).order == 1


@pytest.mark.parametrize("seed", range(6))
def test_planted_symmetry_is_found_and_a_perturbation_breaks_it(seed):
    rng = np.random.default_rng(seed)
    m = 4 + seed % 3
    prob = symmetric_problem_3d(rng, m, free=bool(seed % 2))
    G = node_symmetries(prob.K, 3)
    assert G.order % m == 0 and G.order >= m
    _check_invariant(prob.K, 3, G)
    assert sorted(G.orbit(0).tolist()) == list(range(m))
    K = prob.K.copy()
    K[0, 0] *= 1 + 1e-6                          # far above round-off, far below any physics
    assert node_symmetries(K, 3).order == 1


def test_orbits_of_patterns():
    G = node_symmetries(_problem({"kind": "plug3d", "levels": 2, "ring": 4}, 3).K, 3)
    pats = G.expand([(0b1, 0b11111110)])          # node 0 alone in contact
    assert len(pats) == 4 and sorted(c for c, _ in pats) == [1, 2, 4, 8]
    assert all(c | g == 0xFF and not c & g for c, g in pats)
    assert {G.canonical(c, g) for c, g in pats} == {min(pats)}
    st = G.stabilizer(0b1, 0)                      # elements fixing node 0's contact: identity and a mirror
    assert st.order == 2 and (st.perms[:, 0] == 0).all()
    assert G.expand([(0b1111, 0b11110000)]) == [(0b1111, 0b11110000)]   # a whole level: its own orbit
