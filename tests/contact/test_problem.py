"""The (y, beta) parametrisation (problem.py) in 3D: u = U x, r = R x with
K u = r, N^T r = 0, the lineality (rigid slides with u_n = 0) factored out."""
import numpy as np
import pytest
from instances import random_problem_3d

from hpcwedge.contact.build import contact_problem
from hpcwedge.contact.problem import parametrize, reaction_coordinates
from hpcwedge.scene.parse import parse_scene


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


@pytest.mark.parametrize("seed", range(6))
def test_reaction_coordinates_of_a_free_body_span_the_equilibrium_rows(seed):
    """parametrize sets a free body's reaction form with E = N's orthonormal basis instead of
    an SVD of B^T: the same U' and B bit for bit as the SVD route (reaction_coordinates with
    no E), and E orthonormal rows spanning the same space (projectors within 1e-13), E B = 0
    and E r = 0 for every r = R x (equilibrium); N r = 0 <=> E r = 0."""
    rng = np.random.default_rng(seed)
    prob = random_problem_3d(rng, [3, 4, 5][seed % 3], True)
    p = parametrize(prob)
    assert "reactions" in p.__dict__              # set by parametrize, not by the property's SVD
    fast, svd = p.reactions, reaction_coordinates(p.U, p.R, p.n_alpha)
    assert np.array_equal(fast.U, svd.U) and np.array_equal(fast.B, svd.B)
    k = prob.N.shape[1]
    assert fast.E.shape == svd.E.shape == (k, 3 * prob.m)
    assert np.abs(fast.E @ fast.E.T - np.eye(k)).max() <= 1e-13
    assert np.abs(fast.E.T @ fast.E - svd.E.T @ svd.E).max() <= 1e-13
    assert np.abs(fast.E @ fast.B).max() <= 1e-13
    x = rng.standard_normal(p.d)
    assert np.abs(fast.E @ (p.R @ x)).max() <= 1e-12 * np.abs(p.R @ x).max()
    # a supported body: no equilibrium rows either way
    q = parametrize(random_problem_3d(rng, 3, False))
    assert q.reactions.E.shape == (0, 9)


def test_plug3d_lineality_is_the_spin_about_the_axis():
    """plug3d: 6 rigid modes; the rotation about the cone's axis slides every ring
    node along its wall (u_n = 0 everywhere): one lineality direction, n_alpha = 5."""
    sc = parse_scene({"name": "p", "dim": 3, "model": {"kind": "plug3d"}, "friction": {"mu": [1.0]}})
    prob = contact_problem(sc)
    p = parametrize(prob)
    assert prob.N.shape[1] == 6 and p.n_alpha == 5 and p.d == 30 - 6 + 5
    assert np.abs(prob.K @ p.U - p.R).max() <= 1e-10 * np.abs(prob.K).max() * np.abs(p.U).max()


@pytest.mark.parametrize("dim", [2, 3])
def test_balanced_coordinates_are_the_same_states(dim):
    """problem.balanced: x' = T x gives the same u and r (U' T x = U x, R' T x = R x), the
    balanced blocks (s u_n, r_n, r_t / mu) are an isometry of x', and (3D) the reaction form
    (r, beta) reaches the same x' through T (before, the reaction form of a balanced
    parametrisation read x' as if it were x: a feasible plug3d pattern came out infeasible)."""
    from hpcwedge.contact.problem import balanced, blocks
    data = {"name": "p", "dim": dim, "friction": {"mu": [1.0]},
            "model": {"kind": "plug3d", "levels": 2, "ring": 5} if dim == 3 else {"kind": "plug2d", "rows": 3}}
    prob = contact_problem(parse_scene(data))
    param, m, mu, s = parametrize(prob), prob.m, 0.01, 0.7
    pb, cond, T = balanced(param, mu, m, s)
    x = np.random.default_rng(dim).standard_normal(param.d)
    assert np.allclose(pb.U @ (T @ x), param.U @ x, atol=1e-10) and np.allclose(pb.R @ (T @ x), param.R @ x, atol=1e-10)
    M = np.vstack([s * blocks(pb.U, m, dim)[0], blocks(pb.R, m, dim)[0], *(Rt / mu for Rt in blocks(pb.R, m, dim)[1:])])
    assert np.allclose(M.T @ M, np.eye(param.d), atol=1e-10) and cond >= 1.0
    if dim == 3:
        rc, rb = param.reactions, pb.reactions
        r, beta = param.R @ x, x[param.d - param.n_alpha:]
        assert np.allclose(rc.to_x(r, beta), x, atol=1e-10)
        assert np.allclose(rb.to_x(r, beta), T @ x, atol=1e-10)
        c = np.random.default_rng(5).standard_normal(param.d)
        x0 = np.concatenate([rc.B.T @ r, beta])
        assert np.isclose(rb.pullback(c) @ x0, c @ (T @ x))
