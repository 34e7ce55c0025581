"""Sign-pattern branch and bound: exploring by subtrees with a node budget
finds exactly what one uninterrupted depth-first search finds."""
import numpy as np
import pytest
from instances import brute_3d, random_problem, tree_factory

from hpcwedge.contact.problem import parametrize
from hpcwedge.nodesets import pattern_key, to_bits
from hpcwedge.patterns.job import run_patterns
from hpcwedge.patterns.tree import PatternTree, Subtree
from hpcwedge.reference import patterns_of_supports
from hpcwedge.run.pipeline import run_scene
from hpcwedge.scene.parse import parse_scene


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("budget", [1, 3, 7])
def test_budgeted_exploration_equals_one_pass(seed, budget):
    rng = np.random.default_rng(900 + seed)
    m = 4
    prob = random_problem(rng, m, free=bool(seed % 2))
    tree = PatternTree(parametrize(prob), m, mu=3.0)
    whole = tree.explore(tree.root())
    assert whole.open == []
    queue, found, calls = [tree.root()], [], 0
    while queue:
        out = tree.explore(queue.pop(), budget)
        assert out.stats.nodes <= budget
        found += out.found
        queue += out.open
        calls += 1
    key = lambda s: (s.contact, s.gap)
    assert sorted(found, key=key) == sorted(whole.found, key=key)
    assert all(s.depth == m and s.contact | s.gap == (1 << m) - 1 for s in found)
    assert calls > 1


def test_subtree_masks():
    zu, zr = Subtree(3, contact=0b101, gap=0b010).masks(4)
    assert zu.tolist() == [True, False, True, False]
    assert zr.tolist() == [False, True, False, False]
    # both masks come from one unpacking: neither may read the other's bits, on any m
    rng = np.random.default_rng(1)
    for m in (1, 7, 8, 9, 18, 64, 65):
        for _ in range(20):
            contact, gap = (int.from_bytes(rng.bytes(m // 8 + 1), "little") & ((1 << m) - 1) for _ in "cg")
            zu, zr = Subtree(0, contact, gap).masks(m)
            assert zu.tolist() == [bool(contact >> i & 1) for i in range(m)]
            assert zr.tolist() == [bool(gap >> i & 1) for i in range(m)]


# ------------------------------------------------------------------ 2D vs rays
from instances import random_problem_3d  # noqa: E402

from hpcwedge.contact.problem import friction_rows_2d  # noqa: E402
from hpcwedge.patterns.tree import sign_patterns  # noqa: E402
from hpcwedge.rays.dd import complementary_rays  # noqa: E402


@pytest.mark.parametrize("seed", range(40))
def test_2d_patterns_are_the_ones_the_rays_imply(seed):
    """SPEC §2: (C, G) is feasible iff some wedged ray has supp(r_n) ⊆ C and
    supp(u_n) ⊆ G — the branch and bound (LPs) against the double description."""
    rng = np.random.default_rng(4000 + seed)
    m = [2, 3, 4, 5][seed % 4]
    prob = random_problem(rng, m, free=bool(seed % 2))
    mu = float(np.exp(rng.uniform(np.log(1.0), np.log(20.0))))
    p = parametrize(prob)
    dd = complementary_rays(friction_rows_2d(p, mu, m), m)
    w = dd.wedged()
    loaded, lifted = ~dd.zero_r()[w], ~dd.zero_u()[w]          # supp(r_n), supp(u_n) per wedged ray
    implied = patterns_of_supports(loaded, lifted, m)
    got = {int(sum(1 << i for i in range(m) if zu[i])) for zu, _ in sign_patterns(p, m, mu)}
    assert got == implied


# ------------------------------------------------------------------ 3D tree
@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("budget", [1, 4])
def test_3d_budgeted_exploration_equals_one_pass(seed, budget):
    rng = np.random.default_rng(950 + seed)
    m = 4
    tree = PatternTree(parametrize(random_problem_3d(rng, m, free=bool(seed % 2))), m, mu=2.0)
    assert tree.dim == 3
    whole = tree.explore(tree.root())
    queue, found = [tree.root()], []
    while queue:
        out = tree.explore(queue.pop(), budget)
        assert out.stats.nodes <= budget
        found += out.found
        queue += out.open
    key = lambda s: (s.contact, s.gap)
    assert sorted(found, key=key) == sorted(whole.found, key=key)


def test_3d_skip_rule_and_steering_save_solves():
    """plug3d, m = 10, mu = 1, static order: fewer SOCPs than tree nodes and than
    2^m, every pattern found; dynamic branching (the default): the same patterns
    with fewer SOCPs still."""
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.scene.parse import parse_scene
    sc = parse_scene({"name": "p", "dim": 3, "model": {"kind": "plug3d"}, "friction": {"mu": [1.0]}})
    p = parametrize(contact_problem(sc))
    tree = PatternTree(p, 10, 1.0, order=list(range(9, -1, -1)))
    assert not tree.dynamic
    out = tree.explore(tree.root())
    assert len(out.found) == 131
    s = out.stats
    assert s.skipped > 0 and s.statuses.get("contact_child_infeasible_by_parent", 0) > 0
    assert s.solves < 1024 and s.solves + s.skipped + s.pruned == s.nodes
    dyn = PatternTree(p, 10, 1.0)
    assert dyn.dynamic
    out2 = dyn.explore(dyn.root())
    key = lambda t: (t.contact, t.gap)
    assert sorted(out2.found, key=key) == sorted(out.found, key=key)
    assert out2.stats.solves < s.solves


# ---------------------------------------------------------------- symmetry


@pytest.mark.parametrize("seed", range(16))
def test_orbital_branching_finds_every_orbit(seed):
    """Planted cyclic symmetry (free and supported, m = 3..6, random mu): the tree
    with the symmetry, expanded over the group, finds exactly the brute force's
    patterns; it visits fewer leaves than there are patterns whenever some orbit
    has more than one pattern."""
    from instances import symmetric_problem_3d

    from hpcwedge.patterns.symmetry import node_symmetries
    rng = np.random.default_rng(seed)
    m = 3 + seed % 4
    prob = symmetric_problem_3d(rng, m, free=bool(seed % 2))
    mu = float(np.exp(rng.uniform(np.log(0.3), np.log(3.0))))
    p = parametrize(prob)
    G = node_symmetries(prob.K, 3)
    assert G.order >= m
    tree = PatternTree(p, m, mu, symmetry=G)
    out = tree.explore(tree.root())
    got = tree.expand(out.found)
    assert {s.contact for s in got} == brute_3d(p, m, mu)
    assert all(s.depth == m and s.contact | s.gap == (1 << m) - 1 and not s.contact & s.gap for s in got)
    if any(len(G.expand([(s.contact, s.gap)])) > 1 for s in got):
        assert len(out.found) < len(got)


def test_symmetry_saves_solves_on_plug3d_and_changes_no_pattern():
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.patterns.symmetry import node_symmetries
    from hpcwedge.scene.parse import parse_scene
    sc = parse_scene({"name": "p", "dim": 3, "model": {"kind": "plug3d", "ring": 5}, "friction": {"mu": 1.0}})
    prob = contact_problem(sc)
    p, G = parametrize(prob), node_symmetries(prob.K, 3)
    plain, sym = PatternTree(p, 10, 1.0), PatternTree(p, 10, 1.0, symmetry=G)
    a, b = plain.explore(plain.root()), sym.explore(sym.root())
    key = lambda t: (t.contact, t.gap)
    assert sorted(a.found, key=key) == sym.expand(b.found) and len(a.found) == 131
    assert 2 * b.stats.solves < a.stats.solves


def test_orbital_fixing_drops_no_orbit_and_saves_solves():
    """plug3d 2 x 4 at mu = 1 (m = 8, dihedral group of order 8): the orbital tree (with
    orbital fixing), expanded over the group, gives the brute force's 77 patterns from 14
    leaves and 81 SOCPs (orbital branching alone, measured before the fixing became
    unconditional: 21 leaves, 103 SOCPs)."""
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.patterns.symmetry import node_symmetries
    from hpcwedge.scene.parse import parse_scene
    sc = parse_scene({"name": "p", "dim": 3, "model": {"kind": "plug3d", "ring": 4}, "friction": {"mu": 1.0}})
    prob = contact_problem(sc)
    p, G = parametrize(prob), node_symmetries(prob.K, 3)
    tree = PatternTree(p, 8, 1.0, symmetry=G)
    a = tree.explore(tree.root())
    want = brute_3d(p, 8, 1.0)
    assert {s.contact for s in tree.expand(a.found)} == want and len(want) == 77
    assert (len(a.found), a.stats.solves) == (14, 81)


@pytest.mark.parametrize("seed,budget", [(0, 1), (1, 3), (2, 1000)])
def test_run_patterns_equals_serial_search(seed, budget):
    make, prob = tree_factory(700 + seed, free=bool(seed % 2))
    mus = [0.5, 2.0, 8.0]
    out = run_patterns(make, mus, budget=budget)
    for k, mu in enumerate(mus):
        tree = make(mu)
        whole = tree.explore(tree.root())
        # the engine's order is the one canonical order (nodesets.pattern_key), whatever the split
        assert out.found[k] == sorted(whole.found, key=lambda s: pattern_key(s.contact))
        masks = [s.masks(tree.m) for s in out.found[k]]
        ref = sorted(sign_patterns(tree.param, tree.m, mu), key=lambda ab: pattern_key(to_bits(np.flatnonzero(ab[0]))))
        assert [(a.tolist(), b.tolist()) for a, b in masks] == [(a.tolist(), b.tolist()) for a, b in ref]
    # every tree node is visited exactly once, however the work is split
    nodes = sum(make(mu).explore(make(mu).root()).stats.nodes for mu in mus)
    assert out.counters["nodes"] == nodes
    if budget == 1:
        assert out.counters["handed_back"] > 0


@pytest.mark.parametrize("rows,taper,mus", [(2, 10.0, [0.2, 0.65]), (3, 10.0, [0.65]),
                                            (3, 31.0, [0.62, 2.0]), (4, 20.0, [0.5])])
def test_2d_patterns_agree_with_rays(rows, taper, mus):
    """SPEC §2: (C, G) is feasible iff some wedged ray has supp(r_n) in C and
    supp(u_n) in G — the engine's patterns against the double description's rays."""
    from hpcwedge.reference import patterns_of_supports

    def scene(enum):
        return parse_scene({"name": "t", "dim": 2, "model": {"kind": "plug2d", "rows": rows, "taper_deg": taper},
                            "friction": {"mu": mus}, "compute": {"enumerate": enum, "mu_c": "cones"},
                            "run": {"task_budget": 3}})
    pat, ray = run_scene(scene("patterns")), run_scene(scene(True))
    m = pat.m
    assert pat.stages == ["condense", "enumerate", "mu_c"]
    assert abs(pat.mu_c - ray.mu_c) <= 1e-9 * ray.mu_c
    for rp, rr in zip(pat.runs, ray.runs):
        assert rp.rays is None and rp.cones is None and rr.patterns is None
        un, rn = rr.rays[:, :m], rr.rays[:, 2 * m:3 * m]
        scale = np.abs(rr.rays).max(axis=1, keepdims=True)
        supp_u, supp_r = np.abs(un) > 1e-9 * scale, np.abs(rn) > 1e-9 * scale
        want = [[i for i in range(m) if bits >> i & 1]                   # canonical: by contact bits
                for bits in sorted(patterns_of_supports(supp_r, supp_u, m))]
        assert [p.contact for p in rp.patterns] == want
        for p in rp.patterns:               # a pattern's mu^c: at most the run's mu, at least the global one
            assert ray.mu_c * (1 - 1e-9) <= p.mu_c <= rp.mu * (1 + 1e-9)


# ------------------------------------------------- bodies where elasticity sets mu^c


NECKS = [dict(levels=2, ring=5, seed=0), dict(levels=3, ring=3, seed=1), dict(levels=2, ring=5, seed=2, drop=1)]


@pytest.mark.parametrize("body", NECKS, ids=lambda b: "-".join(f"{k}{v}" for k, v in b.items()))
def test_curved_neck_patterns_and_global_mu_c_agree_with_brute_force(body):
    """instances.curved_neck (m = 9, 10): the global mu^c equals the least certified mu^c over
    the brute force's feasible patterns at mu = 2 (all 2^m partitions, one SOCP each), to
    1e-9; it lies well above the relaxation bound (the root relaxation, no complementarity,
    is feasible at 1.5 tan(taper)): elasticity, not the rigid bound, sets it; the tree finds
    exactly the brute force's patterns at 1.02, 1.1 and 1.5 mu^c."""
    import math

    from instances import curved_neck, scene_param

    from hpcwedge.mu_c.critical import mu_critical
    from hpcwedge.solvers.feasibility import decide
    from hpcwedge.solvers.rows import Status, pattern_rows
    data = curved_neck(**body)
    p, m = scene_param(data)
    assert m == body["levels"] * body["ring"] - body.get("drop", 0)
    values = []
    for bits in brute_3d(p, m, 2.0):
        zu = np.array([bool(bits >> i & 1) for i in range(m)])
        values.append(mu_critical(p, m, zu, ~zu, mu_hi=2.0).mu_c)
    want = min(values)
    got = _global_of(data)
    assert abs(got - want) <= 1e-9 * want, (got, want)
    tan = math.tan(math.radians(3.0))
    assert decide(pattern_rows(p, m, np.zeros(m, bool), np.zeros(m, bool)), 1.5 * tan).status == Status.FEASIBLE
    assert want > 3 * tan
    for f in (1.02, 1.1, 1.5):
        tree = PatternTree(p, m, f * want)
        found = {s.contact for s in tree.explore(tree.root()).found}
        assert found == brute_3d(p, m, f * want) and found


def _global_of(data: dict) -> float:
    """The global mu^c of scene data by `hpcwedge run`'s route (enumerate = false)."""
    scene = dict(data, friction={"mu": [0.01]}, compute={"enumerate": False, "mu_c": "global"})
    res = run_scene(parse_scene(scene))
    assert res.stats["bnb"]["unsettled"] == 0
    return res.mu_c
def test_a_stop_inside_a_solve_hands_the_node_back_uncounted():
    """plug3d 2 x 5 (m = 10) at mu = 1: the engine stops the exploration after k looks at
    task_stopping (between nodes, or inside a Clarabel solve, which then raises
    TaskCancelled); the stopped exploration followed by its open subtrees finds the
    patterns of one pass and counts its nodes and solves exactly, for every k (some of
    which fall inside solves: more looks than nodes visited)."""
    from instances import plug3d_param

    from hpcwedge.parallel.cancel import run_cancellable
    param, m = plug3d_param(2, 5)
    tree = PatternTree(param, m, 1.0)
    ref = tree.explore(Subtree(0))
    inside = 0
    for k in (3, 10, 25, 60, 150):
        looks = []
        first = run_cancellable(lambda ctx, p: tree.explore(Subtree(0)), None, None,
                                lambda: looks.append(1) or len(looks) > k, tick_every_s=0.0)
        assert first.stopped
        inside += len(looks) > first.stats.nodes + 2
        found, nodes, solves = list(first.found), first.stats.nodes, first.stats.solves
        for node, x in zip(first.open, first.open_x):
            rest = tree.explore(node, x=x)
            found += rest.found
            nodes, solves = nodes + rest.stats.nodes, solves + rest.stats.solves
        assert sorted(s.contact for s in found) == sorted(s.contact for s in ref.found)
        assert (nodes, solves) == (ref.stats.nodes, ref.stats.solves)
    assert inside > 0
