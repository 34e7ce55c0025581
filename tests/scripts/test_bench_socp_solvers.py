"""scripts/bench_socp_solvers.py on plug3d 2 x 4 (m = 8) at mu = 0.65: Clarabel re-solving the
tree's recorded SOCPs gives the tree's statuses with every feasible point verified; no point of a
problem the tree proved infeasible verifies, whichever engine returned it (QOCO, bench extras:
skipped where it does not import, has no infeasibility detection)."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "scripts"))
import bench_socp_solvers  # noqa: E402


def test_engines_on_the_tree_socps(tmp_path):
    row = bench_socp_solvers.study(2, 4, 0.65, sample=400, repeat=1)
    assert row["m"] == 8 and row["sampled"] == row["socps"] > 100
    by = row["engines"]["clarabel"]["by_tree_status"]
    assert set(by) == {"Solved", "PrimalInfeasible"}
    assert by["Solved"]["statuses"] == {"Solved": by["Solved"]["count"]}
    assert by["Solved"]["points_verified"] == by["Solved"]["count"]
    assert by["PrimalInfeasible"]["statuses"] == {"PrimalInfeasible": by["PrimalInfeasible"]["count"]}
    for name, e in row["engines"].items():
        if e != "missing":
            assert e["by_tree_status"]["PrimalInfeasible"]["points_verified"] == 0, name
    if bench_socp_solvers.available():
        assert row["engines"]["qoco"]["by_tree_status"]["Solved"]["points_verified"] > 0


def test_ldl_study_solves_alike_with_either_ldl_solver():
    """--ldl on plug3d 2 x 4: QDLDL and faer reach the same statuses and iterations on every
    recorded SOCP, and Clarabel's "auto" returns the bits of one of them on all of them."""
    row = bench_socp_solvers.ldl_study(2, 4, 0.3, sample=30, repeat=1)
    assert row["m"] == 8 and row["sampled"] == 30
    solvers = row["solvers"]
    assert set(solvers) == {"auto", "qdldl", "faer"}
    assert solvers["qdldl"]["statuses"] == solvers["faer"]["statuses"] == solvers["auto"]["statuses"]
    assert set(solvers["auto"]["statuses"]) <= {"Solved", "PrimalInfeasible"}
    assert max(row["auto_same_bits_as"].values()) == 30
    assert row["qdldl_over_faer"] > 0
