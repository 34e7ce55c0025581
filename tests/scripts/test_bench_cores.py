"""scripts/bench_cores.py's two routes on plug3d 2 x 4 (m = 8) at mu = 0.65: the node-by-node
walk of the tree (explore with budget 1) is the tree of one pass, and the deletion filter's
cores are minimal infeasible subsets of the node's fixings (each infeasible, each one
smaller by a fixing feasible), checked against feasibility.decide."""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "scripts"))
import bench_cores  # noqa: E402
from bench_search_3d import scene  # noqa: E402

from hpcwedge.contact.build import contact_problem
from hpcwedge.contact.problem import parametrize
from hpcwedge.patterns.tree import PatternTree
from hpcwedge.solvers.feasibility import TREE_OPTIONS, decide
from hpcwedge.solvers.rows import Status, pattern_rows

MU = 0.65


@pytest.fixture(scope="module")
def body():
    prob = contact_problem(scene("enumerate", 2, 4))
    return parametrize(prob), prob.m


def infeasible(param, m, zu, zr) -> bool:
    return decide(pattern_rows(param, m, zu, zr), MU, TREE_OPTIONS).status == Status.INFEASIBLE


def test_node_by_node_walk_is_the_one_pass_tree(body):
    param, m = body
    tree = PatternTree(param, m, MU)
    one = tree.explore(tree.root())
    walk = bench_cores.tree_nodes(param, m, MU)
    assert (walk.nodes, walk.solves) == (one.stats.nodes, one.stats.solves)
    assert sorted(p.tobytes() for zu, zr in walk.patterns for p in (zu, zr)) == \
        sorted(p.tobytes() for f in one.found for p in f.masks(m))
    assert len(walk.infeasible) == one.stats.statuses.get("PrimalInfeasible", 0) > 0
    assert len(walk.infeasible) + len(walk.feasible) == one.stats.nodes
    assert all(infeasible(param, m, zu, zr) for zu, zr in walk.infeasible)


def test_live_nodes_are_those_with_a_pattern_below(body):
    """live() against the brute force: every partition of plug3d 2 x 4 decided by the SOCP;
    a feasible node is live iff some feasible full pattern completes its fixings."""
    param, m = body
    walk = bench_cores.tree_nodes(param, m, MU)
    full = []
    for code in range(2 ** m):
        zr = np.array([not code >> i & 1 for i in range(m)])
        if not infeasible(param, m, ~zr, zr):
            full.append((~zr, zr))
    alive = bench_cores.live(walk.feasible, walk.patterns)
    for (zu, zr), a in zip(walk.feasible, alive):
        assert a == any(not (zu & ~pu).any() and not (zr & ~pr).any() for pu, pr in full)
    assert 0 < alive.sum() < len(alive)
    assert alive.sum() >= len(walk.patterns)
    # a binary tree without symmetry: every live node above the leaves has two children,
    # the live ones other than the root and the dead roots
    inner = sum(1 for (zu, zr), a in zip(walk.feasible, alive) if a and (zu | zr).sum() < m)
    assert bench_cores.dead_roots(walk, alive) == 2 * inner - (alive.sum() - 1) > 0


def test_deletion_filter_cores_are_minimal(body):
    param, m = body
    nodes = bench_cores.tree_nodes(param, m, MU).infeasible
    for zu, zr in nodes[:: max(1, len(nodes) // 6)]:
        cu, cr, socps = bench_cores.minimal_core(param, m, MU, zu, zr)
        assert socps == int((zu | zr).sum())
        assert not (cu & ~zu).any() and not (cr & ~zr).any()
        assert infeasible(param, m, cu, cr)
        for i in np.flatnonzero(cu | cr):
            tu, tr = cu.copy(), cr.copy()
            tu[i] = tr[i] = False
            assert not infeasible(param, m, tu, tr)
