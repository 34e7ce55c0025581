"""The cross-complementarity graph and its maximal cliques (cones.py) against a brute force:
every subset of a few random complementary rays, tested pair by pair (no packing, no
twin classes, no networkx)."""
import itertools

import numpy as np
import pytest

from hpcwedge.rays.cones import cross_complementary, maximal_cones


def random_rays(rng, R: int, m: int, wedged_share: float = 0.8):
    """(gap, load, wedged) of R random complementary rays on m nodes: per node gap, load or
    neither (never both); a wedged ray carries load somewhere. Few signatures, so twins occur."""
    state = rng.integers(0, 3, size=(R, m))              # 0 neither, 1 gap, 2 load
    wedged = rng.random(R) < wedged_share
    for r in range(R):
        if wedged[r] and not (state[r] == 2).any():
            state[r, rng.integers(m)] = 2
        if not wedged[r]:
            state[r][state[r] == 2] = 1                 # a rigid lift-off: no load anywhere
    return state == 1, state == 2, wedged


def adjacent(gap, load, a: int, b: int) -> bool:
    m = gap.shape[1]
    return not any((gap[a, i] and load[b, i]) or (gap[b, i] and load[a, i]) for i in range(m))


def brute_cones(gap, load, wedged) -> set:
    """{(rays, zero_u, zero_r)} of the maximal cliques with a wedged ray, by all subsets."""
    R, m = gap.shape
    out = set()
    for k in range(1, R + 1):
        for S in itertools.combinations(range(R), k):
            if not all(adjacent(gap, load, a, b) for a, b in itertools.combinations(S, 2)):
                continue
            if any(all(adjacent(gap, load, c, a) for a in S) for c in range(R) if c not in S):
                continue                                  # not maximal
            if not any(wedged[a] for a in S):
                continue
            zu = tuple(not any(gap[a, i] for a in S) for i in range(m))
            zr = tuple(not any(load[a, i] for a in S) for i in range(m))
            out.add((S, zu, zr))
    return out


@pytest.mark.parametrize("seed", range(30))
def test_cross_complementary_pairwise(seed):
    rng = np.random.default_rng(seed)
    m = int(rng.integers(1, 20))                         # beyond 8 and 16: several packed bytes
    gap, load, _ = random_rays(rng, 7, m)
    ga, la, _ = random_rays(rng, 5, m)
    got = cross_complementary(gap, load, ga, la)
    assert got.shape == (7, 5) and got.dtype == bool
    for a in range(7):
        for b in range(5):
            clash = any((gap[a, i] and la[b, i]) or (ga[b, i] and load[a, i]) for i in range(m))
            assert got[a, b] == (not clash)


@pytest.mark.parametrize("seed", range(60))
def test_maximal_cones_equal_brute_force_cliques(seed):
    rng = np.random.default_rng(1000 + seed)
    R, m = int(rng.integers(1, 11)), int(rng.integers(1, 5))
    gap, load, wedged = random_rays(rng, R, m)
    cones = maximal_cones(gap, load, wedged)
    got = {(c.rays, tuple(c.zero_u.tolist()), tuple(c.zero_r.tolist())) for c in cones}
    assert len(got) == len(cones)                       # no cone twice
    assert got == brute_cones(gap, load, wedged)
    keys = [c.key() for c in cones]
    assert keys == sorted(keys)                         # canonical order
    for c in cones:
        assert c.key() == (tuple(np.flatnonzero(c.zero_u)), tuple(np.flatnonzero(c.zero_r)))


def test_the_brute_force_sees_several_cones_and_twins():
    """The random cases above are not all trivial: some have several cones, and twins."""
    many = twins = 0
    for seed in range(60):
        rng = np.random.default_rng(1000 + seed)
        R, m = int(rng.integers(1, 11)), int(rng.integers(1, 5))
        gap, load, wedged = random_rays(rng, R, m)
        many += len(brute_cones(gap, load, wedged)) > 1
        twins += len({(g.tobytes(), l.tobytes()) for g, l in zip(gap, load)}) < R
    assert many >= 10 and twins >= 10


def test_no_rays_and_no_wedged_ray():
    assert maximal_cones(np.zeros((0, 3), bool), np.zeros((0, 3), bool), np.zeros(0, bool)) == []
    gap = np.array([[True, False], [False, True]])
    assert maximal_cones(gap, np.zeros_like(gap), np.zeros(2, bool)) == []


def test_a_clash_splits_the_cones():
    """Ray 0 lifts node 0 where ray 1 loads it: two cones ({1, 2}, {0, 2}), in canonical order."""
    gap = np.array([[True, False], [False, False], [False, False]])
    load = np.array([[False, True], [True, False], [False, True]])
    cones = maximal_cones(gap, load, np.ones(3, bool))
    assert [c.rays for c in cones] == [(1, 2), (0, 2)]
    assert [c.key() for c in cones] == [((0, 1), ()), ((1,), (0,))]
