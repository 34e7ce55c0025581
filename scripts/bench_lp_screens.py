#!/usr/bin/env python3
"""Polyhedral LP screens before the 3D tree's SOCPs (issue 13): counts and CPU.

    PYTHONPATH=. python scripts/bench_lp_screens.py [--scenes 2x6 3x5 3x6] [--mu 0.65]
                                                    [--facets 8] [--engines clp highs]
                                                    [--forms facets generators]
                                                    [--from-depths 6 8 9 10]
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
Then `both` on CLP's generator form from each --from-depths D on: the screens only at tree
nodes with >= D nodes fixed, the SOCP alone above (its interior points choose the branching
there; no node of plug3d 3 x 6 with fewer than 8 fixings is infeasible).
One LP model per (scene, pyramid, form), kept warm in the engine (a node changes bounds
only: the reactions of its gap nodes fixed to 0, the u_n rows of its contact nodes fixed to
0), in either form of the same pyramids (PyramidLP): `facets` (a row per facet) or
`generators` (a column per edge, k + m + 1 rows):
  clp    COIN-OR CLP through cylp (EPL-2.0): dual simplex, the bounds written into CLP's
         own arrays, its work areas kept between solves
  highs  HiGHS through highspy: dual simplex, presolve off, bounds changed by its API; a
         warm solve that ends neither optimal nor infeasible (HiGHS's "Unknown", seen under
         other BLAS kernels, whose last bits change the model's rows) is solved again cold
         and counted (`cold_retries`)
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
import os
import sys
import time
from types import SimpleNamespace

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from bench_search_3d import scene  # noqa: E402
from harness import write_json  # noqa: E402

from hpcwedge.solvers.screens import edge_matrix  # noqa: E402

#: what the engines take for an infinite bound (CLP: COIN_DBL_MAX)
BIG = float(np.finfo(float).max)


class PyramidLP:
    """The LP of a node's problem at mu with every friction cone replaced by a k-facet
    pyramid (rows.pyramid_rows: inner inscribed, outer circumscribed; a facet normal on t1),
    in the reaction coordinates x' = (r, beta) of problem.ReactionCoordinates, one model for
    every node, in one of two forms of the same pyramids:
      facets      columns (r, beta): E r = 0; u_n = U_n x' >= 0 (= 0 at a contact node); the
                  k facets of every node; sum r_n = 1; r_n >= 0 as column bounds (a gap
                  node's three reactions fixed to 0)
      generators  columns (lambda, beta), r = G lambda with lambda >= 0 on the k edges of
                  every node's pyramid (pyramid_edges): E G lambda = 0; u_n >= 0 (= 0 at a
                  contact node); sum lambda = 1 (each edge has r_n = 1); a gap node's k
                  lambdas fixed to 0. k + m + 1 rows instead of k + m + km + 1.
    Rows unit-scaled. `run(zu, zr)`: (status "optimal" / "infeasible" / "other", x-space
    point or None)."""

    def __init__(self, param, m: int, mu: float, facets: int, inner: bool, engine: str,
                 form: str = "facets"):
        from hpcwedge.solvers.rows import pyramid_rows
        rc = param.reactions
        self.rc, self.m, self.form = rc, m, form
        n, nb, k = rc.E.shape[1], rc.U.shape[1] - rc.E.shape[1], rc.E.shape[0]
        self.n, self.k = n, k
        Un = rc.U[:m]
        if form == "facets":
            nc = n + nb
            # the pattern rows of no fixing, in x': what pyramid_rows reads of a rows.ConeRows
            # (eq, lin, the cones' rn and rt, norm); every cone a coordinate cone
            cols = np.eye(nc)[:n].reshape(3, m, nc)
            free = SimpleNamespace(eq=np.hstack([rc.E, np.zeros((k, nb))]),
                                   lin=Un / np.linalg.norm(Un, axis=1, keepdims=True),
                                   rn=cols[0], rt=cols[1:].transpose(1, 0, 2), norm=cols[0].sum(axis=0))
            pyramid = pyramid_rows(free, facets, inner, phase=np.zeros(m))
            A = pyramid.a0 + mu * pyramid.a1
            A[k + m:] /= np.linalg.norm(A[k + m:], axis=1, keepdims=True)   # the facets; the rest are unit
            A = np.vstack([A, free.norm])
            self.G, fixed = None, 3 * m               # a gap node fixes r_n, r_t1, r_t2
            self.col_lo = np.concatenate([np.zeros(m), np.full(nc - m, -BIG)])
        else:
            G = edge_matrix(m, mu, facets, inner)                     # node i's edges: columns i*k..
            A_u = np.hstack([Un[:, :n] @ G, Un[:, n:]])
            A = np.vstack([np.hstack([rc.E @ G, np.zeros((k, nb))]),
                           A_u / np.linalg.norm(A_u, axis=1, keepdims=True),
                           np.concatenate([np.ones(m * facets), np.zeros(nb)])])
            self.G, fixed = G, m * facets
            self.col_lo = np.concatenate([np.zeros(fixed), np.full(nb, -BIG)])
        self.facets = facets
        rows = A.shape[0] - 1
        self.row_lo = np.concatenate([np.zeros(rows), [1.0]])
        self.row_hi = np.concatenate([np.zeros(k), np.full(rows - k, BIG), [1.0]])
        self.col_hi = np.full(A.shape[1], BIG)
        self.fixed = fixed                            # the leading columns a gap node fixes
        self.seconds, self.calls, self.iterations, self.cold_retries = 0.0, 0, 0, 0
        self._solve = getattr(self, "_load_" + engine)(A)

    def gap_columns(self, zr: np.ndarray) -> np.ndarray:
        """The mask over the leading `fixed` columns of the gap nodes zr."""
        return np.concatenate([zr, zr, zr]) if self.G is None else np.repeat(zr, self.facets)

    def to_x(self, xp: np.ndarray) -> np.ndarray:
        """The x-space point of the LP's column values xp."""
        if self.G is None:
            return self.rc.to_x(xp[:self.n], xp[self.n:])
        return self.rc.to_x(self.G @ xp[:self.fixed], xp[self.fixed:])

    def _load_clp(self, A):
        """CLP's model of A; returns its solve(g, zu) -> (status, x' or None)."""
        import scipy.sparse as sp
        from cylp.cy import CyClpSimplex
        from cylp.cy.CyCoinPackedMatrix import CyCoinPackedMatrix
        C = sp.csc_matrix(A).tocoo()       # CoinPackedMatrix(colOrdered) wants column order
        M = CyCoinPackedMatrix(True, C.row.astype(np.int32), C.col.astype(np.int32), C.data.astype(float))
        s = CyClpSimplex()
        s.loadProblem(M, self.col_lo, self.col_hi, np.zeros(A.shape[1]), self.row_lo, self.row_hi)
        s.logLevel = 0
        s.dual()
        # views of CLP's own bound arrays, written in place (cylp's array setters hand CLP
        # the numpy buffer itself, which CLP then frees: a double free at exit)
        cl, cu, ru = s.variablesLower, s.variablesUpper, s.constraintsUpper
        m, k, f, lo = self.m, self.k, self.fixed, self.col_lo[:self.fixed]
        statuses = {0: "optimal", 1: "infeasible"}

        def solve(g, zu):
            cl[:f] = np.where(g, 0.0, lo)
            cu[:f] = np.where(g, 0.0, BIG)
            ru[k:k + m] = np.where(zu, 0.0, BIG)
            s.dual(startFinishOptions="x")
            self.iterations += s.iteration
            status = statuses.get(s.getStatusCode(), "other")
            return status, np.array(s.primalVariableSolution) if status == "optimal" else None
        return solve

    def _load_highs(self, A):
        """HiGHS's model of A; returns its solve(g, zu) -> (status, x' or None)."""
        import highspy
        import scipy.sparse as sp
        h = highspy.Highs()
        h.setOptionValue("output_flag", False)
        h.setOptionValue("presolve", "off")
        h.setOptionValue("solver", "simplex")
        inf = highspy.kHighsInf
        h.addVars(A.shape[1], _highs_inf(self.col_lo, inf), _highs_inf(self.col_hi, inf))
        R = sp.csr_matrix(A)
        h.addRows(A.shape[0], _highs_inf(self.row_lo, inf), _highs_inf(self.row_hi, inf), R.nnz,
                  R.indptr[:-1].astype(np.int32), R.indices.astype(np.int32), R.data)
        m, k, f = self.m, self.k, self.fixed
        cols, urows = np.arange(f, dtype=np.int32), np.arange(k, k + m, dtype=np.int32)
        lo, zeros = _highs_inf(self.col_lo[:f], inf), np.zeros(m)
        statuses = {highspy.HighsModelStatus.kOptimal: "optimal",
                    highspy.HighsModelStatus.kInfeasible: "infeasible"}

        def solve(g, zu):
            h.changeColsBounds(f, cols, np.where(g, 0.0, lo), np.where(g, 0.0, inf))
            h.changeRowsBounds(m, urows, zeros, np.where(zu, 0.0, inf))
            h.run()
            self.iterations += h.getInfo().simplex_iteration_count
            if h.getModelStatus() not in statuses:
                self.cold_retries += 1
                h.clearSolver()
                h.run()
                self.iterations += h.getInfo().simplex_iteration_count
            status = statuses.get(h.getModelStatus(), "other")
            return status, np.array(h.getSolution().col_value) if status == "optimal" else None
        return solve

    def run(self, zu: np.ndarray, zr: np.ndarray) -> tuple[str, np.ndarray | None]:
        t0 = time.process_time()
        status, xp = self._solve(self.gap_columns(zr), zu)
        x = None if xp is None else self.to_x(xp)
        self.seconds += time.process_time() - t0
        self.calls += 1
        return status, x


def _highs_inf(v: np.ndarray, inf: float) -> np.ndarray:
    """v with the bounds at +-BIG as HiGHS's infinity inf."""
    return np.where(v >= BIG, inf, np.where(v <= -BIG, -inf, v))


def screened_tree(param, m: int, mu: float, variant: str, engine: str, facets: int,
                  form: str = "facets", from_depth: int = 0) -> dict:
    """The enumeration tree with `variant` screens (module doc) on `engine`, its LPs in
    `form` (PyramidLP), at the tree nodes with at least `from_depth` nodes fixed (above:
    the SOCP alone, whose interior points choose the branching there): counts, CPU."""
    import hpcwedge.patterns.tree as patterns
    from hpcwedge.solvers.feasibility import Decision, decide
    from hpcwedge.solvers.rows import Status
    from hpcwedge.solvers.socp import VERIFY_TOL, violation
    lps = {} if variant == "none" else {
        "outer": PyramidLP(param, m, mu, facets, False, engine, form),
        **({"inner": PyramidLP(param, m, mu, facets, True, engine, form)} if variant == "both" else {})}
    counted = {"socps": 0, "inner_feasible": 0, "outer_infeasible": 0, "outer_wrong": 0, "audit": 0.0}

    def screened(rows, mu_, options, counts=None, **kw):
        zu, zr = rows.zero_u, rows.zero_r
        if lps and (~zr).any() and np.count_nonzero(zu | zr) >= from_depth:
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
    return {"variant": variant, "engine": engine if lps else None, "form": form if lps else None,
            "from_depth": from_depth, "tree_nodes": ex.stats.nodes,
            "socps": counted["socps"], "patterns": len(found),
            "socps_per_pattern": round(counted["socps"] / max(len(found), 1), 1),
            "inner_feasible": counted["inner_feasible"], "outer_infeasible": counted["outer_infeasible"],
            "outer_infeasible_but_socp_feasible": counted["outer_wrong"],
            "lps": calls, "cold_retries": sum(lp.cold_retries for lp in lps.values()),
            "iterations_per_lp": round(sum(lp.iterations for lp in lps.values()) / max(calls, 1), 1),
            "hash": hashlib.sha256(repr(found).encode()).hexdigest()[:12],
            "cpu_seconds": round(cpu, 2), "lp_cpu_seconds": round(sum(lp.seconds for lp in lps.values()), 2),
            "ms_per_lp": round(sum(lp.seconds for lp in lps.values()) / max(calls, 1) * 1e3, 3)}


def available(engine: str) -> bool:
    try:
        __import__({"clp": "cylp.cy", "highs": "highspy"}[engine])
        return True
    except ImportError:
        return False


def study(levels: int, ring: int, mu: float, engines: list[str], facets: int,
          forms: tuple[str, ...] = ("facets",), from_depths: tuple[int, ...] = ()) -> list[dict]:
    """The rows of one scene: the product's tree, then per engine and form the outer and
    both screens at every node, then both screens on CLP's generator form from each of
    `from_depths` on (when CLP imports)."""
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.contact.problem import parametrize
    prob = contact_problem(scene("enumerate", levels, ring))
    param, m = parametrize(prob), prob.m
    base = screened_tree(param, m, mu, "none", "", facets)
    rows = [base]
    for engine in engines:
        for form, variant in ((f, v) for f in forms for v in ("outer", "both")):
            if not available(engine):
                rows.append({"variant": variant, "engine": engine, "form": form, "missing": True})
                continue
            r = screened_tree(param, m, mu, variant, engine, facets, form)
            r["same_patterns"] = r["hash"] == base["hash"]
            rows.append(r)
    for d in from_depths if available("clp") else ():
        r = screened_tree(param, m, mu, "both", "clp", facets, "generators", d)
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
    ap.add_argument("--forms", nargs="+", default=["facets", "generators"], choices=["facets", "generators"])
    ap.add_argument("--from-depths", nargs="*", type=int, default=[6, 8, 9, 10],
                    help="rows of both screens (CLP, generators) from this many fixings on")
    ap.add_argument("--out", default=os.path.join(os.path.dirname(HERE), "results", "bench_lp_screens"))
    args = ap.parse_args(argv)
    rows = []
    print(f"{'scene':<13} {'screens':<20} {'nodes':>7} {'SOCPs':>7} {'/pattern':>8} {'LPs':>7} "
          f"{'it/LP':>6} {'ms/LP':>6} {'LP s':>6} {'CPU s':>6} {'wrong':>5}  patterns")
    for s in args.scenes:
        levels, ring = (int(v) for v in s.split("x"))
        for r in study(levels, ring, args.mu, args.engines, args.facets, tuple(args.forms),
                       tuple(args.from_depths)):
            rows.append(r)
            name = r["variant"] if r["engine"] is None else f"{r['variant']} {r['engine']} {r['form'][:3]}"
            name += f" >={r['from_depth']}" if r.get("from_depth") else ""
            if r.get("missing"):
                print(f"{r['scene']:<13} {name:<20} missing (bench extras)")
                continue
            same = "" if "same_patterns" not in r else (" same" if r["same_patterns"] else " DIFFERENT")
            print(f"{r['scene']:<13} {name:<20} {r['tree_nodes']:>7} {r['socps']:>7} {r['socps_per_pattern']:>8} "
                  f"{r['lps']:>7} {r['iterations_per_lp']:>6} {r['ms_per_lp']:>6} {r['lp_cpu_seconds']:>6} "
                  f"{r['cpu_seconds']:>6} {r['outer_infeasible_but_socp_feasible']:>5}  {r['patterns']} {r['hash']}{same}",
                  flush=True)
    write_json(args.out + ".json", {"rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
