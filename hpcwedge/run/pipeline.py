"""The pipeline: scene -> model -> condensation -> enumeration -> mu^c -> Result.

run_scene loops over the scene's plan (Scene.plan().steps()), one function per stage, each
returning a typed record that the loop files into the Result and its SolveStats:

  condense     -> Condensed      the model and its contact problem (here, or before the
                                 pipeline over the ranks of an MPI run: run.condense, batch.py)
  rays         -> list[Rays]     2D: the complementary extreme rays per listed mu
  cones        -> Cones          2D: the maximal cross-complementary cones of one mu's rays
  patterns     -> PatternSets    feasible sign patterns per listed mu (3D; 2D with
                                 enumerate = "patterns")
  mu_c         -> MuCValues      mu^c per cone / pattern, one task per orbit (mu_c_keys)
  global_mu_c  -> GlobalMuC      the least mu with a wedged configuration

Lists are in canonical order (SPEC §4). 2D float decisions too close to call are detected
and, on small problems, redone exactly (numerics.py). The units of work the parallel layer
distributes (patterns.run_patterns: budgeted PatternTree.explore calls over subtrees;
mu_critical.run_mu_c: mu^c of one cone or pattern) are the same in both dimensions; the 2D
double description is split over faces when the scene asks (faces.run_faces: the DD of
one face of a few branching nodes, at one mu).
"""
from __future__ import annotations

import contextlib

import time
from dataclasses import replace
from functools import cache as once
from functools import partial

import numpy as np

from hpcwedge.contact.build import build_model, contact_problem, stiffness_exponent, unscale_u
from hpcwedge.contact.problem import (
    ContactProblem,
    Parametrization,
    balanced,
    friction_rows_2d,
    parametrize,
    ray_vectors,
)
from hpcwedge.environment import environment, single_threaded
from hpcwedge.mu_c.critical import mu_critical, run_mu_c
from hpcwedge.mu_c.exact_2d import certify_2d, exact_certifier
from hpcwedge.mu_c.global_search import global_mu_critical
from hpcwedge.nodesets import bits_to_nodes, canonical_order, pattern_key, to_bits, to_mask
from hpcwedge.parallel.engine import Engine
from hpcwedge.patterns.job import run_patterns
from hpcwedge.patterns.symmetry import Symmetry, node_symmetries
from hpcwedge.patterns.tree import BnBStats, PatternTree, expand_orbits, solver_statuses
from hpcwedge.progress import MemoryGuard, Progress, out_of_memory, ranks_on_host
from hpcwedge.rays.faces import branching_nodes, run_faces
from hpcwedge.rays.numerics import (
    NumericsReport,
    checked_rays_2d,
    drop_below_mu_c,
    note_mu_c,
    note_near_mu_c,
    recheck_patterns_2d,
    settle_rays_2d,
)
from hpcwedge.results.record import (
    Cone,
    GlobalRouteStats,
    Pattern,
    Result,
    Run,
    SolveStats,
    SymmetryStats,
    TreeStats,
)
from hpcwedge.run.stages import Condensed, Cones, Context, GlobalMuC, MuCValues, OrbitKey, PatternSets, Rays
from hpcwedge.scene.parse import Plan, Scene
from hpcwedge.scene.values import SceneError

#: the engine job of the 2D rays stage (when split over faces)
RAYS_JOB = "rays"
#: a plan step -> (its name in Result.stages, its timings key)
STEP_REPORT = {"condense": ("condense", "condense"), "rays": ("enumerate", "enumerate"),
               "cones": ("cones", "enumerate"), "patterns": ("enumerate", "enumerate"),
               "mu_c": ("mu_c", "mu_c"), "global_mu_c": ("mu_c", "mu_c")}



# ---------------------------------------------------------------------------- the loop

def run_scene(scene: Scene, progress: Progress | None = None, engine: Engine | None = None,
              condensed: Condensed | None = None) -> Result:
    """Every answer the scene asks for: its plan's stages in order (Scene.plan). Sign
    patterns and mu^c run as tasks of `engine` (parallel/: in-process by default; the
    master of an MPI run, with checkpoints, in a batch run: batch.py). The 2D rays run as one
    double description per mu, or split over the faces the scene asks for (run.face_split;
    "auto": 3 nodes from m = 16 on) as "face" tasks (faces.run_faces) — the split, and so
    every bit of the result, depends on the scene, not on the rank count; a resumed run keeps
    its checkpoint's split. `condensed`: the condense stage's record when the caller has
    it (an MPI run's start-up, collective over the ranks: batch.condense_on_ranks); None:
    condensed here. Runs under the thread policy (environment.single_threaded);
    stats["environment"] records what it ran on (environment.environment).

    Memory: progress.MemoryGuard (run.max_memory_gb) checks every double description step
    and the engine's merges (sign patterns, mu^c: Engine.guard), and a MemoryError that
    still happens becomes one line (progress.MemoryLimit, a UserError: exit status 2,
    nothing written)."""
    scene.input_digests          # the bytes of its files as solved (cached): what the result records
    progress = progress or Progress(quiet=True)
    engine = engine or Engine()
    progress.guard = engine.guard = MemoryGuard(scene.max_memory_gb, ranks_on_host())
    try:
        with single_threaded():
            return _run_plan(scene, progress, engine, condensed)
    except MemoryError:
        raise out_of_memory("this run") from None


def _run_plan(scene: Scene, progress: Progress, engine: Engine, condensed: Condensed | None) -> Result:
    """run_scene under its thread policy: condense, then the plan's steps, their records filed."""
    t0 = time.perf_counter()
    plan = scene.plan()
    condensed = condensed or condense(scene, progress)
    result = Result(scene=scene, m=condensed.problem.m, runs=[Run(mu=mu) for mu in scene.mu],
                    model=condensed.model, problem=condensed.problem,
                    timings={"condense": 0.0, "enumerate": 0.0, "mu_c": 0.0})
    if plan.condense:
        _report(result, "condense", condensed.seconds)
    stats = SolveStats()
    ctx = _context(scene, plan, condensed.problem, engine, progress, stats)
    found = values = None
    for step in plan.steps():
        t = time.perf_counter()
        if step == "rays":
            found = rays(ctx)
            for run, r in zip(result.runs, found):
                run.rays, run.trivial_rays, run.ray_zero = r.rays, r.trivial_rays, r.ray_zero
                stats.dd.append({"mu": r.mu, **r.stats})
            found = found if plan.cones else None         # every ray's zero flags: the cones' input
        elif step == "cones":
            for run, r in zip(result.runs, found):
                run.cones = cones(r).items
            found = None
        elif step == "patterns":
            _file_patterns(patterns(ctx), result.runs, stats)
        elif step == "mu_c":
            values = mu_c(ctx, result.runs, every_run=plan.mu_c_cones)
            for r in values.by_key.values():
                stats.add(solves=r.solves, undecided=r.undecided, polished=int(r.polished),
                          unpolished=int(not r.polished))
            if plan.mu_c_cones:
                _file_mu_c(values, result.runs)
        elif step == "global_mu_c":
            g = global_mu_c(ctx, values)
            result.mu_c, result.mu_c_status = g.mu_c, g.status
            if g.search is not None:
                stats.bnb = g.search
                stats.add(polished=g.polished, unpolished=g.unpolished)
        _report(result, step, time.perf_counter() - t)
    drop_below_mu_c(ctx.numerics, result.runs)
    note_mu_c(ctx.numerics, stats.mu_c_unpolished, stats.lp_undecided)
    note_near_mu_c(ctx.numerics, result.runs)
    for line in ctx.numerics.warnings():
        progress.note(line)
    stats.numerics = ctx.numerics.as_dict()
    result.timings["total"] = time.perf_counter() - t0
    stats.parallel = engine.summary()
    stats.environment = environment()
    result.stats = stats.as_dict()
    return result


def _report(result: Result, step: str, seconds: float) -> None:
    """A step's name into result.stages (once for consecutive steps of one name) and its
    seconds into result.timings (STEP_REPORT)."""
    name, clock = STEP_REPORT[step]
    if not result.stages or result.stages[-1] != name:
        result.stages.append(name)
    result.timings[clock] += seconds


def _context(scene: Scene, plan: Plan, problem: ContactProblem, engine: Engine, progress: Progress,
             stats: SolveStats) -> Context:
    """The stages' shared context: the parametrisation (exact when the scene asks), the node
    symmetries when a stage uses them (their order into stats.symmetry), the numerics."""
    param = parametrize(problem, exact=scene.exact)
    sym = None
    if scene.symmetry and (plan.patterns or plan.mu_c_cones or plan.mu_c_global):
        sym = node_symmetries(problem.K, scene.dim)
        stats.symmetry = SymmetryStats(sym.order)
        sym = sym if sym.order > 1 else None
    numerics = NumericsReport.of(problem, scene.exact_fallback_max_m)
    exact_param = (lambda: param) if scene.exact else once(lambda: parametrize(problem, exact=True))
    float_param = parametrize(problem) if scene.exact else param
    return Context(scene, problem.m, param, numerics, exact_param, float_param, sym, engine, progress)


# ---------------------------------------------------------------------------- the stages

#: a model of this many DOFs or more says on stderr when its condensation starts and ends
#: (block2d refine 120, 290,000 DOFs: ~4 s; refine 160, 514,242 DOFs: 15-30 s on 2 cores)
NOTE_CONDENSE_MIN_DOFS = 100_000


def condense(scene: Scene, progress: Progress | None = None) -> Condensed:
    """The condense stage: the scene's model built and condensed (build.build_model,
    build.contact_problem), or a raw K read (no model, 0 s). (Under mpirun the batch may have
    condensed it over the ranks first: batch.condense_on_ranks.) progress: where a large
    model's condensation is announced (`noted_condensation`)."""
    if not scene.plan().condense:
        return Condensed(None, contact_problem(scene))
    t = time.perf_counter()
    model = build_model(scene)
    with noted_condensation(model, progress):
        problem = contact_problem(scene, model)
    return Condensed(model, problem, time.perf_counter() - t)


@contextlib.contextmanager
def noted_condensation(model, progress: Progress | None, where: str = ""):
    """A line when the condensation of a model of NOTE_CONDENSE_MIN_DOFS DOFs or more starts
    (its size; where: how it is spread) and one when it ends (its seconds); nothing for smaller
    models or without progress."""
    if progress is None or model is None or model.n_dofs < NOTE_CONDENSE_MIN_DOFS:
        yield
        return
    progress.note(f"condense: {model.n_dofs:,} DOFs onto {len(model.contact_nodes):,} contact nodes{where}")
    t = time.perf_counter()
    yield
    progress.note(f"condense: done ({time.perf_counter() - t:.1f} s)")


def rays(ctx: Context) -> list[Rays]:
    """The 2D rays stage: per listed mu, the complementary extreme rays of P(mu). One double
    description per mu on the master, or split over the faces of the scene's branching
    nodes (faces.branching_nodes; resumed: the checkpoint's split), one "face" task per (mu,
    face), the merged rays judged as a whole in each mu's balanced coordinates (float:
    numerics.settle_rays_2d, redone exactly when suspect and small)."""
    scene, m, param, numerics = ctx.scene, ctx.m, ctx.param, ctx.numerics
    e = stiffness_exponent(scene)
    nodes = branching_nodes(m, scene.face_split)
    if nodes or ctx.engine.restored(RAYS_JOB):
        coords = [(param, None) if scene.exact else balanced(param, mu, m, numerics.scale)[:2]
                  for mu in scene.mu]
        rows = [friction_rows_2d(p, mu, m, exact=scene.exact) for (p, _), mu in zip(coords, scene.mu)]
        dds = run_faces(rows, m, exact=scene.exact, engine=ctx.engine, nodes=nodes, name=RAYS_JOB,
                        max_memory_gb=scene.max_memory_gb)
        done = [settle_rays_2d(dd, p, cond_T, m, mu, numerics, ctx.exact_param, ctx.progress)
                for dd, (p, cond_T), mu in zip(dds, coords, scene.mu)]
    else:                                        # one mu at a time: each DD dropped once filed
        done = (_rays_whole(ctx, mu) for mu in scene.mu)
    found = []
    for mu, (dd, p_run) in zip(scene.mu, done):
        found.append(r := _rays_of(dd, p_run, m, mu, e))
        # the counts in show's words (cli.py)
        ctx.progress.note(f"rays mu={mu:g}: {len(r.rays)} wedged + {len(r.trivial_rays)} trivial rays")
    return found


def _rays_whole(ctx: Context, mu: float):
    """One double description of P(mu) on the master, unsplit (numerics.checked_rays_2d):
    (rays, the parametrisation they are expressed in)."""
    ctx.progress.stage(f"rays mu={mu:g}")
    dd, p_run = checked_rays_2d(ctx.param, ctx.m, mu, ctx.numerics, ctx.exact_param, ctx.progress)
    ctx.progress.close()
    dd.stats.update(faces=1, branching_nodes=[])
    return dd, p_run


def _rays_of(dd, param: Parametrization, m: int, mu: float, e: int = 0) -> Rays:
    """The Rays of one mu's double description: canonical order, a wedged ray's u back in
    the scene's units (build.unscale_u with the stiffness exponent e)."""
    order = canonical_order(dd.zero)
    zero = dd.zero[order]
    wedged = ~(zero[:, 1::3] & zero[:, 2::3]).all(axis=1)
    out = {}
    for name, sel in (("rays", wedged), ("trivial_rays", ~wedged)):
        _, V = ray_vectors(param, dd.X[order[sel]], m, np.full(int(sel.sum()), sel is wedged))
        if sel is wedged:                      # trivial rays: sum u_n = 1, no scale to undo
            with np.errstate(over="ignore"):
                V[:, :V.shape[1] // 2] = unscale_u(V[:, :V.shape[1] // 2], e)
            if not np.isfinite(V).all():
                raise SceneError(f"model: the stiffness is so small (~2^{e}) that the wedged rays' "
                                 "displacements u (sum r_n = 1) overflow a double; give K or the "
                                 "moduli in other units")
        out[name] = V
    return Rays(mu, out["rays"], out["trivial_rays"], zero[wedged], zero, wedged, dd.stats)


def cones(r: Rays) -> Cones:
    """The 2D cones stage at one mu: the maximal cones of cross-complementary rays
    (cones.maximal_cones), their rays as indices into the run's wedged and trivial lists."""
    from hpcwedge.rays.cones import maximal_cones  # networkx: imported only by the 2D cone stage (~0.15 s)
    zero, wedged = r.zero, r.wedged
    gap = ~zero[:, 0::3]
    load = ~(zero[:, 1::3] & zero[:, 2::3])
    widx = np.cumsum(wedged) - 1
    tidx = np.cumsum(~wedged) - 1
    items = []
    for cone in maximal_cones(gap, load, wedged):
        ids = np.asarray(cone.rays, dtype=int)
        items.append(Cone(rays=widx[ids[wedged[ids]]].tolist(), trivial_rays=tidx[ids[~wedged[ids]]].tolist(),
                          zero_u=np.flatnonzero(cone.zero_u).tolist(), zero_r=np.flatnonzero(cone.zero_r).tolist()))
    return Cones(items)


def patterns(ctx: Context) -> PatternSets:
    """The sign-patterns stage: the feasible patterns at every listed mu, branch and bound
    over subtrees as engine tasks (patterns.run_patterns; with a symmetry, over orbit
    representatives, expanded here). 2D: redone from the exact rays when the LP decisions
    are suspect and m small (numerics.recheck_patterns_2d). A warning for undecided ones."""
    scene, m, sym = ctx.scene, ctx.m, ctx.symmetry
    make_tree = partial(PatternTree, ctx.float_param, m, symmetry=sym, screens=scene.screens)
    pats = run_patterns(make_tree, scene.mu, engine=ctx.engine, budget=scene.task_budget)
    items = []
    for found, doubt in zip(pats.found, pats.undecided):
        found, doubt = expand_orbits(found, sym, m), set(expand_orbits(doubt, sym, m))
        items.append([Pattern(list(bits_to_nodes(s.contact, m)), undecided=s in doubt)
                      for s in sorted(found, key=lambda s: pattern_key(s.contact))])
    reps = None if sym is None else [len(f) for f in pats.found]
    c = pats.counters
    undecided = sum(len(u) for u in pats.undecided)
    if scene.dim == 2:
        near = solver_statuses(c).get("near_boundary", 0)
        exact_sets = recheck_patterns_2d(ctx.numerics, m, scene.mu, near, undecided, c.get("undecided", 0),
                                         ctx.exact_param, scene.exact)
        if exact_sets is not None:
            exact = [[Pattern(list(cs)) for cs in sorted(sets, key=lambda cs: pattern_key(to_bits(cs)))]
                     for sets in exact_sets]
            items = exact + items[len(exact):]
            undecided = 0
    tree = TreeStats.of(c, 2 ** m * len(scene.mu))        # partitions: what brute force would solve
    statuses = solver_statuses(c) if scene.dim == 3 else None
    if undecided:
        ctx.progress.note(f"warning: {undecided} pattern(s) undecided by every "
                          "solver (kept, flagged \"undecided\")")
    return PatternSets(items, undecided, tree, statuses, reps)


def _file_patterns(found: PatternSets, runs: list[Run], stats: SolveStats) -> None:
    """The patterns stage's record into the runs and the stats."""
    for run, items in zip(runs, found.items):
        run.patterns = items
    if found.representatives is not None:
        stats.symmetry.representatives = found.representatives
    stats.patterns_undecided, stats.bnb, stats.socp_statuses = found.undecided, found.tree, found.statuses


def orbit_key(zero_u, zero_r, symmetry: Symmetry | None) -> OrbitKey:
    """The key of a pair of node sets (zero_u, zero_r: node indices): their bit words (bit i:
    node i), canonical under `symmetry` (Symmetry.canonical; None: the pair's own words).
    Every pair of an orbit has the same key; mu^c is invariant, so one task serves a key."""
    bits = (to_bits(zero_u), to_bits(zero_r))
    return bits if symmetry is None else symmetry.canonical(*bits)


def mu_c_keys(run: Run, m: int, symmetry: Symmetry | None) -> list[tuple[OrbitKey, list, list]]:
    """(key, zero_u, zero_r) of every cone (its zero sets) then every pattern (zero_u: its
    contact nodes, zero_r: the others) of the run, in the run's order."""
    out = [(orbit_key(c.zero_u, c.zero_r, symmetry), c.zero_u, c.zero_r) for c in run.cones or []]
    for p in run.patterns or []:
        gap = sorted(set(range(m)).difference(p.contact))
        out.append((orbit_key(p.contact, gap, symmetry), p.contact, gap))
    return out


def _file_mu_c(values: MuCValues, runs: list[Run]) -> None:
    """Every run's cones and patterns with their mu^c (values.keyed: one list per run) and
    whether it is certified (None without a value)."""
    def valued(item, key):
        v = values.by_key[key]
        return replace(item, mu_c=v.mu_c, mu_c_polished=None if v.mu_c is None else bool(v.polished))
    for run, keys in zip(runs, values.keyed):
        n = len(run.cones or [])
        if run.cones is not None:
            run.cones = [valued(c, key) for c, key in zip(run.cones, keys[:n])]
        if run.patterns is not None:
            run.patterns = [valued(p, key) for p, key in zip(run.patterns, keys[n:])]


def mu_c(ctx: Context, runs: list[Run], every_run: bool) -> MuCValues:
    """The mu_c stage: mu^c of the cones / patterns of every run (every_run), or of the first
    run that lists any (for the global value), one task per orbit key (mu_c_keys) at the
    least mu that lists it (runs in increasing mu), through the engine (mu_critical.run_mu_c);
    2D, certified exactly (exact_mu_c) when the scene is exact or a mu's DD was redone so."""
    m, scene = ctx.m, ctx.scene
    listed = [r for r in runs if r.cones or r.patterns]
    wanted = runs if every_run else listed[:1]
    # the keys once per run (the master works alone here: workers wait for the tasks)
    entries = [mu_c_keys(run, m, ctx.symmetry) for run in wanted]
    tasks: dict = {}
    for run, entry in zip(wanted, entries):
        for key, zu, zr in entry:
            if key not in tasks:
                tasks[key] = (to_mask(zu, m), to_mask(zr, m), run.mu)
    solve = partial(mu_critical, ctx.float_param, m, mu_max=scene.mu_max, method=scene.mu_c_method,
                    tol=scene.mu_c_tol, scale=ctx.scale)
    by_key = dict(zip(tasks, run_mu_c(solve, list(tasks.values()), engine=ctx.engine)))
    if scene.dim == 2 and scene.mu_c_method == "accurate" and (scene.exact or ctx.numerics.exact_fallback):
        certify_2d(by_key, tasks, ctx.exact_param(), ctx.float_param, m, ctx.scale, ctx.numerics.notes)
    keyed = [[key for key, _, _ in entry] for entry in entries]
    first = next((ks for r, ks in zip(wanted, keyed) if r is listed[0]), None) if listed else None
    return MuCValues(by_key, keyed, first)


def global_mu_c(ctx: Context, values: MuCValues) -> GlobalMuC:
    """The global mu^c: the least of the first listed mu's cone / pattern values (any
    pattern feasible below that mu lies in one of its cones / patterns); when no mu lists
    any, or none of them has a value, the global search (global_mu_c.global_mu_critical: tree
    or MILP route, below mu_max). A least value above mu_max (a listed mu above it) is
    "none_up_to_mu_max", as the search gives when no listed mu is that high (SPEC §2: the
    global mu^c does not depend on the listed mu)."""
    scene = ctx.scene
    if values.first is not None:
        least = min((v for v in (values.by_key[key].mu_c for key in values.first) if v is not None), default=None)
        if least is not None:
            return GlobalMuC(least, "found") if least <= scene.mu_max else GlobalMuC(None, "none_up_to_mu_max")
    bnb = BnBStats()
    certify = exact_certifier(scene, ctx.m, ctx.float_param, ctx.exact_param, ctx.scale)
    mu_c, status = global_mu_critical(ctx.float_param, ctx.m, scene.mu_max, scene.mu_c_method, scene.mu_c_tol, bnb,
                                      ctx.symmetry, ctx.scale, certify=certify, engine=ctx.engine,
                                      budget=scene.task_budget)
    search = GlobalRouteStats(bnb.solves, bnb.skipped, bnb.undecided, bnb.nodes, bnb.extra.get("route", "tree"),
                              bnb.extra.get("milp_solves", 0), bnb.extra.get("milp_nodes", 0), bnb.pruned, bnb.lps,
                              bnb.extra.get("mu_c_unsettled", 0), bnb.extra.get("bound_solves", 0),
                              bnb.extra.get("bound_certified", 0))
    return GlobalMuC(mu_c, status, search, polished=bnb.extra.get("mu_c_polished", 0),
                     unpolished=bnb.extra.get("mu_c_unpolished", 0))
