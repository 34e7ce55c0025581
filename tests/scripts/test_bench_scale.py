"""scripts/bench_scale.py's bound of the floor's job: a free one-level schedule (no master
cost, the finest tasks) keeps one worker busy all the time, and no fitted master beats it."""
import json
import os
import sys

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "scripts"))
import bench_scale  # noqa: E402
from scale_workload import load_durations  # noqa: E402

from hpcwedge.parallel.model import MasterCosts  # noqa: E402

RESULTS = os.path.join(HERE, "..", "..", "results")


@pytest.fixture(scope="module")
def durations():
    return load_durations(os.path.join(RESULTS, "task_durations.json"))


@pytest.mark.parametrize("workload", bench_scale.WORKLOADS)
def test_a_free_schedule_keeps_one_worker_always_busy(durations, workload):
    assert bench_scale.free_schedule(workload, durations, 0, ranks=2, worker_seconds=30.0) == pytest.approx(1.0)


@pytest.mark.parametrize("workload", bench_scale.WORKLOADS)
def test_no_fitted_master_beats_the_free_schedule(durations, workload):
    with open(os.path.join(RESULTS, "bench_scale.json")) as f:
        costs = MasterCosts(**json.load(f)["costs_predicting"][workload])
    free = bench_scale.free_schedule(workload, durations, 1, ranks=33, worker_seconds=120.0)
    engine = bench_scale.model_run(workload, durations, 33, 120.0, 1, costs).efficiency
    assert engine <= free + 1e-9 and free < 1.0
