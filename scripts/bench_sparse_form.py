#!/usr/bin/env python3
"""The 3D tree's node SOCP in the condensed reaction form the product solves against the same
problem on the body's uncondensed sparse stiffness: seconds per solve and the same decisions.

    PYTHONPATH=. python scripts/bench_sparse_form.py [--levels 8 --ring 8] [--mu 0.3] [--nodes 20]
                                                     [--out results/bench_sparse_form]

The body is tests/instances.py's curved neck LEVELS x RING (a truss: ring nodes in contact,
a centre node per level). Per sampled tree node (seeded: a random 1/8 .. 1/2 of the m nodes
fixed, 70 % of them to contact): the product's SOCP (socp.reaction_socp: x' = (r, beta), the
condensed stiffness's dense u_n rows), solved by conic.solve (a kept solver where there is
one), and the sparse form: variables (v, r, alpha) with K v = E r, N^T v = 0 (v the
displacement on range(K) = N^perp, N the rigid modes) and u_n = n . (v + N alpha) on the whole
truss's K (sparse, no condensation), the same cones (mu r_n, r_t1, r_t2) and sum r_n = 1, on a new
Clarabel solver with the product's first-attempt settings (its setup timed apart). Records the
nonzeros of both constraint matrices, each form's seconds and iterations, and whether the
decisions agree. Writes <out>.json; prints a summary.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path[:0] = [ROOT, HERE, os.path.join(ROOT, "tests")]

from harness import write_records  # noqa: E402

#: Clarabel's statuses that decide (the rest: neither)
FEASIBLE, INFEASIBLE = "Solved", "PrimalInfeasible"


class SparseForm:
    """The node SOCP on the uncondensed truss (module doc) of one scene."""

    def __init__(self, model):
        import scipy.sparse as sp
        self.K = sp.csr_matrix(model.K)
        self.N = np.asarray(model.rigid_modes)
        self.nodes = np.asarray(model.contact_nodes)
        self.frames = np.stack([np.asarray(model.normals), *np.moveaxis(np.asarray(model.tangents), 1, 0)], axis=1)

    def problem(self, zero_u: np.ndarray, zero_r: np.ndarray, mu: float):
        """(P, q, A, b, cones) of Clarabel for the pattern node (zero_u, zero_r) at mu."""
        import clarabel
        import scipy.sparse as sp
        nd, k, m = self.K.shape[0], self.N.shape[1], len(self.nodes)
        cone_nodes = np.flatnonzero(~zero_r)
        nr = 3 * len(cone_nodes)
        nv = nd + nr + k
        dofs = 3 * self.nodes[:, None] + np.arange(3)                     # (m, 3) global DOFs
        rows = np.repeat(dofs[cone_nodes], 3, axis=0).ravel()             # E: node force from (r_n, r_t1, r_t2)
        cols = np.repeat(np.arange(nr), 3)
        E = sp.csr_matrix((self.frames[cone_nodes].reshape(-1), (rows, cols)), shape=(nd, nr))
        Un = np.zeros((m, nv))                                            # u_n = n . (v + N alpha)
        Un[np.arange(m)[:, None], dofs] = self.frames[:, 0]
        Un[:, nd + nr:] = np.einsum("ia,iak->ik", self.frames[:, 0], self.N[dofs])
        Un = sp.csr_matrix(Un)
        norm = sp.csr_matrix((np.ones(len(cone_nodes)), (np.zeros(len(cone_nodes), int), nd + 3 * np.arange(len(cone_nodes)))),
                             shape=(1, nv))
        zero = sp.vstack([norm, sp.hstack([self.K, -E, sp.csr_matrix((nd, k))]),
                          sp.hstack([sp.csr_matrix(self.N.T), sp.csr_matrix((k, nr + k))]), Un[np.flatnonzero(zero_u)]])
        lin = -Un[np.flatnonzero(~zero_u)]
        scale = np.sqrt(np.asarray(sp.vstack([zero, lin]).multiply(sp.vstack([zero, lin])).sum(1)).ravel())
        scale[scale == 0] = 1.0
        cone = sp.csr_matrix((-np.tile([mu, 1.0, 1.0], len(cone_nodes)), (np.arange(nr), nd + np.arange(nr))),
                             shape=(nr, nv))
        # the equality and u_n rows unit-scaled; a cone's rows as they are (a row scale would change the cone)
        A = sp.vstack([sp.diags(1.0 / scale) @ sp.vstack([zero, lin]), cone]).tocsc()
        b = np.zeros(A.shape[0])
        b[0] = 1.0 / scale[0]
        cones = ([clarabel.ZeroConeT(zero.shape[0]), clarabel.NonnegativeConeT(lin.shape[0])]
                 + [clarabel.SecondOrderConeT(3)] * len(cone_nodes))
        return sp.csc_matrix((nv, nv)), np.zeros(nv), A, b, cones


def sample_nodes(m: int, count: int, seed: int = 1) -> list[tuple[np.ndarray, np.ndarray]]:
    """`count` tree nodes: a random 1/8 .. 1/2 of the m nodes fixed, 70 % of them to contact."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        depth = int(rng.integers(max(1, m // 8), max(2, m // 2)))
        fix = rng.permutation(m)[:depth]
        contact = rng.random(depth) < 0.7
        zu, zr = np.zeros(m, bool), np.zeros(m, bool)
        zu[fix[contact]] = True
        zr[fix[~contact]] = True
        out.append((zu, zr))
    return out


def measure(levels: int, ring: int, mu: float, count: int) -> list[dict]:
    import clarabel
    from instances import curved_neck

    from hpcwedge.contact.build import build_model, contact_problem
    from hpcwedge.contact.problem import parametrize
    from hpcwedge.scene.parse import parse_scene
    from hpcwedge.solvers import conic
    from hpcwedge.solvers.rows import pattern_rows
    from hpcwedge.solvers.socp import reaction_socp

    scene = parse_scene(curved_neck(levels, ring, 0, mu=mu))
    model = build_model(scene)
    prob = contact_problem(scene, model)
    param, m = parametrize(prob), prob.m
    sparse = SparseForm(model)
    opts = conic.settings(0, False, feasibility=True)
    recs = []
    for zu, zr in sample_nodes(m, count):
        ours = reaction_socp(pattern_rows(param, m, zu, zr), mu)
        t = time.perf_counter()
        sol = conic.solve(ours.problem, 0, False)
        t_ours = time.perf_counter() - t
        P, q, A, b, cones = sparse.problem(zu, zr, mu)
        t = time.perf_counter()
        solver = clarabel.DefaultSolver(P, q, A, b, cones, opts)
        t_setup = time.perf_counter() - t
        t = time.perf_counter()
        other = solver.solve()
        t_sparse = time.perf_counter() - t
        recs.append({"body": f"neck-{levels}x{ring}-s0", "m": m, "mu": mu, "fixed": int((zu | zr).sum()),
                     "contact": int(zu.sum()), "gap": int(zr.sum()),
                     "ours_status": str(sol.status), "ours_ms": 1e3 * t_ours,
                     "ours_nnz": int(np.count_nonzero(ours.problem.A.toarray())),
                     "sparse_status": str(other.status), "sparse_ms": 1e3 * t_sparse,
                     "sparse_setup_ms": 1e3 * t_setup, "sparse_iterations": int(other.iterations),
                     "sparse_nnz": int(A.nnz), "full_dofs": int(sparse.K.shape[0]), "K_nnz": int(sparse.K.nnz),
                     "agree": {"feasible": FEASIBLE, "infeasible": INFEASIBLE}.get(str(sol.status)) == str(other.status)})
    return recs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, default=8)
    ap.add_argument("--ring", type=int, default=8)
    ap.add_argument("--mu", type=float, default=0.3)
    ap.add_argument("--nodes", type=int, default=20)
    ap.add_argument("--out", default=os.path.join(ROOT, "results", "bench_sparse_form"))
    args = ap.parse_args(argv)
    recs = measure(args.levels, args.ring, args.mu, args.nodes)
    med = lambda k: float(np.median([r[k] for r in recs]))  # noqa: E731
    summary = {"nodes": len(recs), "agree": sum(r["agree"] for r in recs), "ours_ms_median": med("ours_ms"),
               "sparse_ms_median": med("sparse_ms"), "sparse_setup_ms_median": med("sparse_setup_ms"),
               "ours_nnz_median": med("ours_nnz"), "sparse_nnz_median": med("sparse_nnz")}
    print(f"neck {args.levels} x {args.ring} (m = {recs[0]['m']}, {recs[0]['full_dofs']} DOFs, K {recs[0]['K_nnz']:,} "
          f"nonzeros), mu {args.mu}: {summary['agree']} of {len(recs)} decisions agree; median ms per solve: "
          f"ours {summary['ours_ms_median']:.2f}, sparse {summary['sparse_ms_median']:.2f} (+ setup "
          f"{summary['sparse_setup_ms_median']:.2f}); nonzeros {summary['ours_nnz_median']:.0f} vs "
          f"{summary['sparse_nnz_median']:.0f}")
    write_records(args.out, recs, extra={"summary": summary}, csv_file=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
