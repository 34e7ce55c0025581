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
