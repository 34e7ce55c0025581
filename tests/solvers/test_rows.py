"""The pattern problem's rows (rows.py): shapes, the friction-free relaxation, the status
values."""
import numpy as np
from instances import random_problem, random_problem_3d

from hpcwedge.contact.problem import Parametrization, parametrize
from hpcwedge.solvers.rows import ConeRows, Rows, Status, eq_null_space, pattern_rows


def test_3d_rows_shapes_and_friction_free_relaxation_is_an_lp():
    p = parametrize(random_problem_3d(np.random.default_rng(0), 3, True))
    zu = np.array([True, False, False])
    zr = np.array([False, True, False])
    rows = pattern_rows(p, 3, zu, zr)
    assert isinstance(rows, ConeRows)
    assert rows.rn.shape == (2, p.d) and rows.rt.shape == (2, 2, p.d) and rows.lin.shape == (2, p.d)
    assert np.allclose(rows.eq @ rows.Z, 0, atol=1e-12)
    assert isinstance(pattern_rows(p, 3, zu, zr, friction=False), Rows)


def test_3d_rows_are_the_unit_rows_of_u_and_r_of_their_own_body():
    """pattern_rows cuts every pattern's rows from blocks computed once per parametrisation:
    they must be the unit rows of U and R of *that* body (two bodies with the same m in
    turn, each twice), zero u_n rows dropped, each cone's rows over one common factor."""
    m = 5
    rng = np.random.default_rng(7)
    bodies = [parametrize(random_problem_3d(np.random.default_rng(s), m, bool(s))) for s in (3, 4)]
    for p in bodies + bodies:
        zu, zr = rng.random(m) < 0.3, np.zeros(m, bool)
        zr[~zu] = rng.random((~zu).sum()) < 0.3
        rows = pattern_rows(p, m, zu, zr)
        Un, Rn, Rt1, Rt2 = (p.U[:m], *(p.R[k * m:(k + 1) * m] for k in range(3)))
        unit = [a / np.linalg.norm(a) for a in np.vstack([Un[zu], Rn[zr], Rt1[zr], Rt2[zr]])]
        assert np.allclose(rows.eq, np.array(unit).reshape(-1, p.d), rtol=0, atol=1e-15)
        free = np.flatnonzero(~zu)
        assert np.array_equal(rows.lin_nodes, free)
        assert np.allclose(rows.lin * rows.lin_scale[:, None], Un[free], rtol=0, atol=1e-14)
        assert np.array_equal(rows.nodes, np.flatnonzero(~zr))
        cone = np.stack([Rn, Rt1, Rt2], axis=1)[~zr]
        assert np.allclose(rows.scale, np.linalg.norm(cone, axis=(1, 2)), rtol=1e-15)
        assert np.allclose(rows.rn * rows.scale[:, None], cone[:, 0], rtol=0, atol=1e-14)
        assert np.allclose(rows.rt * rows.scale[:, None, None], cone[:, 1:], rtol=0, atol=1e-14)
        assert np.array_equal(rows.norm, Rn.sum(axis=0))
    # a u_n row that vanishes is no constraint: dropped (relative to the largest row)
    p = bodies[0]
    U = p.U.copy()
    U[1] = 0.0
    q = Parametrization(U=U, R=p.R, n_alpha=p.n_alpha)
    assert pattern_rows(q, m, np.eye(m, dtype=bool)[1], np.zeros(m, bool)).eq.shape[0] == 0
    assert np.array_equal(pattern_rows(q, m, np.zeros(m, bool), np.zeros(m, bool)).lin_nodes, [0, 2, 3, 4])


def test_rows_at_a_point_are_the_products_of_the_rows():
    """ConeRows.at reads every row at x from one product with all the node rows: it must give
    the products of the pattern's own eq, lin and cone rows, also where a zero row was
    dropped (then the selections are not the plain masks)."""
    m = 5
    rng = np.random.default_rng(11)
    p = parametrize(random_problem_3d(np.random.default_rng(3), m, True))
    U = p.U.copy()
    U[1] = 0.0
    for body in (p, Parametrization(U=U, R=p.R, n_alpha=p.n_alpha)):
        for _ in range(30):
            zu = rng.random(m) < 0.4
            zr = ~zu & (rng.random(m) < 0.4)
            rows = pattern_rows(body, m, zu, zr)
            x = rng.standard_normal(body.d)
            eq, lin, cone = rows.at(x)
            assert np.allclose(eq, rows.eq @ x, rtol=0, atol=1e-13)
            assert np.allclose(lin, rows.lin @ x, rtol=0, atol=1e-13)
            assert np.allclose(cone[0], rows.rn @ x, rtol=0, atol=1e-13)
            assert np.allclose(cone[1:].T, rows.rt @ x, rtol=0, atol=1e-13)
            assert len(eq) == len(rows.eq) and len(lin) == len(rows.lin) and cone.shape[1] == len(rows.nodes)


def test_status_values_are_the_counter_keys():
    """The values reach the stats' counter keys ("lp_feasible", "milp_undecided"): fixed."""
    assert [s.value for s in Status] == ["feasible", "infeasible", "undecided"]
    assert "lp_" + Status.FEASIBLE == "lp_feasible" and f"{Status.UNDECIDED}" == "undecided"


def test_eq_null_space_is_an_orthonormal_basis_of_the_equalities_kernel():
    """Rows.Z (2D) and ConeRows.Z (3D) come from eq_null_space: orthonormal columns,
    killed by every equality row, of dimension d - rank (dependent rows included: a node
    fixed both in contact and open)."""
    rng = np.random.default_rng(3)
    for trial in range(20):
        m = 4
        p = parametrize(random_problem(rng, m, bool(trial % 2)))
        zu = rng.random(m) < 0.5
        zr = rng.random(m) < 0.5
        rows = pattern_rows(p, m, zu, zr)
        Z = rows.Z
        eq = rows.a0[rows.eq]
        assert np.allclose(Z.T @ Z, np.eye(Z.shape[1]), atol=1e-12)
        assert np.abs(eq @ Z).max(initial=0.0) <= 1e-12 * max(1.0, np.abs(eq).max(initial=0.0))
        rank = np.linalg.matrix_rank(eq) if eq.shape[0] else 0
        assert Z.shape == (p.d, p.d - rank)
    assert eq_null_space(np.zeros((0, 5)), 5).shape == (5, 5)
