"""scripts/bench_growth.py's 3D points, each in its own subprocess as `make bench` runs
them: the branch and bound with and without the symmetry and the brute force (one SOCP
per partition, the independent route) find the same pattern set on plug3d ring 4
(m = 8), and the stage profile is filled (the LP wrapper once looked for a module
attribute that the lazy import had removed: every 3D point errored)."""
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "scripts"))
import bench_growth   # noqa: E402


@pytest.fixture(scope="module")
def points():
    return {e: bench_growth.run_point(3, e, 4, 120.0) for e in ("bnb_sym", "bnb", "brute")}


def test_3d_points_agree_with_brute_force(points):
    for rec in points.values():
        assert rec["status"] == "ok", rec.get("error")
    digests = {rec["patterns_digest"] for rec in points.values()}
    assert len(digests) == 1 and points["brute"]["socps"] == 2 ** 8
    assert points["bnb_sym"]["patterns"] == points["brute"]["patterns"] > 0


def test_3d_stage_profile(points):
    st = points["bnb"]["stages"]
    assert {"setup", "socp", "lp", "cores", "other", "expand"} <= set(st)
    assert st["socp"] > 0 and st["socp"] <= points["bnb"]["seconds"]
