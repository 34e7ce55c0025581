"""scripts/bench_lp_screens.py on plug3d 2 x 4 (m = 8) at mu = 0.65, per LP engine (bench
extras; skipped where it does not import): the pyramid LPs agree with the SOCP route
(feasibility.decide on rows.pattern_rows) on every partition — an inscribed pyramid's
verified point proves feasibility, a circumscribed pyramid's infeasibility proves
infeasibility, and with 64 facets every partition is decided one way or the other — and
the screened trees find the product's patterns with fewer SOCPs."""
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "scripts"))
import bench_lp_screens  # noqa: E402
from bench_search_3d import scene  # noqa: E402
from instances import pyramid_agreement  # noqa: E402

from hpcwedge.contact.build import contact_problem
from hpcwedge.contact.problem import parametrize

MU = 0.65
ENGINES = [pytest.param(e, marks=pytest.mark.skipif(not bench_lp_screens.available(e),
                                                    reason=f"LP engine {e} not installed (bench extras)"))
           for e in ("clp", "highs")]


@pytest.fixture(scope="module")
def body():
    prob = contact_problem(scene("enumerate", 2, 4))
    return parametrize(prob), prob.m


@pytest.mark.parametrize("form", ["facets", "generators"])
@pytest.mark.parametrize("engine", ENGINES)
def test_pyramid_lps_agree_with_the_socp(body, engine, form):
    param, m = body
    inner = bench_lp_screens.PyramidLP(param, m, MU, 64, True, engine, form)
    outer = bench_lp_screens.PyramidLP(param, m, MU, 64, False, engine, form)
    pyramid_agreement(param, m, MU, inner.run, outer.run)


@pytest.mark.parametrize("engine", ENGINES)
def test_screened_trees_find_the_products_patterns_with_fewer_socps(body, engine):
    param, m = body
    base = bench_lp_screens.screened_tree(param, m, MU, "none", "", 8)
    assert base["socps"] == base["tree_nodes"] and base["lps"] == 0 and base["patterns"] > 0
    outer = bench_lp_screens.screened_tree(param, m, MU, "outer", engine, 8)
    both = bench_lp_screens.screened_tree(param, m, MU, "both", engine, 8)
    for r in (outer, both):
        assert r["hash"] == base["hash"] and r["patterns"] == base["patterns"]
        assert r["lps"] > 0 and r["outer_infeasible"] > 0
    assert outer["socps"] < base["socps"] and both["socps"] < outer["socps"]
    assert both["inner_feasible"] > 0


@pytest.mark.parametrize("engine", ENGINES)
def test_screens_from_a_depth_on_leave_the_tree_above_it_alone(body, engine):
    param, m = body
    base = bench_lp_screens.screened_tree(param, m, MU, "none", "", 8)
    below = bench_lp_screens.screened_tree(param, m, MU, "both", engine, 8, "generators", from_depth=m + 1)
    assert (below["lps"], below["tree_nodes"], below["socps"]) == (0, base["tree_nodes"], base["socps"])
    # from half the depth on: the screens run (how many LPs against screens everywhere
    # depends on the vertices each engine returns: 219 against 220 with CLP here)
    deep = bench_lp_screens.screened_tree(param, m, MU, "both", engine, 8, "generators", from_depth=m // 2)
    assert deep["hash"] == base["hash"] and deep["lps"] > 0 and deep["inner_feasible"] > 0
