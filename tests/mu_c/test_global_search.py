"""The 2D global mu^c by the MILP route (global_mu_c.global_bracket_milp) against analytic
values, the tree route and the public scenes' expected answers (the MILP itself, milp.py:
test_milp.py)."""
import json
import math
import os
import tomllib
from functools import partial

import numpy as np
import pytest
from instances import global_run, plug3d_param, random_problem

from hpcwedge.contact.problem import parametrize
from hpcwedge.mu_c.critical import mu_critical
from hpcwedge.mu_c.global_search import MILP_FROM_M, global_bracket_milp, global_mu_critical
from hpcwedge.patterns.tree import BnBStats
from hpcwedge.run.pipeline import run_scene
from hpcwedge.scene.parse import parse_scene

SCENES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "..", "shared", "scenes")


def route_for(m: int) -> str:
    """The route "auto" takes for a 2D scene with m contact nodes."""
    return "milp" if m >= MILP_FROM_M else "tree"


def by_milp(res) -> float | None:
    """The global mu^c of a run's problem by the MILP route, asked for explicitly."""
    p, st = parametrize(res.problem), BnBStats()
    mu, _ = global_mu_critical(p, res.m, 100.0, stats=st, route="milp")
    assert mu is None or st.extra["route"] == "milp"
    return mu


@pytest.mark.parametrize("rows", [2, 10, 20])
def test_plug2d_global_mu_c_is_tan_taper_by_either_route(rows):
    """plug2d: global mu^c = tan(taper) for any rows, to 1e-9, by the route "auto" takes
    (the MILP route from MILP_FROM_M nodes) and by the MILP route asked for (m = 20: a single
    MILP step at 1e-7 below the incumbent returned a blurred pattern and stopped at 0.2975).
    The certified lower bound (lower_bound.py) meets the incumbent on the free plug: neither
    route settles."""
    res = global_run({"kind": "plug2d", "rows": rows, "taper_deg": 10.0})
    want = math.tan(math.radians(10.0))
    assert res.mu_c_status == "found"
    assert abs(res.mu_c - want) <= 1e-9 * want
    bnb = res.stats["bnb"]
    assert bnb["route"] == route_for(2 * rows)
    assert bnb["bound_certified"] == 1 and bnb["bound_solves"] >= 1
    # the engine's jobs: the bound ends the search, no settling tree
    assert [j for j in res.stats["parallel"]["jobs"] if j.startswith("global")] == ["global_bracket"]
    if rows < 20:
        assert abs(by_milp(res) - want) <= 1e-9 * want


@pytest.mark.parametrize("rows", [2, 10])
def test_plug2d_global_mu_c_by_milps_alone(rows):
    """No dive: every step is a MILP (HiGHS), each pattern's mu^c certified by ours. Without
    the certified bound the steps go down to 1e-6 below the answer (>= 4 MILPs); with it they
    end as soon as it meets the incumbent, same answer: the floor pattern's (all contact)
    meets it before any MILP."""
    res = global_run({"kind": "plug2d", "rows": rows, "taper_deg": 10.0}, mu_c="none")
    p, m = parametrize(res.problem), res.m
    want = math.tan(math.radians(10.0))
    solve = partial(mu_critical, p, m, mu_max=100.0)
    st, st_bound = BnBStats(), BnBStats()
    best = global_bracket_milp(p, m, 100.0, solve, st, dive=0, bound=False)
    assert abs(best - want) <= 1e-9 * want
    assert st.extra["milp_solves"] >= 4 and st.nodes == 0 and "bound_solves" not in st.extra
    assert abs(global_bracket_milp(p, m, 100.0, solve, st_bound, dive=0) - best) <= 1e-12 * want
    assert st_bound.extra["bound_certified"] == 1 and st_bound.extra["bound_solves"] >= 1
    assert st_bound.extra.get("milp_solves", 0) == 0 < st.extra["milp_solves"]
    assert st_bound.statuses["floor_pattern"] == 1


@pytest.mark.parametrize("theta,k,eps", [(20.0, 1.0, 0.0), (20.0, 1.0, 0.1), (35.0, 2.0, 0.3)])
def test_vgroove_global_mu_c_analytic(theta, k, eps):
    th = math.radians(theta)
    want = math.tan(th) + eps / (k * math.sin(2 * th))
    res = global_run({"kind": "vgroove_bar", "theta_deg": theta, "EA": 2 * k, "eps": eps})
    assert res.mu_c_status == "found" and res.stats["bnb"]["route"] == "tree"
    assert abs(res.mu_c - want) <= 1e-9 * want
    assert abs(by_milp(res) - want) <= 1e-9 * want


@pytest.mark.parametrize("seed", range(6))
def test_milp_route_equals_tree_route_on_random_bodies(seed):
    prob = random_problem(np.random.default_rng(seed), 5, free=seed % 2 == 0)
    p = parametrize(prob)
    s_tree, s_milp = BnBStats(), BnBStats()
    tree = global_mu_critical(p, prob.m, 50.0, stats=s_tree, route="tree")
    milp = global_mu_critical(p, prob.m, 50.0, stats=s_milp, route="milp")
    assert tree[1] == milp[1]
    if tree[0] is None:
        assert milp[0] is None and s_milp.extra["route"] == "tree"      # fell back: "none" is the tree's
    else:
        assert abs(tree[0] - milp[0]) <= 1e-9 * tree[0]
        assert s_milp.extra["route"] == "milp" and s_tree.extra["route"] == "tree"
        alone = global_bracket_milp(p, prob.m, 50.0, partial(mu_critical, p, prob.m, mu_max=50.0), BnBStats(),
                                    dive=0)
        assert alone is not None and abs(alone - tree[0]) <= 1e-9 * tree[0]


@pytest.mark.parametrize("seed,m", [(2, 6), (14, 5)])
def test_milp_steps_below_the_rigid_floor_are_skipped_and_the_answer_stands(seed, m):
    """Free random bodies whose global mu^c lies less than 1e-2 above the certified rigid
    floor: the MILP route's step at best (1 - 1e-2) is below the floor and is not solved
    (counted milp_step_below_floor), and its answer is the tree route's."""
    prob = random_problem(np.random.default_rng(seed), m, free=True)
    p = parametrize(prob)
    s_tree, s_milp = BnBStats(), BnBStats()
    tree, _ = global_mu_critical(p, prob.m, 50.0, stats=s_tree, route="tree")
    milp, _ = global_mu_critical(p, prob.m, 50.0, stats=s_milp, route="milp")
    assert s_milp.extra["route"] == "milp" and s_milp.statuses["milp_step_below_floor"] >= 1
    assert abs(milp - tree) <= 1e-9 * tree


@pytest.mark.skipif(not os.path.isdir(SCENES), reason="../shared/scenes not beside the checkout")
@pytest.mark.parametrize("name", ["vgroove_free.toml", "vgroove_springs.toml", "node2d.toml",
                                  "uncoupled2d.toml", "plug2d_r2.toml", "plug2d_r3.toml"])
def test_public_scenes_global_mu_c(name):
    """As `make check`: the expected global mu^c (null: none at any mu) to 1e-9."""
    want = json.load(open(os.path.join(SCENES, "expected.json")))[name]["mu_c"]
    with open(os.path.join(SCENES, name), "rb") as f:
        data = tomllib.load(f)
    data["compute"] = {"enumerate": False, "mu_c": "global"}
    res = run_scene(parse_scene(data, base_dir=SCENES))
    if want is None:
        assert res.mu_c is None and res.mu_c_status == "none_at_any_mu"
        assert res.stats["bnb"]["route"] == "tree"            # a "none" is never the MILP's word
    else:
        assert abs(res.mu_c - want) <= 1e-9 * want
        assert abs(by_milp(res) - want) <= 1e-9 * want




def test_3d_tree_route_decides_every_problem_on_a_body_without_symmetry():
    """plug3d 2 x 6 (m = 12) without its symmetry: the tree route's global mu^c is tan 10 deg
    with no undecided problem and at most 1 % of the SOCPs failing verification (the bound
    best (1 - TREE_STEP) and the first attempt's 1e-10 tolerances; with 1e-7 and Clarabel's
    default tolerances: 1 undecided and 88 of 319 failing)."""
    param, m = plug3d_param(2, 6)
    st = BnBStats()
    mu, status = global_mu_critical(param, m, 100.0, stats=st)
    assert status == "found" and abs(mu - math.tan(math.radians(10))) <= 1e-12
    assert st.undecided == 0 and st.statuses.get("verify_failed", 0) <= 0.01 * st.solves, st.statuses


def test_exact_scene_with_no_listed_mu_above_mu_c_runs_the_float_search():
    """compute.exact = true, a free truss (m = 6) whose listed mu both lie below mu^c: the global
    search runs on the float parametrisation, as a float scene's does, and gives its value,
    certified in exact arithmetic (exact_mu_c: within 1e-12 of the float one) (before: on the
    exact one's rational bases, it did not end within 280 s; pytest's timeout guards against
    that)."""
    from hpcwedge.run.pipeline import run_scene
    from hpcwedge.scene.parse import parse_scene
    data = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data")
    with open(os.path.join(data, "truss2d_seed4_exact.toml"), "rb") as f:
        d = tomllib.load(f)
    exact = run_scene(parse_scene(d, base_dir=data))
    d["compute"]["exact"] = False
    flt = run_scene(parse_scene(d, base_dir=data))
    assert abs(exact.mu_c - flt.mu_c) <= 1e-12 * flt.mu_c and exact.mu_c_status == "found"
    assert exact.mu_c > max(d["friction"]["mu"])


@pytest.mark.parametrize("body", ["plug2d", "plug3d"])
def test_global_search_is_the_same_for_every_split_into_tasks(body):
    """The global search's settling runs as subtree tasks of `budget` tree nodes, then one
    mu^c task per pattern found (engine jobs global_patterns, global_mu_c): its value and every
    count (tree nodes, solves, statuses, mu^c polished) are the same in tasks of 1 node, 5
    nodes and one task for the whole tree, and the tasks really split the tree (handed back).
    The certified bound, which ends the search on these plugs before any settling, is not
    asked (bound=False)."""
    from hpcwedge.parallel.engine import Engine
    if body == "plug2d":
        data = {"name": "p", "dim": 2, "friction": {"mu": [0.65]},
                "model": {"kind": "plug2d", "rows": 4}}
        param, m = parametrize(run_scene(parse_scene({**data, "compute": {"mu_c": "none"}})).problem), 8
    else:
        param, m = plug3d_param(2, 5)
    seen = []
    for budget in (1, 5, 10**9):
        st, engine = BnBStats(), Engine()
        mu, status = global_mu_critical(param, m, 100.0, stats=st, engine=engine, budget=budget, bound=False)
        jobs = engine.summary()["jobs"]
        assert list(jobs) == ["global_bracket", "global_patterns", "global_mu_c"]
        assert (jobs["global_patterns"]["handed_back"] > 0) == (budget < 10**9)
        seen.append((mu, status, st.nodes, st.solves, st.skipped, st.undecided, st.statuses, st.extra))
    assert seen[0][1] == "found"
    assert abs(seen[0][0] - math.tan(math.radians(10))) <= 1e-12
    assert seen[0] == seen[1] == seen[2]


def _brute_global(p, m: int, mu_max: float) -> float:
    """The least certified mu^c over the feasible full patterns at mu_max, every partition
    tried (reference.brute_force_patterns: 2^m SOCPs)."""
    from instances import brute_3d
    values = []
    for bits in brute_3d(p, m, mu_max):
        zu = np.array([bool(bits >> i & 1) for i in range(m)])
        values.append(mu_critical(p, m, zu, ~zu, mu_hi=mu_max).mu_c)
    return min(v for v in values if v is not None)


@pytest.mark.parametrize("body", ["neck-2x5-s0", "neck-3x3-s1", "random3d-6", "random3d-7"])
def test_3d_global_mu_c_is_the_brute_force_least_for_every_step_dive_budget(monkeypatch, body):
    """3D tree route on bodies where elasticity sets mu^c (curved necks, m = 9, 10) and random
    free bodies (m = 6, 7): the global mu^c is the least certified mu^c of the brute force's
    patterns, to 1e-9, whether the dives below the incumbent are cut at once
    (STEP_DIVE_FACTOR = 0: the settling tree starts from the first pattern's value), get the
    default budget, or none (the bracket's steps to the end); no value unsettled. (Undecided
    tree solves, kept as feasible, occur on neck 3 x 3 in the dives at every budget.)"""
    from instances import curved_neck, random_problem_3d, scene_param

    import hpcwedge.mu_c.global_search as gs
    if body.startswith("neck"):
        shape, seed = body.split("-")[1:]
        levels, ring = map(int, shape.split("x"))
        p, m = scene_param(curved_neck(levels, ring, int(seed[1:])))
    else:
        m = int(body.split("-")[1])
        p = parametrize(random_problem_3d(np.random.default_rng(m), m, free=True))
    mu_max = 5.0
    want = _brute_global(p, m, mu_max)
    spent = []
    for factor in (0, gs.STEP_DIVE_FACTOR, 10**6):
        monkeypatch.setattr(gs, "STEP_DIVE_FACTOR", factor)
        st = BnBStats()
        mu, status = global_mu_critical(p, m, mu_max, stats=st, bound=False)
        assert status == "found" and abs(mu - want) <= 1e-9 * want, (factor, mu, want)
        assert st.extra.get("mu_c_unsettled", 0) == 0
        spent.append(st.statuses.get("step_dive_spent", 0))
    # cut at once, a dive below the incumbent is spent unless its root fails (random 3d-6 does)
    assert spent[2] == 0 and spent[0] <= 1 and (spent[0] == 1 or not body.startswith("neck"))


def test_no_wedge_up_to_mu_max_is_told_from_none_at_any_mu_and_resumes_between():
    """3D tree route: plug3d 2 x 5 (mu^c = tan 10 deg) searched up to mu_max = 0.1 has no
    wedge there but one with r_t free ("none_up_to_mu_max"); a single uncoupled node has none
    at all ("none_at_any_mu"). The dive with r_t free follows the dive at mu_max that found
    nothing; a bracket resumed between the two (a Continuation's payload, bound None) ends
    with the uninterrupted bracket's outcome and counts."""
    from hpcwedge.contact.problem import ContactProblem
    from hpcwedge.mu_c.floor_pattern import floor_start
    from hpcwedge.mu_c.global_search import GlobalSearch, _counts_json, _step_state
    single = parametrize(ContactProblem(3, np.diag([2.0, 1.0, 3.0]), np.zeros((3, 0))))
    for (p, m), want in ((plug3d_param(2, 5), "none_up_to_mu_max"), ((single, 1), "none_at_any_mu")):
        assert global_mu_critical(p, m, 0.1) == (None, want)
        search = GlobalSearch(p, m, 0.1, "accurate", 1e-6, None, None, "auto")
        whole = BnBStats()
        assert search.bracket(whole, {}) == (None, want)
        before = BnBStats(extra={"route": "tree"})
        assert floor_start(p, m, 0.1, before) is None          # the floor is mu_max, or none
        assert search._first_leaf(before, 0.1) is None
        resumed = BnBStats()
        assert search.bracket(resumed, {}, resume=_step_state(before, {}, None, None, m)) == (None, want)
        assert _counts_json(resumed) == _counts_json(whole) and whole.nodes > before.nodes > 0


def test_3d_tree_route_starts_from_the_floor_pattern_and_resumes_it():
    """3D with the bound: the tree route first takes floor_pattern's pattern at the certified
    rigid bound; on plug3d 2 x 5 its mu^c meets the bound, so no tree node is solved, and the
    answer is the whole tree's (bound=False) to 1e-9. A bracket paused in that step (its
    Continuation's payload marked "floor") ends with the uninterrupted bracket's counts."""
    from hpcwedge.mu_c.global_search import GlobalSearch, _counts_json, _step_state
    p, m = plug3d_param(2, 5)
    st, tree = BnBStats(), BnBStats()
    mu, status = global_mu_critical(p, m, 5.0, stats=st)
    assert status == "found" and abs(mu - math.tan(math.radians(10.0))) <= 1e-9
    assert st.nodes == 0 and st.statuses["floor_pattern"] == 1 and st.extra["bound_certified"] == 1
    mu_tree, _ = global_mu_critical(p, m, 5.0, stats=tree, bound=False)
    assert tree.nodes > 0 and abs(mu_tree - mu) <= 1e-9 * mu
    search = GlobalSearch(p, m, 5.0, "accurate", 1e-6, None, None, "auto")
    whole = BnBStats()
    best, how = search.bracket(whole, {})
    assert how == "found" and best == mu
    resumed = BnBStats()
    state = {**_step_state(BnBStats(extra={"route": "tree"}), {}, None, 5.0, m), "floor": True}
    assert search.bracket(resumed, {}, resume=state) == (best, "found")
    assert _counts_json(resumed) == _counts_json(whole)

