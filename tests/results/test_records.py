"""The records of a solve (results.py, SPEC §4): Run's counts, and SolveStats with its
sub-records as the stats object of the result file, in the file's key order."""
import numpy as np

from hpcwedge.results.record import GlobalRouteStats, Run, SolveStats, SymmetryStats, TreeStats


def test_solve_stats_as_dict_is_the_file_object():
    """SolveStats.as_dict: the fields that are set, in the result file's key order."""
    s = SolveStats()
    assert s.as_dict() == {"dd": [], "lp_solves": 0, "mu_c_polished": 0, "mu_c_unpolished": 0, "lp_undecided": 0}
    s.add(solves=3, undecided=1, polished=1)
    s.add(unpolished=2)
    s.symmetry = SymmetryStats(2)
    s.bnb = TreeStats.of({"solves": 4, "status_optimal": 1}, partitions=8)
    s.numerics = {}
    d = s.as_dict()
    assert list(d) == ["dd", "lp_solves", "mu_c_polished", "mu_c_unpolished", "lp_undecided", "symmetry", "bnb",
                       "numerics"]
    assert (d["lp_solves"], d["lp_undecided"], d["mu_c_polished"], d["mu_c_unpolished"]) == (3, 1, 1, 2)
    assert d["symmetry"] == {"order": 2}
    assert d["bnb"] == {"nodes": 0, "solves": 4, "skipped": 0, "pruned": 0, "undecided": 0, "lps": 0,
                        "partitions": 8}
    s.bnb = GlobalRouteStats(solves=1, nodes=2, route="milp")
    assert list(s.as_dict()["bnb"]) == ["solves", "skipped", "undecided", "nodes", "route", "milp_solves",
                                        "milp_nodes", "pruned", "lps", "unsettled"]


def test_run_counts_are_none_until_asked():
    """Run.n_*: len of the field, None while the scene did not ask for it."""
    run = Run(mu=0.5)
    assert (run.n_wedged_rays, run.n_trivial_rays, run.n_cones, run.n_patterns) == (None, None, None, None)
    run = Run(mu=0.5, rays=np.zeros((3, 4)), trivial_rays=np.zeros((0, 4)), cones=[{}, {}], patterns=[])
    assert (run.n_wedged_rays, run.n_trivial_rays, run.n_cones, run.n_patterns) == (3, 0, 2, 0)


def test_tree_stats_of_counters():
    """TreeStats.of: a patterns job's counters, absent ones 0, and the partitions given."""
    t = TreeStats.of({"nodes": 5, "pruned": 2, "status_optimal": 7}, partitions=16)
    assert t == TreeStats(nodes=5, solves=0, skipped=0, pruned=2, undecided=0, lps=0, partitions=16)
