"""scene -> model -> condensation -> enumeration -> mu^c -> Result.

Runs only the stages the scene's plan asks for, times each, and returns a
Result whose lists are in canonical order (SPEC §4).

2D: rays (double description), cones, mu^c per cone and global; float decisions too
close to call are detected and, on small problems, redone exactly (numerics.py).
3D: feasible sign patterns per listed mu (branch and bound over SOCPs),
mu^c per pattern and global (2D too with enumerate = "patterns"). The units
of work the parallel layer distributes (parallel.run_patterns: budgeted
PatternTree.explore calls over subtrees; parallel.run_mu_c: mu^c of one
cone or pattern) are the same in both dimensions; under mpirun the 2D double
description is split too (parallel.run_faces: the DD of one face of a few
branching nodes, at one mu).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import cache as once, partial

import numpy as np

from .build import build_model, contact_problem, stiffness_exponent, unscale_u
from .dd import branching_nodes, canonical_order
from .environment import environment, single_threaded
from .model import Model
from .mu_critical import mu_critical
from .numerics import Numerics, enumerate_2d, judge_2d, note_mu_c, settle_patterns_2d
from .parallel import Engine, ranks_on_host, run_faces, run_mu_c, run_patterns, strip_exact
from .global_mu_c import global_mu_critical
from .patterns import BnBStats, PatternTree, expand_orbits
from .problem import ContactProblem, balanced_2d, friction_rows_2d, parametrize, ray_vectors
from .progress import MemoryGuard, Progress, out_of_memory
from .scene import Scene, SceneError
from .symmetry import node_symmetries


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

    def to_dict(self, with_rays: bool = True) -> dict:
        """The `hpcwedge show --json` object of this result (SPEC §4): written to a temporary
        result file and read back by results.read_result, the one JSON writer (so the two
        never differ; it costs a write and a read of the file)."""
        import os
        import tempfile

        from .results import read_result, write_result
        with tempfile.TemporaryDirectory(prefix="hpcwedge-") as folder:
            path = os.path.join(folder, "result.h5")
            write_result(path, self)
            return read_result(path, with_rays=with_rays)


def run_scene(scene: Scene, progress: Progress | None = None, engine: Engine | None = None,
              condensed: tuple[Model, ContactProblem, float] | None = None) -> Result:
    """Every answer the scene asks for (see Scene.plan). Sign patterns and mu^c
    run as tasks of `engine` (parallel.py: in-process by default; the master of
    an MPI run, with checkpoints, from the command line). The 2D rays run as one
    double description per mu, or split over the faces the scene asks for
    (run.face_split; "auto": 3 nodes from m = 16 on) as "face" tasks
    (parallel.run_faces) — the split, and so every bit of the result, depends on
    the scene, not on the rank count; a resumed run keeps its checkpoint's split.
    `condensed`: (model, problem, seconds) of this scene condensed already (the
    command line's distributed condensation under mpirun); None: built and
    condensed here. Runs under the thread policy (environment.single_threaded);
    stats["environment"] records what it ran on (environment.environment).

    Memory: progress.MemoryGuard (run.max_memory_gb) checks every double description step
    and the engine's merges (sign patterns, mu^c: Engine.guard), and a MemoryError that
    still happens becomes one line (progress.MemoryLimit, a SceneError: exit status 2,
    nothing written)."""
    progress = progress or Progress(quiet=True)
    engine = engine or Engine()
    progress.guard = engine.guard = MemoryGuard(scene.max_memory_gb, ranks_on_host())
    try:
        with single_threaded():
            return _run_scene(scene, progress, engine, condensed)
    except MemoryError:
        raise out_of_memory("this run") from None


def _run_scene(scene: Scene, progress: Progress, engine: Engine,
               condensed: tuple[Model, ContactProblem, float] | None) -> Result:
    t0 = time.perf_counter()
    plan = scene.plan()
    timings = {"condense": 0.0, "enumerate": 0.0, "mu_c": 0.0}
    stages = []
    model = None
    t = time.perf_counter()
    if plan.condense and condensed is not None:
        model, problem, timings["condense"] = condensed
        stages.append("condense")
    elif plan.condense:
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
    stats = {"dd": [], "lp_solves": 0, "mu_c_polished": 0, "mu_c_unpolished": 0, "lp_undecided": 0}
    sym = None
    if scene.symmetry and (plan.patterns or plan.mu_c_cones or plan.mu_c_global):
        sym = node_symmetries(problem.K, scene.dim)
        stats["symmetry"] = {"order": sym.order}
        sym = sym if sym.order > 1 else None
    numerics = Numerics.of(problem, scene.exact_fallback_max_m)
    # the exact parametrisation, made once if a fallback needs it
    exact_param = (lambda: param) if scene.exact else once(lambda: parametrize(problem, exact=True))

    if plan.rays:
        t = time.perf_counter()
        stages.append("enumerate")
        nodes = branching_nodes(m, scene.face_split)
        if nodes or engine.restored(RAYS_JOB):
            # split over faces, one task per (mu, face) (SPEC §5); resumed: the saved split.
            # Float: in each mu's balanced coordinates, the merged rays judged as a whole
            # (numerics.judge_2d: redone exactly when suspect and small)
            coords = [(param, None) if scene.exact else balanced_2d(param, run.mu, m, numerics.scale)
                      for run in result.runs]
            rows = [friction_rows_2d(p, run.mu, m, exact=scene.exact) for (p, _), run in zip(coords, result.runs)]
            dds = run_faces(rows, m, exact=scene.exact, engine=engine, nodes=nodes, name=RAYS_JOB,
                            max_memory_gb=scene.max_memory_gb)
            done = [judge_2d(dd, p, cond_T, m, run.mu, numerics, exact_param, progress)
                    for dd, (p, cond_T), run in zip(dds, coords, result.runs)]
        else:
            done = (_rays_whole(param, m, run.mu, numerics, exact_param, progress) for run in result.runs)
        e = stiffness_exponent(scene)
        for run, (dd, p_run) in zip(result.runs, done):
            _fill_rays(run, dd, p_run, m, plan.cones, e)
            stats["dd"].append({"mu": run.mu, **dd.stats})
        timings["enumerate"] = time.perf_counter() - t
        if plan.cones:
            stages.append("cones")

    if plan.patterns:
        t = time.perf_counter()
        stages.append("enumerate")
        make_tree = partial(PatternTree, strip_exact(param), m, symmetry=sym)
        pats = run_patterns(make_tree, scene.mu, engine=engine, budget=scene.task_budget)
        for run, found, doubt in zip(result.runs, pats.found, pats.undecided):
            found, doubt = expand_orbits(found, sym, m), set(expand_orbits(doubt, sym, m))
            run.patterns = [{"contact": np.flatnonzero(s.masks(m)[0]).tolist(), "mu_c": None,
                             "undecided": s in doubt} for s in sorted(found, key=lambda s: s.contact)]
        if sym is not None:
            stats["symmetry"]["representatives"] = [len(f) for f in pats.found]
        c = pats.counters
        stats["patterns_undecided"] = sum(len(u) for u in pats.undecided)
        if scene.dim == 2:
            exact_sets = settle_patterns_2d(numerics, m, scene.mu, c, stats["patterns_undecided"],
                                            exact_param, scene.exact)
            if exact_sets is not None:
                for run, sets in zip(result.runs, exact_sets):
                    run.patterns = [{"contact": list(cs), "mu_c": None, "undecided": False}
                                    for cs in sorted(sets, key=lambda cs: sum(1 << i for i in cs))]
                stats["patterns_undecided"] = 0
        stats["bnb"] = {k: c.get(k, 0) for k in ("nodes", "solves", "skipped", "pruned", "undecided")}
        stats["bnb"]["partitions"] = 2 ** m * len(scene.mu)       # what brute force would solve
        if scene.dim == 3:
            stats["socp_statuses"] = {k[7:]: v for k, v in c.items() if k.startswith("status_")}
        if stats["patterns_undecided"]:
            progress.note(f"warning: {stats['patterns_undecided']} pattern(s) undecided by every "
                          "solver (kept, flagged \"undecided\")")
        timings["enumerate"] += time.perf_counter() - t

    if plan.mu_c_cones or plan.mu_c_global:
        t = time.perf_counter()
        stages.append("mu_c")

        def mask(nodes):
            z = np.zeros(m, dtype=bool)
            z[list(nodes)] = True
            return z

        def orbit_key(zu, zr):    # the same for every pattern of an orbit: one mu^c task each
            bits = (sum(1 << i for i in zu), sum(1 << i for i in zr))
            return bits if sym is None else sym.canonical(*bits)

        def keyed(run):       # (key, zero_u nodes, zero_r nodes, item) of the run's cones and patterns
            for c in run.cones or []:
                yield orbit_key(c["zero_u"], c["zero_r"]), c["zero_u"], c["zero_r"], c
            for p in run.patterns or []:
                gap = sorted(set(range(m)).difference(p["contact"]))
                yield orbit_key(p["contact"], gap), p["contact"], gap, p

        listed = [r for r in result.runs if r.cones or r.patterns]
        wanted = result.runs if plan.mu_c_cones else listed[:1]
        # the keys once per run (the master works alone here: workers wait for the tasks)
        entries = [list(keyed(run)) for run in wanted]
        items: dict = {}      # one task per zero-set pair, at the least mu that lists it
        for run, entry in zip(wanted, entries):
            for key, zu, zr, _ in entry:
                if key not in items:
                    items[key] = (mask(zu), mask(zr), run.mu)
        scale = numerics.scale if scene.dim == 2 else None       # 2D: balanced coordinates
        solve = partial(mu_critical, strip_exact(param), m, mu_max=scene.mu_max,
                        method=scene.mu_c_method, tol=scene.mu_c_tol, scale=scale)
        cache = dict(zip(items, run_mu_c(solve, list(items.values()), engine=engine)))
        for r in cache.values():
            stats["lp_solves"] += r.solves
            stats["lp_undecided"] += r.undecided
            stats["mu_c_polished" if r.polished else "mu_c_unpolished"] += 1
        for entry in entries:
            for key, _, _, item in entry:
                if plan.mu_c_cones:
                    item["mu_c"] = cache[key].mu_c
        if plan.mu_c_global:
            if listed:
                # any pattern feasible below the smallest such mu lies in one of its cones/patterns
                first = next(e for r, e in zip(wanted, entries) if r is listed[0])
                values = [cache[key].mu_c for key, *_ in first]
                values = [v for v in values if v is not None]
                result.mu_c, result.mu_c_status = (min(values), "found") if values else (None, None)
            if result.mu_c is None:
                bnb = BnBStats()
                result.mu_c, result.mu_c_status = global_mu_critical(
                    param, m, scene.mu_max, method=scene.mu_c_method, tol=scene.mu_c_tol, stats=bnb,
                    symmetry=sym, scale=scale)
                stats["bnb"] = {"solves": bnb.solves, "skipped": bnb.skipped,
                                "undecided": bnb.undecided, "nodes": bnb.nodes,
                                "route": bnb.extra.get("route", "tree"),
                                "milp_solves": bnb.extra.get("milp_solves", 0),
                                "milp_nodes": bnb.extra.get("milp_nodes", 0)}
                stats["mu_c_unpolished"] += bnb.extra.get("mu_c_unpolished", 0)
                stats["mu_c_polished"] += bnb.extra.get("mu_c_polished", 0)
        timings["mu_c"] = time.perf_counter() - t
    note_mu_c(numerics, stats["mu_c_unpolished"], stats["lp_undecided"])
    for line in numerics.warnings():
        progress.note(line)
    stats["numerics"] = numerics.as_dict()
    timings["total"] = time.perf_counter() - t0
    stats["parallel"] = engine.summary()
    stats["environment"] = environment()
    result.stats = stats
    return result


#: the engine job of the 2D rays stage (when split over faces)
RAYS_JOB = "rays"


def _rays_whole(param, m: int, mu: float, numerics: Numerics, exact_param, progress: Progress):
    """One double description of P(mu) on the master, unsplit (numerics.enumerate_2d):
    (rays, the parametrisation they are expressed in)."""
    progress.stage(f"rays mu={mu:g}")
    dd, p_run = enumerate_2d(param, m, mu, numerics, exact_param, progress)
    progress.close()
    dd.stats.update(faces=1, branching_nodes=[])
    return dd, p_run


def _fill_rays(run: Run, dd, param, m: int, want_cones: bool, e: int = 0) -> None:
    """The run's rays (canonical order; a wedged ray's u back in the scene's units:
    build.unscale_u with the stiffness exponent e) and cones."""
    order = canonical_order(dd.zero)
    zero = dd.zero[order]
    wedged = ~(zero[:, 1::3] & zero[:, 2::3]).all(axis=1)
    for name, sel in (("rays", wedged), ("trivial_rays", ~wedged)):
        _, V = ray_vectors(param, dd.X[order[sel]], m, np.full(int(sel.sum()), sel is wedged))
        if sel is wedged:                      # trivial rays: sum u_n = 1, no scale to undo
            with np.errstate(over="ignore"):
                V[:, :V.shape[1] // 2] = unscale_u(V[:, :V.shape[1] // 2], e)
            if not np.isfinite(V).all():
                raise SceneError(f"model: the stiffness is so small (~2^{e}) that the wedged rays' "
                                 "displacements u (sum r_n = 1) overflow a double; give K or the "
                                 "moduli in other units")
        setattr(run, name, V)
    run.ray_zero = zero[wedged]
    if not want_cones:
        return
    from .cones import maximal_cones     # networkx: imported only by the 2D cone stage (~0.15 s)
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
