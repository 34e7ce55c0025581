"""scripts/harness.py: a case over its limit is recorded as an overrun (and the script goes on),
a failing case is an error record, records are written as JSON and CSV with the environment,
and a same-answer check that fails is reported."""
import csv
import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "scripts"))
import harness  # noqa: E402

import hpcwedge as hw


def _sleep(seconds):
    time.sleep(seconds)
    return "woke"


def _fail():
    raise ValueError("bad case")


def test_a_call_over_its_limit_is_an_overrun_and_does_not_hang():
    t = time.perf_counter()
    rec = harness.run_call(_sleep, 60, limit=0.5)
    assert rec["status"] == harness.OVERRUN == "timeout" and rec["seconds"] == 0.5   # the word docs_pages reads
    assert time.perf_counter() - t < 30


def _sleep_in_a_grandchild(path):
    import subprocess
    p = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    with open(path, "w") as f:
        f.write(str(p.pid))
    p.wait()


def test_an_overrun_kills_what_the_case_started(tmp_path):
    path = tmp_path / "pid"
    rec = harness.run_call(_sleep_in_a_grandchild, str(path), limit=3)
    assert rec["status"] == harness.OVERRUN
    pid = int(path.read_text())
    for _ in range(100):
        if not _running(pid):
            break
        time.sleep(0.1)
    else:
        raise AssertionError(f"process {pid} of an overrun case still runs")


def _running(pid: int) -> bool:
    """pid exists and is not a zombie (a killed orphan waits for whoever reaps it)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_a_call_within_its_limit_returns_its_value_and_times():
    rec = harness.run_call(_sleep, 0.01, limit=30)
    assert rec["status"] == harness.OK and rec["value"] == "woke"
    assert 0.01 <= rec["seconds"] < 30 and rec["cpu_seconds"] >= 0


def test_a_failing_call_is_an_error_record():
    rec = harness.run_call(_fail, limit=30)
    assert rec["status"] == harness.ERROR and rec["error"] == "ValueError: bad case"


def test_a_command_over_its_limit_is_an_overrun():
    rec = harness.run_command(harness.python_command("-c", "import time; time.sleep(60)"), limit=0.5)
    assert rec["status"] == harness.OVERRUN and rec["returncode"] is None
    rec = harness.run_command(harness.python_command("-c", "import sys; sys.exit(3)"), limit=30)
    assert rec["status"] == harness.ERROR and rec["returncode"] == 3


def test_records_are_written_as_json_and_csv_with_the_environment(tmp_path):
    records = [{"case": "a", "seconds": 1.5, "statuses": {"Solved": 2}}, {"case": "b", "extra": None}]
    js, cs = harness.write_records(str(tmp_path / "sub" / "bench"), records, extra={"scene": "s"})
    with open(js) as f:
        d = json.load(f)
    assert d["records"] == records and d["scene"] == "s" and "python" in json.dumps(d["environment"])
    with open(cs) as f:
        rows = list(csv.reader(f))
    assert rows == [["case", "seconds", "statuses", "extra"], ["a", "1.5", '{"Solved": 2}', ""],
                    ["b", "", "", ""]]


def test_a_failing_same_answer_check_is_reported(capsys):
    checks = harness.Checks(rel_tol=1e-9)
    want = {"runs": [{"n_patterns": 3, "patterns_hash": harness.pattern_hash([[0, 1], [2]])}], "mu_c": 0.5}
    same = {"runs": [{"n_patterns": 3, "patterns_hash": harness.pattern_hash([[2], [1, 0]])}],
            "mu_c": 0.5 * (1 + 1e-12)}
    assert checks.compare("reordered", same, want) and checks.ok and checks.exit_status() == 0
    other = {"runs": [{"n_patterns": 4, "patterns_hash": harness.pattern_hash([[0, 1], [3]])}], "mu_c": 0.5001}
    assert not checks.compare("engine b", other, want)
    assert not checks.ok and checks.exit_status() == 1
    err = capsys.readouterr().err
    assert "engine b" in err and "n_patterns: 4 != 3" in err and "mu_c: 0.5001 != 0.5" in err
    assert "patterns_hash" in err and "1 same-answer check(s) failed" in err


def test_answer_of_a_result_counts_and_hashes_its_patterns():
    r = hw.solve(hw.Scene.builtin("plug2d", rows=3))
    a = harness.answer(r)
    assert a["runs"][0]["n_wedged_rays"] == 44 and a["mu_c"] == r.mu_c
    assert a["runs"][0]["cones_hash"] == harness.pattern_hash(
        tuple(c.zero_u) + tuple(-1 - i for i in c.zero_r) for c in r.runs[0].cones)
    assert harness.answer(r.to_dict()) == a
