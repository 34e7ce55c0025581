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


def test_neck_settling_tree_and_minimal_cores():
    """The curved neck 2 x 5 (m = 10), mu^c asked of `hpcwedge run` (test_tree.py's brute-force
    value): the settling tree at mu^c (1 + 1e-9) finds brute force's patterns there; every
    infeasible node shrinks to a core of its own fixings that no feasible pattern (brute force
    over all 1,024) extends, and that is minimal: without any one fixing it is feasible. The tree
    again from each first branching node: the rule's own first choice gives the same tree."""
    import numpy as np

    from hpcwedge.solvers.feasibility import decide
    from hpcwedge.solvers.rows import Status, pattern_rows
    from instances import curved_neck, scene_param

    rec = bench_tree_pruning.measure(2, 5, None, 0, neck=True, cores=1000, roots=True)
    p, m = scene_param(curved_neck(2, 5, 0))
    assert m == 10 and abs(rec["mu"] - 0.4593401459998697 * (1 + 1e-9)) <= 1e-9 * 0.46
    feasible = brute_3d(p, m, rec["mu"])
    assert rec["finished"] and {c for c, _ in rec["found"]} == feasible
    c = rec["counts"]
    assert len(rec["cores"]) == c["infeasible"] > 0
    assert sum(f + i for f, i in rec["feasible_infeasible_by_depth"].values()) == c["feasible"] + c["infeasible"]

    def infeasible(contact, gap):
        zu, zr = np.zeros(m, bool), np.zeros(m, bool)
        zu[contact], zr[gap] = True, True
        return decide(pattern_rows(p, m, zu, zr), rec["mu"]).status == Status.INFEASIBLE

    for core in rec["cores"]:
        cc, cg = core["core_contact"], core["core_gap"]
        assert set(cc) <= set(core["contact"]) and set(cg) <= set(core["gap"])
        assert not any(all(bits >> i & 1 for i in cc) and not any(bits >> i & 1 for i in cg) for bits in feasible)
        assert infeasible(cc, cg)
        assert not any(infeasible([j for j in cc if j != i], cg) for i in cc)
        assert not any(infeasible(cc, [j for j in cg if j != i]) for i in cg)
    by_root = rec["nodes_by_first_branching"]
    assert len(by_root) == m and rec["nodes"] in by_root.values() and min(by_root.values()) > m
    s = rec["core_summary"]
    assert s["least_core"] <= s["mean_core"] <= s["mean_fixings"]


def test_neck_trees_at_fractions_of_mu_c():
    """--fractions: the curved neck 2 x 5's tree at 0.9 and 2 times its mu^c (the value above)
    finds brute force's patterns at that mu: none below mu^c, at 2 mu^c several; each record
    says its fraction and mu."""
    from instances import curved_neck, scene_param

    mu_c = 0.4593401459998697
    p, m = scene_param(curved_neck(2, 5, 0))
    for fraction in (0.9, 2.0):
        rec = bench_tree_pruning.measure(2, 5, mu_c, 0, neck=True, fraction=fraction)
        assert rec["fraction_of_mu_c"] == fraction and rec["mu"] == mu_c * fraction and rec["seconds"] >= 0
        feasible = brute_3d(p, m, rec["mu"])
        assert rec["finished"] and {c for c, _ in rec["found"]} == feasible
        assert (len(feasible) > 1) == (fraction > 1)
