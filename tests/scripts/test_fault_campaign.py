"""scripts/fault_campaign.py: its catalogue (size, unique names, every category), and a few of
its cases run end to end through the real command line, each a defect of issue 11."""
import csv
import importlib.util
import json
import os
import sys

import pytest

SCRIPT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "scripts", "fault_campaign.py")


@pytest.fixture(scope="module")
def campaign():
    spec = importlib.util.spec_from_file_location("fault_campaign", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod           # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


def test_catalogue_has_at_least_100_cases_with_unique_names(campaign):
    cases = campaign.catalogue()
    assert len(cases) >= 100
    assert len({c.name for c in cases}) == len(cases)
    assert {"scene key", "scene file", "output", "result file", "checkpoint", "signal", "mpirun",
            "magnitude", "size guard", "concurrency"} <= {c.category for c in cases}


def test_toml_writer_round_trips(campaign):
    import math
    import tomllib
    d = campaign.with_(campaign.plug(3), "run.checkpoint_every_s", float("nan"))
    back = tomllib.loads(campaign.toml_text(d))
    assert math.isnan(back["run"]["checkpoint_every_s"])
    assert back["model"] == d["model"] and back["friction"] == d["friction"]


@pytest.mark.parametrize("only", ["dim 2.0 (a float)", "run -o the scene itself", "show --json | head",
                                  "matrix K a mechanism"])
def test_cases_pass_end_to_end(campaign, tmp_path, only):
    out = str(tmp_path / "faults")
    assert campaign.main(["--only", only, "--out", out, "--timeout", "120"]) == 0
    with open(out + ".csv") as f:
        rows = list(csv.DictReader(f))
    assert rows and all(r["verdict"] == "pass" for r in rows), rows
    with open(out + ".json") as f:
        assert json.load(f)["cases"] == len(rows)
