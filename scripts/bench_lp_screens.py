#!/usr/bin/env python3
"""Polyhedral LP screens before the 3D tree's SOCPs (issue 13): counts and CPU.

    PYTHONPATH=. python scripts/bench_lp_screens.py [--scenes 2x6 3x5 3x6] [--mu 0.65]
                                                    [--facets 8] [--engines clp highs]
                                                    [--out results/bench_lp_screens]

Each scene is plug3d LEVELSxRING at mu without symmetry (bench_search_3d.scene), its whole
enumeration tree (patterns.PatternTree, one pass) run once as the product runs it, then
with screens in front of every SOCP the tree asks for (the product's `decide`, replaced
in patterns' namespace for this measurement only):
  outer  an LP on a circumscribed k-facet pyramid of every friction cone: infeasible =>
         the node is infeasible, no SOCP; else the SOCP as before
  both   first an LP on the inscribed pyramid (facets at mu cos(pi / k)): a vertex it
         returns is a point of the node's problem once it verifies on the circular cones
         (socp.violation <= socp.VERIFY_TOL) and is the node's point; then the outer LP;
         then the SOCP
One LP model per (scene, pyramid), kept warm in the engine (a node changes bounds only:
the reactions of its gap nodes fixed to 0, the u_n rows of its contact nodes fixed to 0):
  clp    COIN-OR CLP through cylp (EPL-2.0): dual simplex, the bounds written into CLP's
         own arrays, its work areas kept between solves
  highs  HiGHS through highspy: dual simplex, presolve off, bounds changed by its API
(bench extras; an engine that does not import is reported as missing). Every node the
outer LP rules out is also decided by the SOCP, outside the timed CPU, and counted when
the SOCP finds it feasible (`wrong`: the LP's tolerance, as the pyramid contains the cone;
such a node is still pruned, as a product would). Per row: tree nodes, SOCPs, SOCPs per
feasible pattern, LPs, simplex iterations per LP, wrong outer prunes, the patterns' hash (the same set as the product's, or the row says not), CPU seconds of the whole tree
and of the LPs alone. Counts are the same on every machine (an engine's iterations: on
the same build); seconds are not (2 shared cores). Writes <out>.json; prints the table.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from bench_search_3d import scene  # noqa: E402

#: what the engines take for an infinite bound (CLP: COIN_DBL_MAX)
BIG = float(np.finfo(float).max)


class PyramidLP:
    """The LP of a node's problem at mu with every friction cone replaced by a k-facet
    pyramid (inner: inscribed, outer: circumscribed), in the reaction coordinates
    x' = (r, beta) of problem.ReactionCoordinates: E r = 0; u_n = U_n x' >= 0 (= 0 at a
    contact node); r_n >= 0 (column bounds; a gap node's three reactions fixed to 0);
    every facet (mu c) r_n - cos(t) r_t1 - sin(t) r_t2 >= 0, c = cos(pi / k) inside, 1
    outside; sum r_n = 1. Rows unit-scaled. `run(zu, zr)`: (status "optimal" /
    "infeasible" / other, x-space point or None)."""

    def __init__(self, param, m: int, mu: float, facets: int, inner: bool, engine: str):
        form = param.reactions
        self.form, self.m, self.engine = form, m, engine
        n, nb, k = form.E.shape[1], form.U.shape[1] - form.E.shape[1], form.E.shape[0]
        self.n, self.k, nc = n, k, n + nb
        t = 2 * np.pi * np.arange(facets) / facets
        c = np.cos(np.pi / facets) if inner else 1.0
        P = np.zeros((facets * m, nc))
        for i in range(m):
            P[i * facets:(i + 1) * facets, i] = mu * c
            P[i * facets:(i + 1) * facets, i + m] = -np.cos(t)
            P[i * facets:(i + 1) * facets, i + 2 * m] = -np.sin(t)
        Un = form.U[:m]
        total = np.zeros((1, nc))
        total[0, :m] = 1.0
        A = np.vstack([np.hstack([form.E, np.zeros((k, nb))]),
                       Un / np.linalg.norm(Un, axis=1, keepdims=True),
                       P / np.linalg.norm(P, axis=1, keepdims=True), total])
        self.row_lo = np.concatenate([np.zeros(k + m + facets * m), [1.0]])
        self.row_hi = np.concatenate([np.zeros(k), np.full(m + facets * m, BIG), [1.0]])
        self.col_lo = np.concatenate([np.zeros(m), np.full(nc - m, -BIG)])
        self.col_hi = np.full(nc, BIG)
        self.seconds, self.calls, self.iterations = 0.0, 0, 0
        getattr(self, "_load_" + engine)(A)

    def _load_clp(self, A):
        import scipy.sparse as sp
        from cylp.cy import CyClpSimplex
        from cylp.cy.CyCoinPackedMatrix import CyCoinPackedMatrix
        C = sp.csc_matrix(A).tocoo()       # CoinPackedMatrix(colOrdered) wants column order
        M = CyCoinPackedMatrix(True, C.row.astype(np.int32), C.col.astype(np.int32), C.data.astype(float))
        s = self.lp = CyClpSimplex()
        s.loadProblem(M, self.col_lo, self.col_hi, np.zeros(A.shape[1]), self.row_lo, self.row_hi)
        s.logLevel = 0
        s.dual()
        # views of CLP's own bound arrays, written in place (cylp's array setters hand CLP
        # the numpy buffer itself, which CLP then frees: a double free at exit)
        self._cl, self._cu, self._ru = s.variablesLower, s.variablesUpper, s.constraintsUpper

    def _load_highs(self, A):
        import highspy
        import scipy.sparse as sp
        h = self.lp = highspy.Highs()
        h.setOptionValue("output_flag", False)
        h.setOptionValue("presolve", "off")
        h.setOptionValue("solver", "simplex")
        lo, hi = (_highs_inf(v) for v in (self.col_lo, self.col_hi))
        h.addVars(A.shape[1], lo, hi)
        R = sp.csr_matrix(A)
        rlo, rhi = (_highs_inf(v) for v in (self.row_lo, self.row_hi))
        h.addRows(A.shape[0], rlo, rhi, R.nnz, R.indptr[:-1].astype(np.int32), R.indices.astype(np.int32), R.data)
        self._inf = highspy.kHighsInf
        self._cols = np.arange(3 * self.m, dtype=np.int32)
        self._urows = np.arange(self.k, self.k + self.m, dtype=np.int32)

    def run(self, zu: np.ndarray, zr: np.ndarray) -> tuple[str, np.ndarray | None]:
        t0 = time.process_time()
        m, n = self.m, self.n
        g = np.concatenate([zr, zr, zr])
        if self.engine == "clp":
            s = self.lp
            self._cl[:3 * m] = np.where(g, 0.0, self.col_lo[:3 * m])
            self._cu[:3 * m] = np.where(g, 0.0, BIG)
            self._ru[self.k:self.k + m] = np.where(zu, 0.0, BIG)
            s.dual(startFinishOptions="x")
            self.iterations += s.iteration
            status = {0: "optimal", 1: "infeasible"}.get(s.getStatusCode(), "other")
            xp = np.array(s.primalVariableSolution) if status == "optimal" else None
        else:
            import highspy
            h = self.lp
            h.changeColsBounds(3 * m, self._cols, np.where(g, 0.0, np.maximum(self.col_lo[:3 * m], -self._inf)),
                               np.where(g, 0.0, self._inf))
            h.changeRowsBounds(m, self._urows, np.zeros(m), np.where(zu, 0.0, self._inf))
            h.run()
            self.iterations += h.getInfo().simplex_iteration_count
            ms = h.getModelStatus()
            status = ("optimal" if ms == highspy.HighsModelStatus.kOptimal else
                      "infeasible" if ms == highspy.HighsModelStatus.kInfeasible else "other")
            xp = np.array(h.getSolution().col_value) if status == "optimal" else None
        x = None if xp is None else self.form.to_x(xp[:n], xp[n:])
        self.seconds += time.process_time() - t0
        self.calls += 1
        return status, x


def _highs_inf(v: np.ndarray) -> np.ndarray:
    """v with the bounds at +-BIG as HiGHS's infinities."""
    import highspy
    return np.where(v >= BIG, highspy.kHighsInf, np.where(v <= -BIG, -highspy.kHighsInf, v))


def screened_tree(param, m: int, mu: float, variant: str, engine: str, facets: int) -> dict:
    """The enumeration tree with `variant` screens (module doc) on `engine`: counts, CPU."""
    import hpcwedge.patterns as patterns
    from hpcwedge.feasibility import Decision, decide
    from hpcwedge.rows import Status
    from hpcwedge.socp import VERIFY_TOL, violation
    lps = {} if variant == "none" else {
        "outer": PyramidLP(param, m, mu, facets, False, engine),
        **({"inner": PyramidLP(param, m, mu, facets, True, engine)} if variant == "both" else {})}
    counted = {"socps": 0, "inner_feasible": 0, "outer_infeasible": 0, "outer_wrong": 0, "audit": 0.0}

    def screened(rows, mu_, options, counts=None, **kw):
        zu, zr = rows.zero_u, rows.zero_r
        if lps and (~zr).any():
            if "inner" in lps:
                status, x = lps["inner"].run(zu, zr)
                if status == "optimal" and violation(rows, mu_, x) <= VERIFY_TOL:
                    counted["inner_feasible"] += 1
                    return Decision(Status.FEASIBLE, x / (rows.norm @ x))
            if lps["outer"].run(zu, zr)[0] == "infeasible":
                counted["outer_infeasible"] += 1
                t0 = time.process_time()       # the audit: outside the tree's CPU seconds
                if decide(rows, mu_, options).status == Status.FEASIBLE:
                    counted["outer_wrong"] += 1
                counted["audit"] += time.process_time() - t0
                return Decision(Status.INFEASIBLE)
        counted["socps"] += 1
        return decide(rows, mu_, options, counts, **kw)

    saved = patterns.decide
    patterns.decide = screened
    try:
        tree = patterns.PatternTree(param, m, mu)
        t0 = time.process_time()
        ex = tree.explore(tree.root())
        cpu = time.process_time() - t0 - counted["audit"]
    finally:
        patterns.decide = saved
    found = sorted((f.contact, f.gap) for f in ex.found)
    calls = sum(lp.calls for lp in lps.values())
    return {"variant": variant, "engine": engine if lps else None, "tree_nodes": ex.stats.nodes,
            "socps": counted["socps"], "patterns": len(found),
            "socps_per_pattern": round(counted["socps"] / max(len(found), 1), 1),
            "inner_feasible": counted["inner_feasible"], "outer_infeasible": counted["outer_infeasible"],
            "outer_infeasible_but_socp_feasible": counted["outer_wrong"],
            "lps": calls, "iterations_per_lp": round(sum(lp.iterations for lp in lps.values()) / max(calls, 1), 1),
            "hash": hashlib.sha256(repr(found).encode()).hexdigest()[:12],
            "cpu_seconds": round(cpu, 2), "lp_cpu_seconds": round(sum(lp.seconds for lp in lps.values()), 2),
            "ms_per_lp": round(sum(lp.seconds for lp in lps.values()) / max(calls, 1) * 1e3, 3)}


def available(engine: str) -> bool:
    try:
        __import__({"clp": "cylp.cy", "highs": "highspy"}[engine])
        return True
    except ImportError:
        return False


def study(levels: int, ring: int, mu: float, engines: list[str], facets: int) -> list[dict]:
    from hpcwedge.build import contact_problem
    from hpcwedge.problem import parametrize
    prob = contact_problem(scene("enumerate", levels, ring))
    param, m = parametrize(prob), prob.m
    base = screened_tree(param, m, mu, "none", "", facets)
    rows = [base]
    for engine in engines:
        for variant in ("outer", "both"):
            if not available(engine):
                rows.append({"variant": variant, "engine": engine, "missing": True})
                continue
            r = screened_tree(param, m, mu, variant, engine, facets)
            r["same_patterns"] = r["hash"] == base["hash"]
            rows.append(r)
    for r in rows:
        r.update(scene=f"plug3d {levels}x{ring}", m=m, mu=mu, facets=facets)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["2x6", "3x5", "3x6"])
    ap.add_argument("--mu", type=float, default=0.65)
    ap.add_argument("--facets", type=int, default=8)
    ap.add_argument("--engines", nargs="+", default=["clp", "highs"], choices=["clp", "highs"])
    ap.add_argument("--out", default=os.path.join(os.path.dirname(HERE), "results", "bench_lp_screens"))
    args = ap.parse_args(argv)
    rows = []
    print(f"{'scene':<13} {'screens':<12} {'nodes':>7} {'SOCPs':>7} {'/pattern':>8} {'LPs':>7} "
          f"{'it/LP':>6} {'ms/LP':>6} {'LP s':>6} {'CPU s':>6} {'wrong':>5}  patterns")
    for s in args.scenes:
        levels, ring = (int(v) for v in s.split("x"))
        for r in study(levels, ring, args.mu, args.engines, args.facets):
            rows.append(r)
            name = r["variant"] if r["engine"] is None else f"{r['variant']} {r['engine']}"
            if r.get("missing"):
                print(f"{r['scene']:<13} {name:<12} missing (bench extras)")
                continue
            same = "" if "same_patterns" not in r else (" same" if r["same_patterns"] else " DIFFERENT")
            print(f"{r['scene']:<13} {name:<12} {r['tree_nodes']:>7} {r['socps']:>7} {r['socps_per_pattern']:>8} "
                  f"{r['lps']:>7} {r['iterations_per_lp']:>6} {r['ms_per_lp']:>6} {r['lp_cpu_seconds']:>6} "
                  f"{r['cpu_seconds']:>6} {r['outer_infeasible_but_socp_feasible']:>5}  {r['patterns']} {r['hash']}{same}",
                  flush=True)
    from hpcwedge.environment import environment
    with open(args.out + ".json", "w") as f:
        json.dump({"rows": rows, "environment": environment()}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
