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


def test_the_model_runs_a_tree_through_hubs_where_the_engine_does(durations):
    """At 257 ranks and more the engine runs a tree through hubs (hub.layout): so does
    model_run, whose workers are then the hubs' workers; a TaskJob stays on one level, and
    hub_workers forces hubs at any rank count (the measured validation runs)."""
    costs = MasterCosts(send_s=1e-4, merge_s=1e-4)
    tree = bench_scale.model_run("subtree", durations, 300, 100.0, 0, costs)
    assert tree.workers == 299 - 10 and tree.task_s > 50.0            # 9 hubs of 32 workers and one of 1
    assert bench_scale.model_run("mu_c", durations, 300, 100.0, 0, costs).workers == 299
    assert bench_scale.model_run("subtree", durations, 33, 30.0, 0, costs, 7).workers == 28
    assert bench_scale.model_run("subtree", durations, 33, 30.0, 0, costs).workers == 32


def test_the_real_grain_is_a_finer_tree_of_the_same_work(durations):
    costs = MasterCosts(send_s=1e-4, merge_s=1e-4)
    coarse = bench_scale.model_run("subtree", durations, 9, 40.0, 0, costs)
    fine = bench_scale.at_grain(1, "subtree", durations, 9, 40.0, 0, costs)
    assert fine.tasks > coarse.tasks and 0.5 < fine.task_s / coarse.task_s < 2.0
    assert bench_scale.scale_workload.GRAIN == bench_scale.GRAIN                # restored
