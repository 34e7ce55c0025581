"""The independent routes themselves (hpcwedge.reference): the peers' post-processing on rays
whose zero sets are known (our exact DD's, handed over as cddlib would), the rays' implied
patterns against the package's map, and the bench extras (pycddlib, pyscipopt) where
installed."""
import importlib.util
import math

import numpy as np
import pytest
from instances import random_problem

from hpcwedge.contact.problem import friction_rows_2d, parametrize
from hpcwedge.rays.cones import implied_patterns
from hpcwedge.rays.dd import FLOAT_ZERO_TOL, complementary_rays
from hpcwedge.reference import (
    bisect,
    brute_force_patterns,
    cdd_generators,
    cdd_zero,
    complementary_filter,
    contact_mask,
    patterns_of_rays,
    scip_patterns,
    scip_wedged,
)


def test_contact_mask():
    assert contact_mask(0b1010, 5).tolist() == [False, True, False, True, False]
    assert contact_mask(0, 0).tolist() == []


@pytest.mark.parametrize("seed", range(6))
def test_cdd_zero_on_known_rays(seed):
    """Rays in cddlib's generator form ([0, x] rays, a [1, 0] apex) on a free body: the zero
    flags on the rows are the DD's, exactly (integer rows, exact rays) and in float (unit
    rows and rays, FLOAT_ZERO_TOL)."""
    rng = np.random.default_rng(40 + seed)
    m = 3
    prob = random_problem(rng, m, free=True)
    A = friction_rows_2d(parametrize(prob, exact=True), 2.0, m, exact=True)
    dd = complementary_rays(A, m, exact=True)
    assert len(dd.X) > 0
    rows = [[int(v) for v in row] for row in A]
    apex = [[1] + [0] * A.shape[1]]
    gens = apex + [[0] + [int(v) for v in x] for x in dd.X]
    assert np.array_equal(cdd_zero(rows, gens, exact=True), dd.zero)
    with pytest.raises(RuntimeError, match="violates"):
        cdd_zero(rows, apex + [[0] + [-int(v) for v in dd.X[0]]], exact=True)     # a ray outside
    assert cdd_zero(rows, apex, exact=True).shape == (0, 3 * m)
    Af = friction_rows_2d(parametrize(prob), 2.0, m)
    df = complementary_rays(Af, m)
    gens = apex + [[0.0] + x.tolist() for x in df.X]
    assert np.array_equal(cdd_zero(Af, gens, exact=False, tol=FLOAT_ZERO_TOL), df.zero)
    with pytest.raises(RuntimeError, match="violates"):
        cdd_zero(Af, apex + [[0.0] + (-df.X[0]).tolist()], exact=False, tol=FLOAT_ZERO_TOL)


def test_complementary_filter():
    zero = np.array([[0, 0, 0, 1, 1, 1],        # node 0 open and loaded: not complementary
                     [1, 0, 0, 0, 0, 1],        # node 1 open and loaded: not complementary
                     [1, 0, 0, 0, 1, 1],        # complementary, wedged
                     [0, 1, 1, 1, 1, 1],        # complementary, r = 0: a rigid lift-off
                     [1, 0, 0, 1, 1, 1]], dtype=bool)
    kept, wedged, n = complementary_filter(zero)
    assert n == 3 and kept.tolist() == zero[[2, 3, 4]].tolist()
    assert wedged.tolist() == [True, False, True]


@pytest.mark.parametrize("seed", range(10))
def test_patterns_of_rays_equals_the_packages_map(seed):
    """2^m contact sets tried one by one == cones.implied_patterns' subset enumeration."""
    rng = np.random.default_rng(500 + seed)
    m = 3 + seed % 3
    p = parametrize(random_problem(rng, m, free=bool(seed % 2)))
    dd = complementary_rays(friction_rows_2d(p, float(rng.uniform(0.3, 2.0)), m), m)
    want = {sum(1 << i for i in c) for c in implied_patterns(dd.zero[dd.wedged()], m)}
    assert patterns_of_rays(dd.zero, m) == want
    assert patterns_of_rays(dd.zero[~dd.wedged()], m) == set()      # lift-offs imply nothing


def test_bisect():
    assert abs(bisect(lambda mu: mu >= 0.3, 0.0, 1.0, 1e-9) - 0.3) <= 1e-9
    assert bisect(lambda mu: True, 0.5, 1.0, 0.6) == 1.0


def _plug(rows: int = 2):
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.scene.parse import parse_scene
    sc = parse_scene({"name": "p", "dim": 2, "model": {"kind": "plug2d", "rows": rows, "taper_deg": 10.0},
                      "friction": {"mu": [1.0]}})
    prob = contact_problem(sc)
    return parametrize(prob), prob.m


def test_brute_force_on_the_plug():
    """plug2d rows 2 (m = 4): below tan(10 deg) nothing wedges; above, all in contact does."""
    p, m = _plug()
    t = math.tan(math.radians(10.0))
    counts = {}
    assert brute_force_patterns(p, m, 0.9 * t, counts) == []
    assert sum(counts.values()) == 2 ** m
    assert (1 << m) - 1 in brute_force_patterns(p, m, 1.1 * t)


@pytest.mark.skipif(importlib.util.find_spec("pyscipopt") is None, reason="pyscipopt not installed (bench extra)")
def test_scip_wedged_brackets_tan_taper():
    p, m = _plug()
    t = math.tan(math.radians(10.0))
    counts = {}
    assert scip_wedged(p, m, 1.01 * t, counts) and not scip_wedged(p, m, 0.99 * t, counts)
    assert counts["milp_solves"] == 2 and "undecided" not in counts


@pytest.mark.skipif(importlib.util.find_spec("pyscipopt") is None, reason="pyscipopt not installed (bench extra)")
@pytest.mark.parametrize("dim", [2, 3])
def test_scip_patterns_are_the_brute_force_patterns(dim):
    """SCIP's no-good loop (the peer of scripts/bench_search_3d.py) finds exactly the contact
    sets that 2^m feasibility problems find: plug2d rows 3 (LP) at 5 tan 10 deg, plug3d 2 x 4
    without symmetry (SOCP; friction a second-order cone in SCIP) at mu 0.65."""
    from instances import plug3d_param
    p, m = _plug(3) if dim == 2 else plug3d_param(2, 4)
    mu = 5 * math.tan(math.radians(10.0)) if dim == 2 else 0.65
    counts = {}
    got = scip_patterns(p, m, mu, counts)
    want = brute_force_patterns(p, m, mu)
    assert got == want and len(want) >= 2
    assert counts["milp_solves"] == len(want) + 1 and "undecided" not in counts


@pytest.mark.skipif(importlib.util.find_spec("cdd") is None, reason="pycddlib not installed (bench extra)")
@pytest.mark.parametrize("number_type", ["fraction", "float"])
def test_cdd_generators_of_a_quadrant(number_type):
    gens, lin, version = cdd_generators([[0, 1, 0], [0, 0, 1]], number_type)
    rays = sorted(tuple(float(v) for v in g[1:]) for g in gens if float(g[0]) == 0.0)
    assert not lin and version.startswith("pycddlib")
    assert [tuple(np.sign(r)) for r in rays] == [(0.0, 1.0), (1.0, 0.0)]
