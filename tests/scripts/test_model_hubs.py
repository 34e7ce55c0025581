"""scripts/model_hubs.py: its schedules and layout are what its docstring says (the hub
model itself, parallel.model.simulate_hubs: tests/parallel/test_model.py)."""
import json
import os
import sys

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "scripts"))
import model_hubs  # noqa: E402
from scale_workload import load_durations  # noqa: E402

from hpcwedge.parallel.model import MasterCosts  # noqa: E402

ROOT = os.path.join(HERE, "..", "..")


@pytest.fixture(scope="module")
def durations():
    return load_durations(os.path.join(ROOT, "results", "task_durations.json"))


@pytest.fixture(scope="module")
def costs():
    with open(os.path.join(ROOT, "results", "bench_scale.json")) as f:
        return MasterCosts(**json.load(f)["costs_predicting"]["subtree"])


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
