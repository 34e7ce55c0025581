"""3D numerical stress (scripts/stress_3d.py): plug3d at SPEC's smallest stressed taper,
0.1 deg, through the whole pipeline. Before the tree's SOCP was balanced there (socp.
reaction_socp), plug3d 2 x 4's enumeration at 1.5 tan(taper) sent 17 of its 89 SOCPs down
the ladder and ran 10 pyramid LPs; the global mu^c was already within 1e-11 of tan(taper)."""
import importlib.util
import math
import os

import pytest

_spec = importlib.util.spec_from_file_location(
    "stress_3d", os.path.join(os.path.dirname(__file__), "..", "scripts", "stress_3d.py"))
stress_3d = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(stress_3d)


@pytest.mark.parametrize("kind", ["enumerate", "global"])
def test_small_taper_runs_are_decided_and_accurate(kind):
    """plug3d 2 x 4 at 0.1 deg: every SOCP of the tree decided by Clarabel's first attempt
    (enumeration) and no tree node undecided, no pyramid LP in the enumeration, and the
    global mu^c polished and within 1e-9 of tan(taper), the analytic value."""
    r = stress_3d.worker(kind, 2, 4, 0.1)
    want = math.tan(math.radians(0.1))
    assert r["m"] == 8 and r["undecided"] == 0 and r["mu_c_unpolished"] == 0
    assert abs(r["mu_c"] - want) <= 1e-9 * want
    if kind == "enumerate":
        assert r["patterns"] == 1 and r["first_attempt_share"] == 1.0 and r["lps"] == 0
