"""scripts/bench_flags.py's pair on plug3d 2 x 4 (m = 8) at mu = 0.65 without symmetry, each
solve in its own process as `make bench` runs it: screens off and on find the same patterns
(13 measured), the screened tree solves fewer SOCPs and the LPs are counted on its row only."""
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "scripts"))
import bench_flags  # noqa: E402

from hpcwedge.solvers.screens import screens_available


@pytest.mark.skipif(not screens_available(), reason="CLP (cylp) not installed")
def test_screens_pair_same_patterns_fewer_socps():
    off, on = bench_flags.run_case(2, 4, 0.65, False, 300.0)
    assert off["status"] == on["status"] == "ok" and off["screens"] is False and on["screens"] is True
    assert on["same"] is True and on["patterns"] == off["patterns"] > 0
    assert on["socps"] < off["socps"] and on["socps_ratio"] == on["socps"] / off["socps"]
    assert off["lps"] == 0 < on["lps"] and on["cpu_ratio"] > 0
