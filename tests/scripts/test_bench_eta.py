"""scripts/bench_eta.py: it reads the engine's own progress lines, its summary counts right, and
one short case end to end (a real run, its lines timed against the job's end)."""
import os
import sys

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "scripts"))
import bench_eta  # noqa: E402


@pytest.mark.parametrize("line, share, told", [
    ("global_patterns: 12 tasks done, 63 pending, 0 running, 2 patterns found, 9778 tree nodes, 75.2 % of the "
     "tree decided (1 rank(s), 36 s, about 11 s left)", 0.752, 11.0),
    ("patterns: 47 tasks done, 259 pending, 1 running, 1 pattern representatives found, 43935 tree nodes, 92.2 % of "
     "the tree decided (1 rank(s), 356 s, about 7 min left; a task running for 10 s)", 0.922, 420.0),
    ("patterns: 1 tasks done, 12 pending, 1 running, 4 patterns found, 64 tree nodes, 0.0229 % of the tree decided "
     "(1 rank(s), 1 s; a task running for 0 s)", 0.000229, None),
    ("patterns: 3 tasks done, 0 pending, 0 running, 4 patterns found, 64 tree nodes, 50 % of the tree decided "
     "(3 rank(s), 9000 s, about 2 h left)", 0.5, 7200.0),
])
def test_the_engines_lines_are_read(line, share, told):
    hit = bench_eta.LINE.match(line)
    assert hit is not None
    assert float(hit["share"]) / 100 == pytest.approx(share)
    got = None if hit["left"] is None else float(hit["left"]) * bench_eta.UNIT[hit["unit"]]
    assert got == told


def test_summary_counts():
    rows = [{"told_s": t, "left_s": left} for t, left in ((10, 10), (30, 10), (4, 10), (None, 5), (1, 0))]
    s = bench_eta.summary(rows, "told_s")
    assert s == {"lines": 3, "median_ratio": 1.0, "within_2x": round(1 / 3, 3), "below_half": round(1 / 3, 3)}
    assert bench_eta.summary([], "told_s") == {"lines": 0}


def test_a_short_case_end_to_end():
    """The curved neck m = 32 (global mu^c, a few seconds) with a line every second: its tree
    job's lines come in order, the time left falls to 0 at the job's end, and every line with a
    told time has a share of at least 1 % (progress.SHARE_GROWTH_MIN)."""
    rows = bench_eta.run_case("neck-4x8-global", 1.0)
    assert len(rows) >= 3 and {r["job"] for r in rows} == {"global_patterns"}
    elapsed = [r["elapsed_s"] for r in rows]
    assert elapsed == sorted(elapsed)
    assert all(0 <= r["left_s"] <= r["job_s"] and r["elapsed_s"] + r["left_s"] == pytest.approx(r["job_s"], abs=0.02)
               for r in rows)
    assert all(r["share"] >= 0.01 for r in rows if r["told_s"] is not None)
    assert any(r["told_s"] is not None for r in rows)
