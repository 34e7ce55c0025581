"""scripts/bench_matrix.py on a small body under the real mpirun -n 2: with run.condense =
"distributed" no rank loads the whole PETSc binary matrix (each MatLoads its rows), and the
condensed stiffness is the built-in route's (block2d assembled by its own elements)."""
import json
import os
import sys

import pytest
from mpi_helpers import needs_mpirun

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "scripts"))
import bench_matrix  # noqa: E402


@pytest.mark.mpi
@needs_mpirun
def test_distributed_matrix_rows_only_and_the_builtin_answer(tmp_path, monkeypatch):
    monkeypatch.setattr(bench_matrix, "OUT", str(tmp_path))
    monkeypatch.setattr(sys, "argv", ["bench_matrix.py", "--refine", "6"])
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    bench_matrix.main()
    res = json.load(open(tmp_path / "bench_matrix.json"))
    routes = {r["route"]: r for r in res["rows"]}
    assert routes["matrix"]["whole_loads_per_rank"] == [0, 0]
    assert routes["matrix"]["n_dofs"] == routes["builtin"]["n_dofs"] == 2 * (5 * 6 + 1) * (2 * 6 + 1)
    assert res["rel_diff_matrix_vs_builtin"] <= 1e-12
    assert len(routes["matrix"]["maxrss_mb_per_rank"]) == 2
