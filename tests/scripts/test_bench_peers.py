"""scripts/bench_peers.py's peers on small scenes (m <= 6, a few seconds in all): the peers
agree with our engine where they must, the float peer's failure is detected as such, and
the verdicts (judge) flag a disagreement. The references are independent routes: our DD
against cddlib's full DD + filter + cliques, and the rays' implied patterns (SPEC §2)
against one LP per sign pattern."""
import importlib.util
import math
import os
import sys

import pytest

#: the cddlib peers need pycddlib (the bench extra, `make bench` installs it); the brute
#: force and the verdicts run everywhere
needs_cdd = pytest.mark.skipif(importlib.util.find_spec("cdd") is None,
                               reason="pycddlib not installed (make setup-bench)")
sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "scripts"))
import bench_2d  # noqa: E402
import bench_peers  # noqa: E402

PLUG = {"model": {"kind": "plug2d", "rows": 2, "cols": 3, "taper_deg": 10.0}}


@needs_cdd
@pytest.mark.parametrize("number_type", ["fraction", "float"])
def test_cdd_peer_matches_ours_on_plug_m4(number_type):
    ours = bench_2d.enumerate_ours(PLUG, 0.65, exact=False)
    peer = bench_2d.peer_cdd(bench_peers._problem(PLUG, 0.65), 0.65, number_type)
    assert (peer["n_wedged_rays"], peer["n_cones"]) == (ours["n_wedged_rays"], ours["n_cones"]) == (8, 1)
    assert peer["fingerprint"] == ours["fingerprint"]
    assert peer["n_extreme_rays_P"] > peer["n_complementary"]       # the filter dropped rays


@pytest.mark.parametrize("spec, mu", [
    (PLUG, 0.65),
    ({"model": {"kind": "vgroove_bar", "theta_deg": 20.0, "EA": 2.0, "eps": 0.1}}, 1.0),
    ({"model": {"kind": "plug2d", "rows": 3, "cols": 3, "taper_deg": 3.0}}, 0.2),
])
def test_brute_force_patterns_equal_implied_patterns(spec, mu):
    exact = bench_peers.worker_2d("ours_exact", spec, mu)
    brute = bench_peers.worker_2d("brute_lp", spec, mu)
    assert brute["lps"] == 2 ** exact["m"]
    assert brute["patterns"] == exact["patterns"] and exact["patterns"]


@needs_cdd
def test_float_peer_aborts_on_small_taper():
    """cddlib's float arithmetic gives up on the free plug at taper 0.1 deg; ours does not."""
    spec = {"model": {"kind": "plug2d", "rows": 3, "cols": 3, "taper_deg": 0.1}}
    mu = 1.5 * math.tan(math.radians(0.1))
    problem = bench_peers._problem(spec, mu)
    with pytest.raises(RuntimeError, match="[Ii]nconsisten"):
        bench_2d.peer_cdd(problem, mu, "float")
    ours = bench_2d.enumerate_ours(spec, mu, exact=False)
    assert ours["fingerprint"] == bench_2d.enumerate_ours(spec, mu, exact=True)["fingerprint"]


def _rec(engine, status="ok", seconds=1.0, rays=8, fp="a"):
    return {"section": "2d", "scene": "s", "engine": engine, "status": status, "seconds": seconds,
            "wall": seconds, "n_wedged_rays": rays, "n_cones": 1, "fingerprint": fp, "patterns": [3]}


def test_judge_flags_disagreement_but_not_the_float_peer():
    recs = [_rec("ours_float", seconds=0.5), _rec("ours_exact"), _rec("cdd_exact", seconds=50.0),
            _rec("cdd_float", rays=9, fp="b"), _rec("brute_lp")]
    assert bench_peers.judge(recs) == []
    assert recs[3]["agree"].startswith("miscount") and recs[2]["ratio"] == "100"
    recs[2]["n_wedged_rays"] = 7                  # the exact peer against the exact reference
    recs[4]["patterns"] = [1, 3]
    mism = bench_peers.judge(recs)
    assert len(mism) == 2 and recs[2]["agree"] == "no" and recs[4]["agree"] == "no"
    recs[3]["status"] = "error"
    bench_peers.judge(recs)
    assert recs[3]["agree"].startswith("aborted (expected")
