"""scripts/bench_condense_routes.py: a small refinement end to end (the three routes, each in its
own interpreter, the same K_local bits), and the committed record's claims."""
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "scripts"))
import bench_condense_routes  # noqa: E402

RESULTS = os.path.join(HERE, "..", "..", "results")


def test_the_three_routes_give_the_same_bits_on_a_small_body():
    recs = bench_condense_routes.measure(4, 1)
    assert [r["route"] for r in recs] == list(bench_condense_routes.ROUTES)
    assert all(r["same_bits"] and r["n_dofs"] == recs[0]["n_dofs"] for r in recs), recs
    assert recs[0]["over_here_s"] == 0.0


def test_the_committed_record_has_every_route_with_the_same_bits():
    with open(os.path.join(RESULTS, "bench_condense_routes.json")) as f:
        doc = json.load(f)
    by_refine: dict = {}
    for r in doc["records"]:
        by_refine.setdefault(r["refine"], set()).add(r["route"])
        assert r["same_bits"], r
    assert by_refine and all(routes == set(bench_condense_routes.ROUTES) for routes in by_refine.values())
