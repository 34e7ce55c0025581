"""scripts/bench_global_scale.py's cases through the real command line, on small plugs: each
record is the run's own (m as the result has it, the global mu^c tan 10 deg to 1e-9, the
certified bound ending the search), and the case table's m is what the built-ins give."""
import math
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "scripts"))
import bench_global_scale  # noqa: E402


@pytest.mark.parametrize("name,dim,model,m", [("plug3d-2x5", 3, {"kind": "plug3d", "levels": 2, "ring": 5}, 10),
                                              ("plug2d-r4", 2, {"kind": "plug2d", "rows": 4}, 8),
                                              ("block2d-r3", 2, {"kind": "block2d", "rows": 3}, 8)])
def test_a_case_is_the_runs_own_record(tmp_path, name, dim, model, m):
    row = bench_global_scale.run_case(str(tmp_path), name, dim, model, m, 60.0, 120.0)
    assert row["status"] == "ok", row.get("error")
    assert row["m_result"] == m and row["mu_c_status"] == "found"
    assert abs(row["mu_c"] - math.tan(math.radians(10))) <= 1e-9 * row["mu_c"] and row["rel_error"] <= 1e-9
    assert row["bound_certified"] == 1 and row["bound_solves"] >= 1 and row["unsettled"] == 0
    assert 0 < row["condense_seconds"] <= row["program_seconds"] <= row["seconds"]


def test_case_table_m_is_the_builtins():
    """m = levels x ring (plug3d), 2 rows (plug2d), 2 (rows + 1) (block2d): the scene keys'
    documented counts, for every case of the table."""
    rule = {"plug3d": lambda d: d["levels"] * d["ring"], "plug2d": lambda d: 2 * d["rows"],
            "block2d": lambda d: 2 * (d["rows"] + 1)}
    for _, _, model, m, _ in bench_global_scale.CASES + bench_global_scale.QUICK:
        assert rule[model["kind"]](model) == m


def installed(name: str) -> bool:
    import importlib.util
    return importlib.util.find_spec(name) is not None


@pytest.mark.parametrize("peer,package", [("scip", "pyscipopt"), ("gurobi", "gurobipy")])
def test_a_peer_brackets_tan_taper_on_a_small_plug(tmp_path, peer, package):
    """--peers: SCIP and Gurobi (bench extras) on plug2d rows 3 in their own process: the
    bisection's bracket holds tan 10 deg to the peer's tolerance, with its solves and nodes."""
    if not installed(package):
        pytest.skip(f"{package} not installed (bench extra)")
    row = bench_global_scale.run_peer(str(tmp_path), peer, "plug2d-r3", 2, {"kind": "plug2d", "rows": 3}, 6, 120.0)
    assert row["engine"] == peer and row["status"] == "ok", row
    want = math.tan(math.radians(10))
    assert row["mu_lo"] < row["mu_c"] == row["mu_hi"] and row["rel_error"] <= 1e-4
    assert abs(row["mu_c"] - want) <= 1e-4 * want and row["milp_solves"] >= 20 and row["undecided"] == 0
    assert row["n_vars"] == 12 + 6 and row["n_cons"] == 6 * 5 + 1     # x (d = 12) and z; 5 rows a node and sum r_n


def test_gurobi_too_large_is_said_before_the_model_is_built(tmp_path):
    """plug3d 4 x 8 (m = 32): 223 variables with the cones, over the licence's 200: "too
    large" from the size alone (no licence error, no solve)."""
    row = bench_global_scale.run_peer(str(tmp_path), "gurobi", "plug3d-4x8", 3,
                                      {"kind": "plug3d", "levels": 4, "ring": 8}, 32, 120.0)
    if row["status"] == "missing":
        pytest.skip("gurobipy not installed (bench extra)")
    assert row["status"] == "too large" and row["n_vars"] == 223 and row.get("milp_solves") is None, row


def test_a_run_keeps_the_rows_it_does_not_measure(tmp_path):
    """The output keeps its earlier rows of other cases and engines (rows without an engine are
    ours) and replaces those measured again."""
    import json
    base = str(tmp_path / "b")
    with open(base + ".json", "w") as f:
        json.dump({"records": [{"case": "a", "seconds": 1}, {"case": "a", "engine": "scip", "seconds": 2},
                               {"case": "b", "engine": "gurobi", "seconds": 3}]}, f)
    got = bench_global_scale.kept(base, [{"case": "a", "engine": "scip", "seconds": 4}])
    assert [(r["case"], r["engine"], r["seconds"]) for r in got] == [("a", "ours", 1), ("b", "gurobi", 3),
                                                                     ("a", "scip", 4)]
