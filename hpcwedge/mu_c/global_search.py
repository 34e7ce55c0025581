"""The global mu^c: the least mu at which any sign pattern has a solution (2D and 3D),
without enumerating the patterns: a bracket by the pattern tree with an incumbent, or
(2D, large m) by MILPs (milp.wedge_milp), then every pattern near the bracket settled by
its certified mu^c (mu_critical.py)."""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import partial

import numpy as np

from hpcwedge.contact.problem import Parametrization
from hpcwedge.mu_c.critical import MuC, add_counts, mu_critical, run_mu_c
from hpcwedge.mu_c.bracket import BRACKET_RTOL
from hpcwedge.mu_c.floor_pattern import bound_meets, certified_floor, floor_candidate, floor_start
from hpcwedge.parallel.cancel import Continuation, TaskCancelled, task_pausing, task_tick
from hpcwedge.parallel.engine import Engine, run_tasks
from hpcwedge.patterns.job import DEFAULT_BUDGET, run_patterns
from hpcwedge.patterns.symmetry import Symmetry
from hpcwedge.patterns.tree import STAT_KEYS, BnBStats, PatternTree, Subtree, solver_statuses
from hpcwedge.solvers.feasibility import DEFAULT_OPTIONS, decide
from hpcwedge.solvers.lp import X_SPACE_TOL, image_point
from hpcwedge.solvers.milp import WedgeMilp, wedge_milp
from hpcwedge.solvers.rows import Status, count, pattern_rows, problem_dim

#: 2D MILP route (global_bracket_milp): the relative steps below the best mu^c found at
#: which the MILP is asked again; the last is HiGHS's MIP feasibility tolerance
MILP_STEPS = (1e-2, 1e-4, 1e-6)
#: tree route: the next bound is best (1 - TREE_STEP). Every pattern between it and best is
#: settled by the final enumeration at best (1 + 1e-9), so the step sets the work, not the
#: answer. The last dive's problems lie a step from their boundary: at 1e-7 within
#: Clarabel's tolerance on plug3d 4 x 6 at 10 deg (6 undecided, 16 s; 1e-5: none, 6.7 s),
#: at 1e-5 at a 0.01 deg taper (plug3d 3 x 6: 70 s; 1e-2: 7 s) and at 1e-3 at 0.001 deg
#: (87 s; 1e-2: 4.5 s). Fewer, longer steps also mean fewer dives and mu^c computations:
#: random 3D bodies, m = 7, 2,934 tree nodes at 1e-5, 2,725 at 1e-2
TREE_STEP = 1e-2
#: tree route: a dive below an incumbent gets STEP_DIVE_FACTOR * max(n, m) + 1 tree nodes, n
#: the longest dive that found a leaf so far; when they run out the bracket ends and the
#: settling tree (complete at best (1 + 1e-9)) takes over, so the budget sets the work, not the
#: answer. The last dive finds nothing, and unbudgeted it explored nearly the settling tree's
#: nodes again (curved neck 4 x 8: 2,811 nodes beside the settling tree's 3,393; 6 x 8:
#: 24,077); a fixed 4 m + 1 cut dives that would have found a leaf (plug3d 3 x 5 at a 0 deg
#: taper: 235, 224, 239 and 616 nodes, m = 15) and left the settling tree many more patterns
STEP_DIVE_FACTOR = 4
#: tree route: the 3D trees' branching rule (PatternTree's branch): on the node of largest relaxed
#: r_n, whose gap child fails first near mu^c (the settling tree of curved neck 4 x 8: 1,945
#: nodes instead of 3,393 by the enumeration's rule)
TREE_BRANCH = "reaction"
#: 2D MILP route: the tree's dive before each MILP gets DIVE_NODES * m + 1 tree nodes
DIVE_NODES = 2
#: 2D MILP route: a pattern is first asked at floor (1 + FLOOR_STEP), floor the certified
#: lower bound (_PatternValues; bracket_2d's mu_try): half the 2D bracket's tolerance, so that
#: a yes brackets its mu^c (plug2d m = 640: no Dinkelbach step, no bisection)
FLOOR_STEP = 0.5 * BRACKET_RTOL
#: route "auto" takes the 2D MILP route from this many contact nodes on; below it the tree,
#: which sees every pattern within 1e-9 of the answer (the MILP route can miss one within
#: ~1e-6 below it, HiGHS's tolerance) and finishes in seconds there (m = 20: ~6 s)
MILP_FROM_M = 25


def global_mu_critical(param: Parametrization, m: int, mu_max: float, method: str = "accurate",
                       tol: float = 1e-6, stats: BnBStats | None = None,
                       symmetry: Symmetry | None = None,
                       scale: float | None = None, route: str = "auto",
                       certify=None, engine: Engine | None = None,
                       budget: int = DEFAULT_BUDGET, bound: bool = True) -> tuple[float | None, str]:
    """Least mu with any solution (2D and 3D alike; with a symmetry, over orbit
    representatives). scale: passed to mu_critical (2D balanced coordinates).

    Two stages. The bracket: an upper value `best` (the certified mu^c of a pattern) with no
    pattern feasible below best (1 - TREE_STEP) (tree route: or a dive below best spent its
    budget, STEP_DIVE_FACTOR), found by
      route "tree": branch and bound over patterns with an incumbent (LPs in 2D, SOCPs in 3D;
        3D trees branch by TREE_BRANCH; 3D with the bound: floor_pattern's pattern first);
      route "milp" (2D; 3D runs the tree): `global_bracket_milp`, per step a short dive of
        the tree and, where it does not settle the step, one MILP (HiGHS); each pattern
        it returns checked by our LP and its mu^c computed by our certified route; any doubt
        (an undecided MILP, a pattern our LP rejects at every mu, no wedge at all) falls back
        to the tree;
      route "auto": "milp" in 2D from MILP_FROM_M contact nodes on, else "tree".
    Where the certified lower bound meets best (`bound_meets`: no wedge at best (1 - 1e-9), by
    an exactly checked certificate; free bodies whose rigid part sets mu^c, e.g. plugs) best
    is the answer, and neither route searches further (bound=False: the bound is not asked;
    the answer is the same). Otherwise the tree route settles (`settled`): every pattern (one
    per orbit) feasible at best (1 + 1e-9) gets its certified mu^c; the least is the answer.
    The MILP route skips that enumeration (exponential in m): its answer is the certified mu^c of
    the last pattern it found, the least to the MILP's tolerance (a pattern whose mu^c lies
    within ~1e-6 relative below it can go unseen, unless the bound met it: then it is the
    least by a certificate). stats.extra["route"] says which route ran; its MILP counts are
    stats.extra["milp_solves"] and ["milp_nodes"]; the bound's stats.extra["bound_solves"]
    (conic programs), ["bound_certified"] (1 when it ended the search) and ["bound"] (the
    certified value); stats.extra["mu_c_unsettled"] the settled patterns whose mu^c no solve
    decided (the answer is certified when it is 0 and every value is polished). Before the
    settling, engine.tell says best, an upper bound (`show` of a checkpoint: mu_c.saved).

    The stages run as three jobs of `engine` (in-process by default; the master under
    mpirun): "global_bracket" (one task: the bracket), "global_patterns" (the settling tree
    as budgeted subtree tasks of `budget` nodes, shared by the workers) and "global_mu_c"
    (one mu^c task per pattern it found). A stop keeps the finished jobs and the tree's
    open subtrees in the checkpoint; the answer and every count are the same for every
    budget, rank count or resume.

    certify(zero_u, zero_r, mu_c): the least pattern's value certified another way (2D: in
    exact arithmetic, exact_mu_c), or None to keep it.

    Returns (mu_c, status): status "found", "none_at_any_mu" (the relaxation with r_t free has
    no solution) or "none_up_to_mu_max"."""
    if route not in ("auto", "tree", "milp"):
        raise ValueError(f"global mu^c route: 'auto', 'tree' or 'milp', got {route!r}")
    stats = stats if stats is not None else BnBStats()
    engine = engine or Engine()
    search = GlobalSearch(param, m, mu_max, method, tol, symmetry, scale, route, bound)
    got = run_tasks(bracket_task, search, [0], engine=engine, kind="global_bracket")[0]
    best = None if math.isnan(got["best"]) else float(got["best"])
    status = BRACKET_STATUS[int(got["status"])]
    _absorb_json(stats, got["stats"])
    pattern_of: dict = {}           # each value computed -> its pattern (for certify)
    if best is not None:
        pattern_of[best] = (np.asarray(got["zero_u"], dtype=bool), np.asarray(got["zero_r"], dtype=bool))
    if status == "settle" and bound and bound_meets(param, m, best, stats):
        status = "found"
    if status == "settle":
        engine.tell(f"global mu^c: at most {best:.12g} (the certified mu^c of a pattern); a tree "
                    f"of the patterns feasible at that mu looks for a lower one")
        best = settled(search, best, stats, pattern_of, engine, budget)
        status = "found"
    if certify is not None and best in pattern_of:
        exact = certify(*pattern_of[best], best)
        if exact is not None:
            best = exact
    return best, status


def settled(search: GlobalSearch, best: float, stats: BnBStats, pattern_of: dict, engine: Engine,
            budget: int) -> float:
    """The tree route's settling (global_mu_critical's doc): every pattern (one per orbit:
    mu^c is invariant under the symmetry) feasible at best (1 + 1e-9) gets its certified mu^c
    (jobs "global_patterns", "global_mu_c"); the least of them and best. Counted into stats;
    pattern_of[value] = the pattern of every value computed."""
    param, m = search.param, search.m
    top = best * (1 + 1e-9)
    make_tree = partial(PatternTree, param, m, symmetry=search.symmetry, options=DEFAULT_OPTIONS, branch=TREE_BRANCH)
    pats = run_patterns(make_tree, [top], engine=engine, budget=budget, name="global_patterns")
    c = pats.counters
    for k in STAT_KEYS:
        setattr(stats, k, getattr(stats, k) + c.get(k, 0))
    for k, v in solver_statuses(c).items():
        stats.statuses[k] = stats.statuses.get(k, 0) + v
    items = [(*s.masks(m), top) for s in pats.found[0]]
    for (zu, zr, _), r in zip(items, run_mu_c(search.solve, items, engine=engine, name="global_mu_c")):
        _absorb(stats, r)
        if r.mu_c is None and r.undecided:
            # feasible at top (or left undecided by the tree) and no value: its mu^c may
            # lie below best
            stats.extra["mu_c_unsettled"] = stats.extra.get("mu_c_unsettled", 0) + 1
        if r.mu_c is not None:
            pattern_of.setdefault(r.mu_c, (zu, zr))
            best = min(best, r.mu_c)
    return best


#: the bracket task's outcome: "settle" (tree route: best is an upper value, the settling
#: tree follows), "found" (MILP route: best is the answer), or no wedge
BRACKET_STATUS = ("settle", "found", "none_at_any_mu", "none_up_to_mu_max")


@dataclass(frozen=True)
class GlobalSearch:
    """The global search's problem and settings (global_mu_critical's arguments): the
    context of its "global_bracket" task, sent once to a worker."""

    param: Parametrization
    m: int
    mu_max: float
    method: str
    tol: float
    symmetry: Symmetry | None
    scale: float | None
    route: str
    bound: bool = True

    @property
    def solve(self):
        """solve(zero_u, zero_r, mu_hi=...) -> MuC: the certified mu^c of one pattern."""
        return partial(mu_critical, self.param, self.m, mu_max=self.mu_max, method=self.method, tol=self.tol,
                       scale=self.scale)

    def bracket(self, stats: BnBStats, pattern_of: dict, resume: dict | None = None):
        """(best, BRACKET_STATUS entry): the bracket stage (global_mu_critical's doc);
        pattern_of[value] = the pattern of every value computed. The tree route's steps may
        pause (cancel.task_pausing: the checkpoint is due, or the engine is stopping): it then
        returns a Continuation whose payload (`_step_state`) is `resume` of the call that
        goes on, with the counts as of that step (a step cut short by a stop is dropped and
        run again), so the answer and every count are the same wherever it paused."""
        if resume is not None:
            _absorb_json(stats, resume["stats"])
            best = resume["best"]
            if best is not None:
                pattern_of[best] = (np.array(resume["zero_u"], dtype=bool), np.array(resume["zero_r"], dtype=bool))
            if resume.get("floor"):
                return self._from_floor(stats, pattern_of)
            if resume["bound"] is None:            # the steps found none up to mu_max
                return self._at_any_mu(stats, pattern_of)
            return self._tree_steps(stats, pattern_of, best, resume["bound"], resume.get("longest", 0))
        param, m, mu_max = self.param, self.m, self.mu_max
        if (self.route == "milp" or (self.route == "auto" and m >= MILP_FROM_M)) and problem_dim(param, m) == 2:
            best = global_bracket_milp(param, m, mu_max, partial(_recorded, self.solve, pattern_of), stats,
                                       self.scale, bound=self.bound)
            if best is not None:
                return best, "found"
        stats.extra["route"] = "tree"
        return self._from_floor(stats, pattern_of)

    def _from_floor(self, stats: BnBStats, pattern_of: dict):
        """The tree route's steps from the certified mu^c of floor_pattern's pattern (3D with
        the bound: floor_start; plug3d m = 128 skips its 3.8 s dive to a first leaf, the bound
        meets that value: "found"); a Continuation marked "floor" (this step again, from the
        counts before it) when the engine stops it."""
        best, state = None, {**_step_state(stats, pattern_of, None, self.mu_max, self.m), "floor": True}
        if self.bound and problem_dim(self.param, self.m) == 3:
            try:
                found = floor_start(self.param, self.m, self.mu_max, stats)
                r = None if found is None else _recorded(self.solve, pattern_of, found.zero_u, found.zero_r)
            except TaskCancelled:
                return Continuation(state)
            if r is not None:
                _absorb(stats, r)
                best = r.mu_c
            if best is not None and bound_meets(self.param, self.m, best, stats):
                return best, "found"
        return self._tree_steps(stats, pattern_of, best, self.mu_max if best is None else best * (1 - TREE_STEP))

    def _at_any_mu(self, stats: BnBStats, pattern_of: dict):
        """The outcome when no pattern is feasible up to mu_max: "none_at_any_mu" when the tree
        with r_t free has no leaf either, else "none_up_to_mu_max" (asked only then: a wedge
        at mu_max is one at every larger mu); a Continuation when the engine stops its dive."""
        try:
            leaf = self._first_leaf(stats, np.inf, friction=False)
        except TaskCancelled:
            return Continuation(_step_state(stats, pattern_of, None, None, self.m))
        return None, "none_at_any_mu" if leaf is None else "none_up_to_mu_max"

    def _first_leaf(self, stats: BnBStats, mu: float, friction: bool = True, budget: int | None = None):
        """The masks of the first feasible leaf of the tree at mu (None: none; "spent": none
        in `budget` tree nodes, None: no budget); TaskCancelled when the engine stops the dive."""
        # Clarabel's own steps: every tree solve here lies near mu^c (socp module doc)
        tree = PatternTree(self.param, self.m, mu, friction, symmetry=self.symmetry, options=DEFAULT_OPTIONS,
                           branch=TREE_BRANCH)
        out = tree.explore(Subtree(0), budget=budget, first_only=True)
        stats.add(out.stats)
        if out.stopped:                   # the engine is stopping: no answer from this dive
            raise TaskCancelled()
        if out.found:
            return out.found[0].masks(m=self.m)
        return "spent" if out.open else None

    def _tree_steps(self, stats: BnBStats, pattern_of: dict, best: float | None, bound: float, longest: int = 0):
        """The tree route's steps from (best, bound): a dive at bound (below an incumbent:
        STEP_DIVE_FACTOR * max(longest, m) + 1 tree nodes at most, `longest` the most nodes a
        dive that found a leaf took), the certified mu^c of its leaf, the next bound
        best (1 - TREE_STEP); a Continuation when pausing (bracket)."""
        solve = partial(_recorded, self.solve, pattern_of)
        while True:
            state = _step_state(stats, pattern_of, best, bound, self.m, longest)
            if task_pausing():
                return Continuation(state)
            budget = None if best is None else STEP_DIVE_FACTOR * max(longest, self.m) + 1
            try:
                before = stats.nodes
                leaf = self._first_leaf(stats, bound, budget=budget)
                if isinstance(leaf, str):
                    count(stats.statuses, "step_dive_spent")
                    break
                longest = max(longest, stats.nodes - before) if leaf is not None else longest
                r = None if leaf is None else solve(*leaf, mu_hi=bound)
            except TaskCancelled:
                return Continuation(state)
            if r is None:
                break
            _absorb(stats, r)
            if r.mu_c is None or (best is not None and r.mu_c >= best):
                break
            best, bound = r.mu_c, r.mu_c * (1 - TREE_STEP)
        return self._at_any_mu(stats, pattern_of) if best is None else (best, "settle")


def _step_state(stats: BnBStats, pattern_of: dict, best: float | None, bound: float | None, m: int,
                longest: int = 0) -> dict:
    """The bracket's state before a step (JSON data, a Continuation's payload): best, its
    pattern (zero_u, zero_r lists; all False without one), bound (None: no pattern up to
    mu_max, the dive with r_t free is next), longest (_tree_steps') and the counts so far."""
    none = [False] * m
    zu, zr = pattern_of.get(best, (none, none))
    return {"best": best, "bound": bound, "longest": longest, "zero_u": [bool(v) for v in zu],
            "zero_r": [bool(v) for v in zr], "stats": _counts_json(stats)}


def _counts_json(stats: BnBStats) -> str:
    """The counts of stats as JSON (read back by _absorb_json)."""
    counts = {**{k: getattr(stats, k) for k in ("solves", "skipped", "pruned", "undecided", "nodes", "lps")},
              "extra": stats.extra, "statuses": stats.statuses}
    return json.dumps(counts, sort_keys=True)


def bracket_task(search: GlobalSearch, payload):
    """Task "global_bracket": the bracket of `search` (GlobalSearch.bracket) -> best (NaN:
    none), status (index into BRACKET_STATUS), the pattern of best (zero_u, zero_r masks;
    all False without one) and the search's counts (stats: JSON of a BnBStats); or a
    Continuation when it pauses. payload: anything but a dict to start, a Continuation's
    payload to go on."""
    stats, pattern_of = BnBStats(), {}
    out = search.bracket(stats, pattern_of, payload if isinstance(payload, dict) else None)
    if isinstance(out, Continuation):
        return out
    best, status = out
    none = np.zeros(search.m, dtype=bool)
    zu, zr = pattern_of.get(best, (none, none))
    return {"best": math.nan if best is None else float(best), "status": BRACKET_STATUS.index(status),
            "zero_u": np.asarray(zu, dtype=bool), "zero_r": np.asarray(zr, dtype=bool),
            "stats": _counts_json(stats).encode()}


def _recorded(solve, pattern_of: dict, zero_u, zero_r, **kw):
    """solve(zero_u, zero_r, **kw), its value's pattern kept in pattern_of[value]."""
    r = solve(zero_u, zero_r, **kw)
    if r.mu_c is not None:
        pattern_of.setdefault(r.mu_c, (zero_u, zero_r))
    return r


def _absorb_json(stats: BnBStats, text) -> None:
    """Add the counts of bracket_task's JSON `text` (bytes or str) to stats."""
    counts = json.loads(text.decode() if isinstance(text, bytes) else text)
    for k in ("solves", "skipped", "pruned", "undecided", "nodes", "lps"):
        setattr(stats, k, getattr(stats, k) + int(counts[k]))
    for k, v in counts["statuses"].items():
        stats.statuses[k] = stats.statuses.get(k, 0) + v
    for k, v in counts["extra"].items():
        stats.extra[k] = v if isinstance(v, str) else stats.extra.get(k, 0) + v


def global_bracket_milp(param: Parametrization, m: int, mu_max: float, solve, stats: BnBStats,
                        scale: float | None = None, dive: int = DIVE_NODES, bound: bool = True) -> float | None:
    """2D global mu^c by MILPs (milp.wedge_milp, valid big-M): the least certified
    pattern mu^c `best` found; None when in doubt (the caller runs the tree instead).
    solve(zero_u, zero_r, mu_hi): the certified mu^c of one pattern (mu_critical).

    The MILP decides feasibility only to HiGHS's tolerance (a pattern infeasible by ~1e-6
    relative in mu can come back feasible, and then hide one feasible with margin), so
    each step asks at best (1 - delta) with delta = MILP_STEPS in turn: a pattern returned
    of lower certified mu^c replaces best (same delta again); none, or one no better
    (blurred), moves to the next delta. The first pattern is the MILP's at mu = inf (r_t
    free), whose mu^c, when finite, saves the MILP at mu_max (the slowest). Before each
    MILP the tree dives for dive * m + 1 nodes (0: no dive), see `_wedge_at`. The steps
    end where the certified lower bound meets best (`bound_meets`; bound=False: not asked):
    then no pattern lies below best, by a certificate, at 1e-9. A free body's certified lower
    bound (lower_bound.rigid_bound, to 1e-10; bound=False: not asked) is each pattern's
    floor (`_PatternValues`): a pattern feasible just above it has its mu^c bracketed at once;
    the first asked is floor_pattern's (pivots on the bound's certificate), which ends the
    search where it meets the bound (block2d m = 320: no MILP)."""
    s = 1.0 if scale is None else float(scale)
    stats.extra["route"] = "milp"
    wedge = partial(_wedge_at, param, m, stats, s, dive)
    floor = certified_floor(param, m, mu_max, stats) if bound else None
    certified = _PatternValues(param, m, solve, stats, floor)
    met = partial(bound_meets, param, m, stats=stats) if bound else None
    found = floor_candidate(param, m, floor, stats) if floor and floor < mu_max else None
    best = None if found is None else \
        certified(WedgeMilp(Status.FEASIBLE, math.nan, 0, found.zero_u, found.zero_r), np.inf, found.x)
    if best is not None and met(best):
        return best
    for mu in (np.inf, mu_max):
        ans = wedge(mu)
        if ans.status != Status.FEASIBLE:
            return None                   # no wedge, or undecided: the tree decides
        value = certified(ans, mu)
        if value is not None:
            best = value if best is None else min(best, value)
            break
    if best is None:
        return None                       # the MILP's pattern at mu_max is no wedge: doubt
    return _lowered(best, wedge, certified, met)


def _lowered(best: float, wedge, certified: _PatternValues, met=None) -> float | None:
    """global_bracket_milp's steps down from `best`: at best (1 - delta), delta = MILP_STEPS
    in turn, wedge(mu) (`_wedge_at`) asked again while it returns a pattern of lower
    certified mu^c; none once met(best) (the certified lower bound meets it: `bound_meets`).
    A step below certified.floor is no wedge without a solve (block2d m = 320: a MILP > 300 s).
    The last best, or None on doubt (an undecided answer, a pattern with no value)."""
    if met is not None and met(best):
        return best
    for delta in MILP_STEPS:
        while True:
            task_tick()
            bound = best * (1 - delta)
            if certified.floor is not None and bound < certified.floor:
                count(certified.stats.statuses, "milp_step_below_floor")
                break                     # no wedge below the floor, by its certificate
            ans = wedge(bound)
            if ans.status == Status.UNDECIDED:
                return None
            if ans.status == Status.INFEASIBLE:
                break
            mu = certified(ans, bound)
            if mu is None:
                return None
            if mu >= best:
                break
            best = mu
            if met is not None and met(best):
                return best
    return best


def _wedge_at(param: Parametrization, m: int, stats: BnBStats, scale: float, dive: int, mu: float) -> WedgeMilp:
    """Is there a wedged configuration at mu (inf: r_t free)? A short dive of the tree first
    (dive * m + 1 nodes; 0: none): it settles most steps with a few LPs (a relaxed vertex
    that is complementary descends without a solve; an infeasible root proves none; its LPs
    chained, lp.TreeLp's chain); the MILP (milp.wedge_milp, `scale`) only where the dive's
    budget runs out. Counted into stats.
    At mu = inf the dive's first leaf, contact before gap, is the all-contact pattern whenever
    that is feasible: it is tried first in the image coordinates (`_all_contact`), no tree."""
    if dive and np.isinf(mu) and _all_contact(param, m):
        count(stats.statuses, "dive_all_contact")
        return WedgeMilp(Status.FEASIBLE, math.nan, 0, np.ones(m, bool), np.zeros(m, bool))
    if dive:
        tree = PatternTree(param, m, 0.0 if np.isinf(mu) else mu, friction=not np.isinf(mu), lp_chain=True)
        out = tree.explore(Subtree(0), budget=dive * m + 1, first_only=True)
        stats.add(out.stats)
        if out.found and not out.undecided:
            count(stats.statuses, "dive_feasible")
            zu, zr = out.found[0].masks(m)
            return WedgeMilp(Status.FEASIBLE, math.nan, 0, zu, zr)
        if not (out.found or out.open or out.stopped or out.stats.undecided):
            count(stats.statuses, "dive_infeasible")
            return WedgeMilp(Status.INFEASIBLE, 0.0, 0)
    ans = wedge_milp(param, m, mu, scale)
    stats.extra["milp_solves"] = stats.extra.get("milp_solves", 0) + 1
    stats.extra["milp_nodes"] = stats.extra.get("milp_nodes", 0) + ans.nodes
    count(stats.statuses, "milp_" + ans.status)
    return ans


def _all_contact(param: Parametrization, m: int) -> bool:
    """Is the all-contact pattern feasible without friction (u_n = 0, r_n >= 0, sum r_n = 1),
    by a point of lp.image_point meeting its unit rows and sum r_n = 1 to X_SPACE_TOL? False:
    not shown (m = 640: a dense 1280 x 1280 LP in x, ~130 s cold, against one SVD here). No
    share test (lp_feasible's NORM_SHARE_MIN; the least-norm point of plug2d m = 160 has 7e-3):
    the pattern is only a candidate, whose mu^c mu_critical decides (None: the next step)."""
    rows = pattern_rows(param, m, np.ones(m, bool), np.zeros(m, bool), friction=False)
    x = image_point(param.U[:m], param.R[:m])
    if x is None:
        return False
    v = rows.a0 @ x / np.maximum(np.linalg.norm(rows.a0, axis=1), 1e-300)
    worst = max(np.abs(v[rows.eq]).max(initial=0.0), (-v[~rows.eq]).max(initial=0.0), abs(rows.norm @ x - 1.0))
    return bool(worst <= X_SPACE_TOL)


class _PatternValues:
    """The certified mu^c of the patterns the MILP route meets (`solve`: mu_critical), each
    computed once and counted into stats. Called with a FEASIBLE WedgeMilp found at mu =
    bound: its pattern's value, the computation started below bound when our LP finds the
    pattern feasible there. A pattern met again (blurred) gives its known value. With a
    `floor` (a mu below which no wedge exists, by a certificate) the computation asks
    floor (1 + FLOOR_STEP) first (mu_critical's mu_try): feasible there, the bracket
    [floor, floor (1 + FLOOR_STEP)] is within the 2D bracket's tolerance (no Dinkelbach step,
    no bisection; a free plug's all-contact pattern, whose mu^c the rigid bound meets), checking
    `witness` there first when given (floor_pattern's wedge: no LP)."""

    def __init__(self, param: Parametrization, m: int, solve, stats: BnBStats, floor: float | None = None):
        self.param, self.m, self.solve, self.stats, self.floor = param, m, solve, stats, floor
        self.seen: dict = {}

    def __call__(self, ans: WedgeMilp, bound: float, witness: np.ndarray | None = None) -> float | None:
        key = (ans.zero_u.tobytes(), ans.zero_r.tobytes())
        if key in self.seen:
            count(self.stats.statuses, "milp_pattern_again")
            return self.seen[key]
        rows = pattern_rows(self.param, self.m, ans.zero_u, ans.zero_r)
        self.stats.lps += bool(np.isfinite(bound))
        ok = np.isfinite(bound) and decide(rows, bound, counts=self.stats.statuses).status == Status.FEASIBLE
        floor = self.floor
        guess = None if floor is None or floor * (1 + FLOOR_STEP) >= bound else floor * (1 + FLOOR_STEP)
        r = self.solve(ans.zero_u, ans.zero_r, mu_hi=bound if ok else None, mu_floor=floor, mu_try=guess,
                       x_try=None if guess is None else witness)
        _absorb(self.stats, r)
        self.seen[key] = r.mu_c
        return r.mu_c


def _absorb(stats: BnBStats, r: MuC) -> None:
    """Count a mu^c computation (mu_critical.MuC) into the search statistics (its pyramid
    LPs into stats.lps: the search's LPs are its trees' and its mu^c computations')."""
    add_counts(stats, r)
    stats.lps += r.statuses.get("lp_calls", 0)
    key = "mu_c_polished" if r.polished else "mu_c_unpolished"
    stats.extra[key] = stats.extra.get(key, 0) + 1
