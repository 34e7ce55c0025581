"""scripts/bench_tree_pruning.py on a small body: the recorded tree is the product's, its
nogoods never hold at a feasible node, and at mu = 1 (many patterns) a global store prunes."""
import os
import sys

from instances import brute_3d, plug3d_param

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "scripts"))
import bench_tree_pruning  # noqa: E402


def test_nogoods_hold_only_at_infeasible_nodes():
    """plug3d 2 x 4 at mu 0.2 (1.13 mu^c) and 1: the recorded tree finds brute force's
    pattern count; every SOCP is counted feasible or infeasible, each infeasible one has a
    certificate, and no nogood learnt before a feasible node holds there; at mu = 1 (77
    patterns) some hold before infeasible ones (12 of 84 when measured)."""
    p, m = plug3d_param(2, 4)
    for mu in (0.2, 1.0):
        rec = bench_tree_pruning.measure(2, 4, mu, 0)
        c = rec["counts"]
        assert rec["finished"] and rec["patterns"] == len(brute_3d(p, m, mu))
        assert c["feasible"] + c["infeasible"] == rec["socps"]
        assert sum(rec["nogood_sizes_contact_gap"].values()) == c["infeasible"]
        assert c["nogood_held_at_feasible"] == 0 and c["nogood_total"] < c["fixed_total"]
        assert mu < 1.0 or c["nogood_would_prune"] > 0
