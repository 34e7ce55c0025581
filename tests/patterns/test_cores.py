"""cores.py: learnt infeasible cores of the 3D sign-pattern tree — every full pattern that
extends a core is infeasible by brute force — and the core set's cover rule."""
import numpy as np
import pytest
from instances import brute_3d

from hpcwedge.contact.problem import parametrize
from hpcwedge.patterns.cores import Cores
from hpcwedge.patterns.tree import PatternTree, Subtree


@pytest.mark.parametrize("seed", range(10))
def test_learnt_cores_rule_out_only_infeasible_patterns(seed):
    """Every full pattern that extends a core learnt from a Farkas certificate is
    infeasible by brute force; the cores are smaller than the nodes they came from."""
    from instances import random_problem_3d
    rng = np.random.default_rng(100 + seed)
    m = 5 + seed % 2
    prob = random_problem_3d(rng, m, free=bool(seed % 2))
    mu = float(np.exp(rng.uniform(np.log(0.3), np.log(3.0))))
    p = parametrize(prob)
    tree = PatternTree(p, m, mu, learn_cores=True)
    out = tree.explore(tree.root())
    feasible = brute_3d(p, m, mu)
    assert {s.contact for s in out.found} == feasible
    if seed == 2:                                     # this one learns 4 cores, which rule out 4 nodes
        assert out.stats.pruned > 0
    cores = tree._cores
    for c, g in zip(cores._c[:cores.n].tolist(), cores._g[:cores.n].tolist()):
        assert c & g == 0
        for bits in feasible:                         # a feasible pattern extends no core
            assert not (c & ~bits == 0 and g & bits == 0), (bin(c), bin(g), bin(bits))


def test_a_core_covers_the_nodes_that_extend_it():
    """A core (node 0 in contact, node 2 open) rules out every node fixing those two nodes
    the same way, and no other; a core no smaller than its node is not kept."""
    m = 4
    cores = Cores(m)
    assert not cores.covers(Subtree(m, contact=0b1111, gap=0))
    zu, zr = np.array([True, False, False, False]), np.array([False, False, True, False])
    cores.add(Subtree(3, contact=0b011, gap=0b100), zu, zr)
    assert cores.n == 1
    assert cores.covers(Subtree(3, contact=0b011, gap=0b100))
    assert cores.covers(Subtree(4, contact=0b1001, gap=0b0110))
    assert not cores.covers(Subtree(4, contact=0b1101, gap=0b0010))      # node 2 in contact
    assert not cores.covers(Subtree(4, contact=0b0010, gap=0b1101))      # node 0 open
    assert not cores.covers(Subtree(1, contact=0b1, gap=0))              # node 2 not fixed yet
    cores.add(Subtree(2, contact=0b01, gap=0b10), np.array([True, False, False, False]),
              np.array([False, True, False, False]))
    assert cores.n == 1                                                  # the node itself: not kept
