#!/usr/bin/env python3
"""Clarabel against QOCO on the 3D tree's SOCPs (issue 13): could another interior-point
solver for small SOCPs take the tree's solves?

    PYTHONPATH=. python scripts/bench_socp_solvers.py [--scene 3x6] [--mu 0.65] [--sample 1500]
                                                      [--repeat 2] [--out results/bench_socp_solvers]
    PYTHONPATH=. python scripts/bench_socp_solvers.py --ldl [--scenes 4x8 6x8 8x8 ...] [--mu 0.3]
                                                      [--sample 80] [--out results/bench_socp_ldl]

The SOCPs are the first attempts that plug3d LEVELSxRING's enumeration tree (mu, no
symmetry, bench_search_3d.scene) hands to conic.solve, recorded as the tree runs (the
product's settings: long steps, no objective), the first `sample` of them. Each is then
solved again on a new solver by each engine, its matrices built before the clock starts:
Clarabel (conic.settings of that attempt) and QOCO (bench extras, BSD-3; "missing" without
it) with the zero cone as its equalities, the rest as its cone constraints, objective 0.
A point counts as verified when the problem's rows hold at it to socp.VERIFY_TOL (absolute:
the rows are unit-scaled and sum r_n = 1); a verified point of a problem that the tree proved
infeasible (a checked Farkas certificate) would be a contradiction, a SOLVED status there a
false claim of feasibility. Reported per class of SOCP
(Clarabel's status in the tree: Solved, PrimalInfeasible): how many, each engine's mean
iterations and statuses, and the microseconds per solve (each solve's best of `repeat`
passes).
Writes <out>.json (with the environment record); prints a summary.

--ldl: Clarabel alone, its KKT factorisation by each of its two LDL solvers (QDLDL, faer;
Clarabel's "auto", the product's setting, picks one of them by the work of the factorisation)
on the first `sample` SOCPs of each scene's tree (budget: `sample` tree nodes),
every solve repeated `repeat` times in turn per solver; which solver "auto" picked (its x the
same bits as that one's), and the milliseconds and iterations per solve, per size m.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
import scipy.sparse as sp

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from bench_search_3d import scene  # noqa: E402
from harness import write_json  # noqa: E402


def available() -> bool:
    try:
        import qoco  # noqa: F401
    except ImportError:
        return False
    return True


def tree_socps(levels: int, ring: int, mu: float, sample: int,
               budget: int | None = None) -> tuple[list, dict]:
    """The first `sample` first-attempt SOCPs of the enumeration tree (budget: its first
    `budget` nodes; None: all), as (A dense, b, n_zero, n_lin, n_soc, long_steps, tree
    status), and the tree's counts."""
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.contact.problem import parametrize
    from hpcwedge.patterns.tree import PatternTree
    from hpcwedge.solvers import socp
    recorded = []
    solve = socp.solve

    def recording(problem, attempt, tight, long_steps=False):
        sol = solve(problem, attempt, tight, long_steps)
        if attempt == 0 and not tight and problem.q is None and len(recorded) < sample:
            A = problem.A.toarray() if hasattr(problem.A, "toarray") else np.array(problem.A)
            recorded.append((A, np.array(problem.b), problem.n_zero, problem.n_lin, problem.n_soc,
                             long_steps, sol.name))
        return sol

    prob = contact_problem(scene("enumerate", levels, ring))
    param, m = parametrize(prob), prob.m
    socp.solve = recording
    try:
        tree = PatternTree(param, m, mu)
        ex = tree.explore(tree.root(), budget)
    finally:
        socp.solve = solve
    return recorded, {"m": m, "patterns": len(ex.found), "socps": ex.stats.solves}


def _residual_ok(A, b, n_zero, n_lin, n_soc, w, tol: float) -> bool:
    """A w + s = b with s in [zero | nonneg | SOC(3)...] to tol (absolute: b is sum r_n = 1
    and zeros, the rows unit-scaled; relative to ||w|| a point far out along a rigid lift-off
    would pass on an infeasible problem)."""
    s = b - A @ w
    size = 1.0
    if n_zero and np.abs(s[:n_zero]).max() > tol * size:
        return False
    if n_lin and s[n_zero:n_zero + n_lin].min() < -tol * size:
        return False
    c = s[n_zero + n_lin:].reshape(n_soc, 3)
    return not n_soc or float((np.hypot(c[:, 1], c[:, 2]) - c[:, 0]).max()) <= tol * size


def clarabel_engine(problems, ldl: str | None = None):
    """Prepared Clarabel solves: a list of callables returning (status, iterations, x).
    ldl: Clarabel's direct_solve_method ("qdldl", "faer"; None: the product's settings)."""
    import clarabel

    from hpcwedge.solvers.conic import settings
    out = []
    for A, b, nz, nl, ns, long_steps, _ in problems:
        n = A.shape[1]
        P, q, Ac = sp.csc_matrix((n, n)), np.zeros(n), sp.csc_matrix(A)
        cones = [clarabel.ZeroConeT(nz)] + ([clarabel.NonnegativeConeT(nl)] if nl else [])
        cones += [clarabel.SecondOrderConeT(3)] * ns
        opts = settings(0, False, feasibility=True, long_steps=long_steps)
        if ldl is not None:
            opts = settings.__wrapped__(0, False, feasibility=True, long_steps=long_steps)   # not the shared one
            opts.direct_solve_method = ldl

        def run(P=P, q=q, Ac=Ac, b=b, cones=cones, opts=opts):
            sol = clarabel.DefaultSolver(P, q, Ac, b, cones, opts).solve()
            return str(sol.status), sol.iterations, np.asarray(sol.x)
        out.append(run)
    return out


def qoco_engine(problems):
    """Prepared QOCO solves (objective 0): callables returning (status, iterations, x)."""
    import qoco
    out = []
    for A, b, nz, nl, ns, _, _ in problems:
        n = A.shape[1]
        Aeq, G = sp.csc_matrix(A[:nz]), sp.csc_matrix(A[nz:])
        beq, h, c = b[:nz], b[nz:], np.zeros(n)
        qd = np.full(ns, 3, dtype=np.int32)

        def run(n=n, Aeq=Aeq, beq=beq, G=G, h=h, nz=nz, nl=nl, ns=ns, c=c, qd=qd):
            s = qoco.QOCO()
            s.setup(n, G.shape[0], nz, None, c, Aeq, beq, G, h, nl, ns, qd, verbose=0)
            r = s.solve()
            return str(r.status), int(r.iters), np.asarray(r.x)
        out.append(run)
    return out


def study(levels: int, ring: int, mu: float, sample: int, repeat: int) -> dict:
    from hpcwedge.solvers.socp import VERIFY_TOL
    problems, tree = tree_socps(levels, ring, mu, sample)
    engines = {"clarabel": clarabel_engine}
    if available():
        engines["qoco"] = qoco_engine
    row = {"scene": f"plug3d {levels}x{ring}", "mu": mu, **tree, "sampled": len(problems), "engines": {}}
    classes = sorted({p[-1] for p in problems})
    for name, prepare in engines.items():
        runs = prepare(problems)
        best, answers = np.full(len(runs), np.inf), None
        for _ in range(repeat):
            got, took = [], []
            for f in runs:
                t0 = time.perf_counter()
                got.append(f())
                took.append(time.perf_counter() - t0)
            best, answers = np.minimum(best, took), got
        per = {}
        for cls in classes:
            idx = [i for i, p in enumerate(problems) if p[-1] == cls]
            statuses: dict = {}
            for i in idx:
                statuses[answers[i][0]] = statuses.get(answers[i][0], 0) + 1
            verified = sum(_residual_ok(*problems[i][:5], answers[i][2], VERIFY_TOL) for i in idx)
            per[cls] = {"count": len(idx), "us_per_solve": round(float(best[idx].mean()) * 1e6, 1),
                        "mean_iterations": round(float(np.mean([answers[i][1] for i in idx])), 2),
                        "statuses": statuses, "points_verified": int(verified)}
        row["engines"][name] = {"us_per_solve": round(float(best.mean()) * 1e6, 1), "by_tree_status": per}
    if "qoco" not in engines:
        row["engines"]["qoco"] = "missing"
    return row


LDL_SCENES = ("3x6", "4x8", "6x8", "8x8", "10x8", "12x8", "8x16", "10x16")


def ldl_study(levels: int, ring: int, mu: float, sample: int, repeat: int) -> dict:
    """One scene of --ldl (module doc): per LDL solver the mean ms and iterations per solve
    (each solve's best of `repeat`), and which solver Clarabel's "auto" picked."""
    problems, tree = tree_socps(levels, ring, mu, sample, budget=sample)
    runs = {k: clarabel_engine(problems, None if k == "auto" else k) for k in ("auto", "qdldl", "faer")}
    best = {k: np.full(len(problems), np.inf) for k in runs}
    answers: dict = {}
    for _ in range(repeat):
        for i in range(len(problems)):
            for k, fs in runs.items():
                t0 = time.perf_counter()
                answers[k, i] = fs[i]()
                best[k][i] = min(best[k][i], time.perf_counter() - t0)
    picked = {k: sum(np.array_equal(answers["auto", i][2], answers[k, i][2]) for i in range(len(problems)))
              for k in ("qdldl", "faer")}
    row = {"scene": f"plug3d {levels}x{ring}", "m": tree["m"], "mu": mu, "sampled": len(problems),
           "auto_same_bits_as": picked, "solvers": {}}
    for k in runs:
        row["solvers"][k] = {"ms_per_solve": round(float(best[k].mean()) * 1e3, 3),
                             "mean_iterations": round(float(np.mean([answers[k, i][1] for i in range(len(problems))])), 2),
                             "statuses": {s: sum(answers[k, i][0] == s for i in range(len(problems)))
                                          for s in sorted({answers[k, i][0] for i in range(len(problems))})}}
    row["qdldl_over_faer"] = round(row["solvers"]["qdldl"]["ms_per_solve"] / row["solvers"]["faer"]["ms_per_solve"], 3)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="3x6")
    ap.add_argument("--mu", type=float, default=None, help="default 0.65 (--ldl: 0.3)")
    ap.add_argument("--sample", type=int, default=None, help="default 1500 (--ldl: 80)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--out", default=None)
    ap.add_argument("--ldl", action="store_true", help="Clarabel's LDL solvers by size (module doc)")
    ap.add_argument("--scenes", nargs="+", default=list(LDL_SCENES))
    args = ap.parse_args(argv)
    results = os.path.join(os.path.dirname(HERE), "results")
    if args.ldl:
        mu = 0.3 if args.mu is None else args.mu
        sample = 80 if args.sample is None else args.sample
        rows = []
        for sc in args.scenes:
            levels, ring = (int(v) for v in sc.split("x"))
            row = ldl_study(levels, ring, mu, sample, args.repeat)
            rows.append(row)
            print(f"{row['scene']} (m = {row['m']}): " + ", ".join(
                f"{k} {v['ms_per_solve']} ms ({v['mean_iterations']} iterations)" for k, v in row["solvers"].items())
                + f"; auto = qdldl bits on {row['auto_same_bits_as']['qdldl']}, faer on "
                f"{row['auto_same_bits_as']['faer']} of {row['sampled']}", flush=True)
        write_json((args.out or os.path.join(results, "bench_socp_ldl")) + ".json", {"rows": rows})
        return 0
    levels, ring = (int(v) for v in args.scene.split("x"))
    row = study(levels, ring, 0.65 if args.mu is None else args.mu, 1500 if args.sample is None else args.sample,
                args.repeat)
    print(f"{row['scene']} (m = {row['m']}, mu = {row['mu']}): {row['sampled']} of the tree's "
          f"{row['socps']} SOCPs")
    for name, e in row["engines"].items():
        if e == "missing":
            print(f"  {name}: missing (bench extras)")
            continue
        parts = [f"{cls} {v['count']}: {v['us_per_solve']} us, {v['mean_iterations']} iterations, {v['statuses']}, "
                 f"{v['points_verified']} points verified" for cls, v in e["by_tree_status"].items()]
        print(f"  {name}: {e['us_per_solve']} us a solve; " + "; ".join(parts))
    write_json((args.out or os.path.join(results, "bench_socp_solvers")) + ".json", {"rows": [row]})
    return 0


if __name__ == "__main__":
    sys.exit(main())
