"""scripts/bench_sparse_form.py: its sparse form of the node SOCP on the uncondensed truss decides
as the product's condensed form does, both ways, on a small curved neck, and it reads mu."""
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [os.path.join(HERE, "..", "..", "scripts"), os.path.join(HERE, "..")]
import bench_sparse_form  # noqa: E402


def test_sparse_form_decides_as_the_product():
    """neck 3 x 5 (m = 15) at mu 0.1: of 16 sampled tree nodes some are infeasible and the rest
    feasible in the product's form, and the sparse form says the same of every one."""
    recs = bench_sparse_form.measure(3, 5, 0.1, 16)
    statuses = {r["ours_status"] for r in recs}
    assert statuses == {"feasible", "infeasible"}
    assert all(r["agree"] for r in recs)
    assert all(r["sparse_nnz"] > 0 and r["full_dofs"] == 3 * 18 for r in recs)


def test_sparse_form_reads_mu():
    """A node infeasible at mu = 0.1 in both forms is feasible in the sparse form at mu = 1
    (the cone rows carry mu; unit-scaling them as the other rows would drop it)."""
    import clarabel

    from hpcwedge.contact.build import build_model
    from hpcwedge.scene.parse import parse_scene
    from hpcwedge.solvers import conic
    from instances import curved_neck
    recs = bench_sparse_form.measure(3, 5, 0.1, 16)
    zu, zr = bench_sparse_form.sample_nodes(15, 16)[next(i for i, r in enumerate(recs) if r["ours_status"] == "infeasible")]
    form = bench_sparse_form.SparseForm(build_model(parse_scene(curved_neck(3, 5, 0, mu=0.1))))
    P, q, A, b, cones = form.problem(zu, zr, 0.1)
    opts = conic.settings(0, False, feasibility=True)
    assert str(clarabel.DefaultSolver(P, q, A, b, cones, opts).solve().status) == "PrimalInfeasible"
    P, q, A, b, cones = form.problem(zu, zr, 1.0)
    assert str(clarabel.DefaultSolver(P, q, A, b, cones, opts).solve().status) == "Solved"
    assert np.isfinite(A.data).all()
