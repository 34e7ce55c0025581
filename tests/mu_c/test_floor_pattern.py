"""floor_pattern (a pattern at the certified lower bound, by pivots on the bound's
certificate) against HiGHS on the pattern's LP, brute force over every full pattern, and the
tree route's global mu^c."""
from __future__ import annotations

import math

import numpy as np
from instances import plug3d_param, random_problem, scene_param

from hpcwedge.contact.problem import parametrize
from hpcwedge.mu_c.critical import mu_critical
from hpcwedge.mu_c.floor_pattern import floor_pattern
from hpcwedge.mu_c.global_search import global_mu_critical
from hpcwedge.mu_c.lower_bound import rigid_bound
from hpcwedge.patterns.tree import BnBStats
from hpcwedge.reference import brute_force_patterns
from hpcwedge.solvers.lp import lp_feasible
from hpcwedge.solvers.rows import Status, pattern_rows

MU_HI = 10.0


def thin_block():
    """block2d rows 6, cols 1, taper 30 deg (m = 14): elements 3.5 times wider than high.
    Its all-sliding state (every reaction on the cone's edge, horizontal) pulls at the two
    top corners (r_n = -4 % of the largest), as block2d rows 159 does at 10 deg."""
    return scene_param({"name": "thin", "dim": 2, "friction": {"mu": [1.0]},
                        "model": {"kind": "block2d", "rows": 6, "cols": 1, "taper_deg": 30.0}})


def feasible(p, m: int, contact: np.ndarray, mu: float) -> bool:
    """Is the full pattern (contact, the rest gaps) feasible at mu, by HiGHS's dual simplex?"""
    status, _ = lp_feasible(pattern_rows(p, m, contact, ~contact), mu)
    assert status != Status.UNDECIDED
    return status == Status.FEASIBLE


def test_thin_block_opens_its_top_corners_and_meets_tan_taper():
    """The pivots open both top corners (nodes 6 and 13) in one step; HiGHS finds that
    pattern feasible just above tan 30 deg, and neither the all-contact pattern nor one with
    a single corner open; its certified mu^c is tan 30 deg to 1e-9."""
    p, m = thin_block()
    floor, _ = rigid_bound(p, m, MU_HI)
    want = math.tan(math.radians(30.0))
    assert abs(floor - want) <= 1e-9 * want
    found, pivots = floor_pattern(p, m, floor)
    assert found is not None and pivots == 1
    zero_u, zero_r, _ = found
    assert sorted(np.flatnonzero(zero_r)) == [6, 13] and np.array_equal(zero_u, ~zero_r)
    top = floor * (1 + 1e-7)
    assert feasible(p, m, zero_u, top)
    for opened in ([], [6], [13]):
        contact = np.ones(m, bool)
        contact[opened] = False
        assert not feasible(p, m, contact, top), opened
    r = mu_critical(p, m, zero_u, zero_r, mu_max=MU_HI)
    assert abs(r.mu_c - want) <= 1e-9 * want


def test_thin_block_global_mu_c_by_the_floor_pattern_equals_the_tree_route():
    """The MILP route (which asks the floor pattern first) ends at the bound without a MILP,
    certified; the tree route without the bound (every pattern near the answer settled)
    finds the same value."""
    p, m = thin_block()
    st = BnBStats()
    mu, status = global_mu_critical(p, m, MU_HI, route="milp", stats=st)
    tree, tree_status = global_mu_critical(p, m, MU_HI, route="tree", bound=False)
    assert status == tree_status == "found"
    assert abs(mu - tree) <= 1e-9 * tree
    assert st.statuses.get("floor_pattern") == 1 and st.extra.get("bound_certified") == 1
    assert st.extra.get("milp_solves", 0) == 0


def test_a_floor_pattern_is_one_brute_force_finds_feasible_at_the_floor():
    """Random free 2D bodies (m = 5, twelve seeds): a pattern found is among the full patterns
    that brute force (2^m LPs) finds feasible just above the floor; where brute force finds
    none the pivots return none. Both kinds occur (seed 310 has a wedge at its floor)."""
    kinds = set()
    for seed in range(12):
        prob = random_problem(np.random.default_rng(300 + seed), 5, True)
        p, m = parametrize(prob), prob.m
        floor, _ = rigid_bound(p, m, MU_HI)
        assert 0 < floor < MU_HI
        found, _ = floor_pattern(p, m, floor)
        at_floor = brute_force_patterns(p, m, floor * (1 + 1e-7))
        if found is None:
            assert at_floor == [], seed
        else:
            bits = sum(1 << i for i in np.flatnonzero(found[0]))
            assert bits in at_floor and np.array_equal(found[1], ~found[0]), seed
        kinds.add(found is not None)
    assert kinds == {True, False}


def test_free_plug3d_floor_pattern_is_all_contact():
    """plug3d 2 x 5 at 10 deg: the all-contact pattern, without a pivot; its certified mu^c
    is tan 10 deg."""
    p, m = plug3d_param(2, 5)
    floor, _ = rigid_bound(p, m, MU_HI)
    found, pivots = floor_pattern(p, m, floor)
    assert found is not None and pivots == 0 and found[0].all()
    r = mu_critical(p, m, found.zero_u, found.zero_r, mu_max=MU_HI)
    assert abs(r.mu_c - math.tan(math.radians(10.0))) <= 1e-9


def test_floor_wedge_is_the_witness_of_its_pattern_just_above_the_floor():
    """thin block: the FloorWedge's x (sum r_n = 1) is the bracket's upper end at floor
    (1 + FLOOR_STEP) without an LP, plain and balanced (a scale), and gives the mu^c of the
    route that asks HiGHS there; a point that does not hold there (x with r_t flipped) is
    counted as failed and the LP decides, to the same value."""
    from hpcwedge.mu_c.global_search import FLOOR_STEP
    p, m = thin_block()
    floor, _ = rigid_bound(p, m, MU_HI)
    found, _ = floor_pattern(p, m, floor)
    assert abs((p.R[:m] @ found.x).sum() - 1.0) < 1e-12
    guess = floor * (1 + FLOOR_STEP)
    for scale in (None, 1.0):
        kw = dict(mu_max=MU_HI, mu_floor=floor, mu_try=guess, scale=scale)
        lp = mu_critical(p, m, found.zero_u, found.zero_r, **kw)
        w = mu_critical(p, m, found.zero_u, found.zero_r, x_try=found.x, **kw)
        assert w.statuses.get("witness_feasible") == 1 and w.solves == lp.solves - 1, (scale, w.statuses)
        assert w.polished and lp.polished and abs(w.mu_c - lp.mu_c) <= 1e-12 * lp.mu_c
        bad = found.x.copy()
        bad[:] = np.linalg.lstsq(p.R, np.concatenate([p.R[:m] @ found.x, -(p.R[m:] @ found.x)]), rcond=None)[0]
        f = mu_critical(p, m, found.zero_u, found.zero_r, x_try=bad, **kw)
        assert f.statuses.get("witness_failed") == 1 and f.solves == lp.solves and f.mu_c == lp.mu_c
