"""scene -> model -> condensation -> enumeration -> mu^c -> Result.

Runs only the stages the scene's plan asks for, times each, and returns a
Result whose lists are in canonical order (SPEC §4).

2D: rays (double description), cones, mu^c per cone and global.
3D: feasible sign patterns per listed mu (branch and bound over SOCPs),
mu^c per pattern and global. The two units of work the parallel layer
distributes are pure calls made here: `feasible_patterns` (explore the
pattern tree at one mu; the parallel layer splits it into
PatternTree.explore calls over subtrees) and `pattern_mu_c` (mu^c of one
pattern).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .build import build_model, contact_problem
from .cones import maximal_cones
from .dd import complementary_rays
from .model import Model
from .mu_critical import mu_critical
from .patterns import BnBStats, PatternTree, global_mu_critical
from .problem import ContactProblem, parametrize, friction_rows_2d, ray_vectors
from .progress import Progress
from .scene import Scene


@dataclass
class Run:
    """The answers at one mu; a field the scene did not ask for is None."""

    mu: float
    rays: np.ndarray | None = None            # (R, 2n) wedged rays [u, r], sum(r_n) = 1
    trivial_rays: np.ndarray | None = None    # (T, 2n) rigid lift-offs, sum(u_n) = 1
    ray_zero: np.ndarray | None = None        # (R, 3m) zero flags of the wedged rays
    cones: list[dict] | None = None           # {"rays", "trivial_rays", "zero_u", "zero_r", "mu_c"}
    patterns: list[dict] | None = None        # {"contact", "mu_c"}

    @property
    def n_wedged_rays(self):
        return None if self.rays is None else len(self.rays)

    @property
    def n_trivial_rays(self):
        return None if self.trivial_rays is None else len(self.trivial_rays)

    @property
    def n_cones(self):
        return None if self.cones is None else len(self.cones)

    @property
    def n_patterns(self):
        return None if self.patterns is None else len(self.patterns)


@dataclass
class Result:
    scene: Scene
    m: int
    runs: list[Run]
    mu_c: float | None = None
    mu_c_status: str | None = None     # "found" | "none_at_any_mu" | "none_up_to_mu_max" | None
    complete: bool = True
    stages: list[str] = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    model: Model | None = None
    problem: ContactProblem | None = None


def run_scene(scene: Scene, progress: Progress | None = None) -> Result:
    """Every answer the scene asks for (see Scene.plan)."""
    progress = progress or Progress(quiet=True)
    t0 = time.perf_counter()
    plan = scene.plan()
    timings = {"condense": 0.0, "enumerate": 0.0, "mu_c": 0.0}
    stages = []
    model = None
    t = time.perf_counter()
    if plan.condense:
        model = build_model(scene)
        problem = contact_problem(scene, model)
        timings["condense"] = time.perf_counter() - t
        stages.append("condense")
    else:
        problem = contact_problem(scene)
    m = problem.m
    param = parametrize(problem, exact=scene.exact)
    result = Result(scene=scene, m=m, runs=[Run(mu=mu) for mu in scene.mu], model=model,
                    problem=problem, stages=stages, timings=timings)
    if scene.dim == 3:
        _run_3d(scene, plan, param, m, result, progress)
        timings["total"] = time.perf_counter() - t0
        return result
    stats = {"dd": [], "lp_solves": 0, "mu_c_polished": 0, "mu_c_unpolished": 0, "lp_undecided": 0}

    if plan.rays:
        t = time.perf_counter()
        stages.append("enumerate")
        for run in result.runs:
            progress.stage(f"rays mu={run.mu:g}")
            A = friction_rows_2d(param, run.mu, m, exact=scene.exact)
            dd = complementary_rays(A, m, exact=scene.exact, progress=progress)
            progress.close()
            _fill_rays(run, dd, param, m, plan.cones)
            stats["dd"].append({"mu": run.mu, **dd.stats})
        timings["enumerate"] = time.perf_counter() - t
        if plan.cones:
            stages.append("cones")

    if plan.mu_c_cones or plan.mu_c_global:
        t = time.perf_counter()
        stages.append("mu_c")
        cache: dict = {}

        def cone_mu_c(cone, mu):
            key = (tuple(cone["zero_u"]), tuple(cone["zero_r"]))
            if key not in cache:
                r = mu_critical(param, m, np.isin(np.arange(m), cone["zero_u"]),
                                np.isin(np.arange(m), cone["zero_r"]), mu_hi=mu,
                                mu_max=scene.mu_max, method=scene.mu_c_method, tol=scene.mu_c_tol)
                stats["lp_solves"] += r.lps
                stats["lp_undecided"] += r.undecided
                stats["mu_c_polished" if r.polished else "mu_c_unpolished"] += 1
                cache[key] = r.mu_c
            return cache[key]

        with_cones = [r for r in result.runs if r.cones]
        if plan.mu_c_cones:
            for run in result.runs:
                for cone in run.cones or []:
                    cone["mu_c"] = cone_mu_c(cone, run.mu)
        if plan.mu_c_global:
            if with_cones:
                # any pattern feasible below the smallest such mu lies in one of its cones
                run = with_cones[0]
                values = [cone_mu_c(c, run.mu) for c in run.cones]
                values = [v for v in values if v is not None]
                result.mu_c, result.mu_c_status = (min(values), "found") if values else (None, None)
            if result.mu_c is None:
                bnb = BnBStats()
                result.mu_c, result.mu_c_status = global_mu_critical(
                    param, m, scene.mu_max, method=scene.mu_c_method, tol=scene.mu_c_tol, stats=bnb)
                stats["bnb"] = {"solves": bnb.solves, "skipped": bnb.skipped,
                                "undecided": bnb.undecided, "nodes": bnb.nodes}
        timings["mu_c"] = time.perf_counter() - t
    if stats["mu_c_unpolished"]:
        progress.note(f"warning: {stats['mu_c_unpolished']} mu^c value(s) not polished "
                      f"(accurate to the bracket, {1e-7:g} relative)")
    timings["total"] = time.perf_counter() - t0
    result.stats = stats
    return result


def _fill_rays(run: Run, dd, param, m: int, want_cones: bool) -> None:
    order = np.lexsort(dd.zero.T[::-1])
    X, zero = dd.X[order], dd.zero[order]
    wedged = ~(zero[:, 1::3] & zero[:, 2::3]).all(axis=1)
    _, V = ray_vectors(param, X, m, wedged)
    run.rays, run.trivial_rays, run.ray_zero = V[wedged], V[~wedged], zero[wedged]
    if not want_cones:
        return
    gap = ~zero[:, 0::3]
    load = ~(zero[:, 1::3] & zero[:, 2::3])
    widx = np.cumsum(wedged) - 1
    tidx = np.cumsum(~wedged) - 1
    run.cones = []
    for cone in maximal_cones(gap, load, wedged):
        rays = np.asarray(cone.rays, dtype=int)
        run.cones.append({"rays": widx[rays[wedged[rays]]].tolist(),
                          "trivial_rays": tidx[rays[~wedged[rays]]].tolist(),
                          "zero_u": np.flatnonzero(cone.zero_u).tolist(),
                          "zero_r": np.flatnonzero(cone.zero_r).tolist(),
                          "mu_c": None})


# ---------------------------------------------------------------------------- 3D
def feasible_patterns(param, m: int, mu: float, order: list[int] | None = None):
    """The feasible sign patterns at mu, serially: (found, undecided, stats), found
    and undecided as lists of Subtree (full depth), undecided ⊆ found."""
    tree = PatternTree(param, m, mu, order=order)
    out = tree.explore(tree.root())
    return out.found, out.undecided, out.stats


def pattern_mu_c(param, m: int, contact: int, mu_hi: float | None, scene: Scene):
    """mu^c of the full pattern with contact bits `contact` (the others gap)."""
    zu = np.array([(contact >> i) & 1 for i in range(m)], dtype=bool)
    return mu_critical(param, m, zu, ~zu, mu_hi=mu_hi, mu_max=scene.mu_max,
                       method=scene.mu_c_method, tol=scene.mu_c_tol)


def _run_3d(scene: Scene, plan, param, m: int, result: Result, progress: Progress) -> None:
    """Feasible sign patterns per mu, their mu^c and the global mu^c (SPEC §2, 3D)."""
    timings, stages = result.timings, result.stages
    stats = {"bnb": [], "socp_statuses": {}, "mu_c_solves": 0, "mu_c_polished": 0,
             "mu_c_unpolished": 0, "mu_c_undecided": 0, "patterns_undecided": 0}

    def absorb(counts: dict) -> None:
        for k, v in counts.items():
            stats["socp_statuses"][k] = stats["socp_statuses"].get(k, 0) + v

    found_at: dict[float, list[int]] = {}
    if plan.patterns:
        t = time.perf_counter()
        stages.append("enumerate")
        for run in result.runs:
            progress.stage(f"patterns mu={run.mu:g}")
            found, undecided, bnb = feasible_patterns(param, m, run.mu)
            progress.close()
            doubt = {s.contact for s in undecided}
            bits = sorted(s.contact for s in found)
            found_at[run.mu] = bits
            run.patterns = [{"contact": [i for i in range(m) if (b >> i) & 1], "mu_c": None,
                             "undecided": b in doubt} for b in bits]
            stats["patterns_undecided"] += len(doubt)
            stats["bnb"].append({"mu": run.mu, "solves": bnb.solves, "skipped": bnb.skipped,
                                 "undecided": bnb.undecided, "nodes": bnb.nodes,
                                 "partitions": 2 ** m})
            absorb(bnb.statuses)
        timings["enumerate"] = time.perf_counter() - t

    if plan.mu_c_cones or plan.mu_c_global:
        t = time.perf_counter()
        stages.append("mu_c")
        cache: dict[int, float | None] = {}

        def mu_c_of(bits: int, mu: float):
            if bits not in cache:
                r = pattern_mu_c(param, m, bits, mu, scene)
                stats["mu_c_solves"] += r.lps
                stats["mu_c_undecided"] += r.undecided
                stats["mu_c_polished" if r.polished else "mu_c_unpolished"] += 1
                absorb(r.statuses)
                cache[bits] = r.mu_c
            return cache[bits]

        if plan.mu_c_cones:
            for run in result.runs:
                for pat, bits in zip(run.patterns or [], found_at.get(run.mu, [])):
                    pat["mu_c"] = mu_c_of(bits, run.mu)
        if plan.mu_c_global:
            with_patterns = [r for r in result.runs if found_at.get(r.mu)]
            if with_patterns:
                # every pattern feasible below the smallest such mu is among its patterns
                run = with_patterns[0]
                values = [v for v in (mu_c_of(b, run.mu) for b in found_at[run.mu]) if v is not None]
                if values:
                    result.mu_c, result.mu_c_status = min(values), "found"
            if result.mu_c is None:
                bnb = BnBStats()
                result.mu_c, result.mu_c_status = global_mu_critical(
                    param, m, scene.mu_max, method=scene.mu_c_method, tol=scene.mu_c_tol, stats=bnb)
                stats["global_bnb"] = {"solves": bnb.solves, "skipped": bnb.skipped,
                                       "undecided": bnb.undecided, "nodes": bnb.nodes, **bnb.extra}
                absorb(bnb.statuses)
        timings["mu_c"] = time.perf_counter() - t
    if stats["mu_c_unpolished"]:
        progress.note(f"warning: {stats['mu_c_unpolished']} mu^c value(s) not polished "
                      f"(accurate to the bracket, {1e-7:g} relative)")
    if stats["patterns_undecided"]:
        progress.note(f"warning: {stats['patterns_undecided']} pattern(s) undecided by every solver "
                      "(kept, flagged \"undecided\")")
    result.stats = stats
