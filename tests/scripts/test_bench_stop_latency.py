"""scripts/bench_stop_latency.py: its scenes parse, one small case end to end (real runs,
real SIGTERM, a resume), and the committed record's claims."""
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "scripts"))
import bench_stop_latency  # noqa: E402

RESULTS = os.path.join(HERE, "..", "..", "results")


def test_every_case_is_a_scene_of_a_global_run_or_a_long_condensation(tmp_path):
    from hpcwedge.scene.parse import load_scene
    for name, (dim, model, ranks, run_table) in bench_stop_latency.CASES.items():
        path = tmp_path / f"{name}.toml"
        path.write_text(bench_stop_latency.scene_text(name, dim, model, run_table))
        scene = load_scene(str(path))
        assert scene.dim == dim and not scene.symmetry, name
        if model is bench_stop_latency.CONDENSED:
            assert scene.mu_c == "none" and scene.enumerate, name
            assert scene.condense == run_table.get("condense", "auto"), name
        else:
            assert scene.mu_c == "global" and scene.enumerate is False and ranks is None, name


def test_a_small_case_stops_with_75_and_resumes_to_the_same_mu_c(tmp_path, monkeypatch):
    """plug3d 2 x 6 (global mu^c, a few seconds): every stop exits 75 and the resume of the last
    stopped run writes the uninterrupted run's mu^c."""
    monkeypatch.setitem(bench_stop_latency.CASES, "small", (3, {"kind": "plug3d", "levels": 2, "ring": 6}, None, {}))
    rec = bench_stop_latency.measure("small", 3, str(tmp_path))
    assert rec["full_exit"] == 0 and rec["mu_c"] is not None
    assert rec["stops"] and rec["all_served"] and rec["exit_75"] >= 1, rec   # a stop at start-up exits 75 too
    assert rec["resume_exit"] == 0 and rec["resume_same"], rec


def test_a_small_case_through_wedge_mpirun_stops_with_75_and_resumes(tmp_path, monkeypatch):
    """The same through jobs/wedge-mpirun.sh -n 2 (SIGTERM to the script, which passes it to the
    ranks): 75, and the resume (the script resumes by default) gives the same mu^c."""
    monkeypatch.setitem(bench_stop_latency.CASES, "small", (3, {"kind": "plug3d", "levels": 2, "ring": 6}, 2, {}))
    rec = bench_stop_latency.measure("small", 2, str(tmp_path))
    assert rec["ranks"] == 2 and rec["full_exit"] == 0 and rec["mu_c"] is not None, rec
    assert rec["stops"] and rec["all_served"], rec
    assert rec["resume_exit"] == 0 and rec["resume_same"], rec


def test_a_run_of_some_cases_keeps_the_others_records(tmp_path):
    path = tmp_path / "r.json"
    assert bench_stop_latency.kept_records(str(path), ["plug2d-r320"]) == []
    path.write_text(json.dumps({"records": [{"case": "plug2d-r320"}, {"case": "block2d-r159"}, {"case": "gone"}]}))
    assert bench_stop_latency.kept_records(str(path), ["plug2d-r320"]) == [{"case": "block2d-r159"}]


def test_the_committed_record_serves_every_stop_within_2_s_and_resumes_to_the_same_mu_c():
    with open(os.path.join(RESULTS, "bench_stop_latency.json")) as f:
        records = json.load(f)["records"]
    assert {r["case"] for r in records} == set(bench_stop_latency.CASES)
    for r in records:
        assert r["stops"] and r["all_served"] and r["resume_same"] and r["over_target"] == 0, r["case"]
