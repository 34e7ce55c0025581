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
