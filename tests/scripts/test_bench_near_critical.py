"""scripts/bench_near_critical.py's rows on small bodies: the probe of a cut enumeration counts
what the uninterrupted `hpcwedge run` route counts when it finishes, and a global row on a
curved neck (m = 10) is certified with the brute force's mu^c (test_tree.py's value)."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "scripts"))
import bench_near_critical  # noqa: E402


def test_probe_counts_what_the_run_counts():
    """plug3d 2 x 5 at mu = 1 (131 patterns): the probe, explored in budgets, finishes with the
    run's nodes, SOCPs and patterns; cut after a fraction of a second it has fewer nodes."""
    run = bench_near_critical.worker("enumerate", 2, 5, 1.0)
    probe = bench_near_critical.probe(2, 5, 1.0, 600.0)
    assert probe["finished"] and run["patterns"] == probe["patterns"] == 131 and probe["decided"] == 1.0
    assert (probe["nodes"], probe["socps"]) == (run["nodes"], run["socps"])
    assert run["socps_per_pattern"] == run["socps"] / 131
    cut = bench_near_critical.probe(2, 5, 1.0, 0.05)
    assert not cut["finished"] and 0 < cut["nodes"] < run["nodes"] and 0.0 <= cut["decided"] < 1.0


def test_global_row_on_a_curved_neck():
    out = bench_near_critical.worker("global", 2, 5, 0.0)
    assert out["m"] == 10 and out["certified"] is True and out["undecided"] == 0
    assert abs(out["mu_c"] - 0.4593401459998697) <= 1e-9 * 0.46


def test_the_peers_scene_file_is_the_global_rows_scene():
    """--peers hands the peers' script a scene file (_neck_toml): it parses to the scene our
    global row runs (neck_scene), the same condensed problem to the bit."""
    import tomllib

    import numpy as np

    from hpcwedge.contact.build import contact_problem
    from hpcwedge.scene.parse import parse_scene
    ours = contact_problem(bench_near_critical.neck_scene(2, 5))
    theirs = contact_problem(parse_scene(tomllib.loads(bench_near_critical._neck_toml(2, 5))))
    assert theirs.m == ours.m == 10
    assert np.array_equal(theirs.K, ours.K) and np.array_equal(theirs.N, ours.N)


def test_a_peer_row_brackets_the_certified_mu_c_of_a_small_neck(tmp_path):
    """--peers: SCIP (bench extra) on the m = 10 neck in its own process: its row has the
    bisection's bracket and its error against our certified mu^c, which its bracket holds to
    SCIP's tolerance."""
    import argparse
    import importlib.util

    import pytest
    if importlib.util.find_spec("pyscipopt") is None:
        pytest.skip("pyscipopt not installed (bench extra)")
    ours = 0.4593401459998697                   # test_global_row_on_a_curved_neck's value
    records = []
    row = bench_near_critical._run_peer(argparse.Namespace(label="t", limit=120.0), records, "scip", 2, 5, ours)
    assert records == [row] and row["engine"] == "scip" and row["status"] == "ok", row
    assert row["mu_lo"] < row["mu_c"] == row["mu_hi"] and abs(row["rel_error"]) <= 1e-4
    assert row["rel_error"] == (row["mu_c"] - ours) / ours
