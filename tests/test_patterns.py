"""Sign-pattern branch and bound: exploring by subtrees with a node budget
finds exactly what one uninterrupted depth-first search finds."""
import numpy as np
import pytest

from hpcwedge.patterns import PatternTree, Subtree
from hpcwedge.problem import parametrize
from instances import random_problem


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
