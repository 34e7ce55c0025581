"""scripts/model_hubs.py: the streaming-hub model explores the tree the one-level model
explores, every node once (a node lost or run twice between pools changes the counts), and
its layout and fractions are what its docstring says."""
import dataclasses
import json
import os
import sys

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "scripts"))
import model_hubs  # noqa: E402
from scale_workload import load_durations, make_job, task_seconds  # noqa: E402

from hpcwedge.parallel.model import MasterCosts, simulate  # noqa: E402

ROOT = os.path.join(HERE, "..", "..")


@pytest.fixture(scope="module")
def durations():
    return load_durations(os.path.join(ROOT, "results", "task_durations.json"))


@pytest.fixture(scope="module")
def costs():
    with open(os.path.join(ROOT, "results", "bench_scale.json")) as f:
        return MasterCosts(**json.load(f)["costs_predicting"]["subtree"])


@pytest.mark.parametrize("hubs,per_hub,low,chunk", [(4, 4, 4.0, 2.0), (3, 5, 1.0, 1.0), (1, 16, 2.0, 4.0)])
def test_hubs_explore_every_node_of_the_tree_once(durations, costs, hubs, per_hub, low, chunk):
    flat = make_job("subtree", durations, 40.0, 3, sleep=False, budget=16)
    s = simulate(flat, 16, costs, task_seconds)
    job = make_job("subtree", durations, 40.0, 3, sleep=False, budget=16)
    r = model_hubs.simulate_hubs(job, hubs, per_hub, costs, low, chunk)
    assert r["nodes"] == flat.counters["nodes"] > 100
    assert r["found"] == len(flat.found[0]) > 0
    assert r["task_s"] == pytest.approx(s.task_s, rel=1e-9)
    assert 0 < r["efficiency"] <= 1 and 0 <= r["master_busy"] <= 1 and 0 <= r["hub_busy"] <= 1
    assert r["moved"] >= 1 and r["tasks"] >= r["nodes"] / 16


def test_a_free_master_is_no_slower_than_the_fitted_one(durations, costs):
    rows = model_hubs.study(durations, costs, grain=8, ranks=33, worker_seconds=60.0,
                            plans=((8, 64, 4.0, 2.0),))
    by = {(r["schedule"], r["budget"]): r for r in rows}
    assert {r["schedule"] for r in rows} == {"flat", "flat, free", "hubs"}
    assert by[("flat, free", 64)]["efficiency"] >= by[("flat", 64)]["efficiency"] - 1e-9
    hubs = by[("hubs", 64)]
    assert (hubs["hubs"], hubs["per_hub"]) == model_hubs.hub_layout(33, 8) == (4, 7)
    assert hubs["efficiency_all_ranks"] == pytest.approx(hubs["efficiency"] * 28 / 32)
    assert model_hubs.scale_workload.GRAIN == 8


def test_hub_layout():
    assert model_hubs.hub_layout(1024, 32) == (31, 32)
    assert model_hubs.hub_layout(1024, 64) == (16, 62)
    assert model_hubs.hub_layout(3, 64) == (1, 1)


def test_a_protocol_without_an_end_is_an_error(durations, costs):
    free = dataclasses.replace(costs, send_s=0.0)
    job = make_job("subtree", durations, 40.0, 3, sleep=False, budget=16)
    with pytest.raises(RuntimeError, match="max_events"):
        model_hubs.simulate_hubs(job, 2, 4, free, 1.0, 1.0, max_events=50)
