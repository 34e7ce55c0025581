"""Scene parsing and validation: every error is one line naming its key."""
import pytest

from hpcwedge.scene import SceneError, parse_scene

BASE = {"name": "s", "dim": 2, "model": {"kind": "stiffness", "K": [[2.0, 0.5], [0.5, 1.0]]},
        "friction": {"mu": [0.5]}}


def scene(**over):
    d = {k: (dict(v) if isinstance(v, dict) else v) for k, v in BASE.items()}
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(d.get(k), dict) and k != "model":
            d[k].update(v)
        else:
            d[k] = v
    return d


def test_defaults_and_plan():
    s = parse_scene(scene())
    assert s.mu == (0.5,) and s.mu_c == "cones" and s.mu_max == 100.0 and not s.exact
    p = s.plan()
    assert not p.condense and p.rays and p.cones and p.mu_c_cones and p.mu_c_global
    p = parse_scene(scene(compute={"enumerate": "rays", "mu_c": "none"})).plan()
    assert p.rays and not p.cones and not p.mu_c_global
    p = parse_scene(scene(compute={"enumerate": False, "mu_c": "global"})).plan()
    assert not p.rays and not p.cones and p.mu_c_global and not p.mu_c_cones
    assert parse_scene(scene(model={"kind": "plug2d", "rows": 3})).plan().condense


def test_mu_sorted():
    assert parse_scene(scene(friction={"mu": [2.0, 0.5, 1.0]})).mu == (0.5, 1.0, 2.0)


@pytest.mark.parametrize("over,key", [
    ({"name": ""}, "name"),
    ({"dim": 4}, "dim"),
    ({"model": {"kind": "nope"}}, "model.kind"),
    ({"friction": {"mu": [0.0]}}, "friction.mu"),
    ({"friction": {"mu": [float("nan")]}}, "friction.mu"),
    ({"friction": {"mu": []}}, "friction.mu"),
    ({"compute": {"mu_c": "all"}}, "compute.mu_c"),
    ({"compute": {"mu_c_method": "fast"}}, "compute.mu_c_method"),
    ({"compute": {"mu_max": -1}}, "compute.mu_max"),
    ({"compute": {"exact": "yes"}}, "compute.exact"),
    ({"compute": {"typo": 1}}, "compute.typo"),
    ({"run": {"checkpoint_every_s": 0}}, "run.checkpoint_every_s"),
    ({"extra": 1}, "extra"),
    ({"model": {"kind": "plug2d", "rows": 2.5}}, "model.rows"),
    ({"model": {"kind": "plug2d", "wheels": 2}}, "model.wheels"),
    ({"dim": 3, "model": {"kind": "plug2d"}}, "dim"),
])
def test_errors_name_the_key(over, key):
    with pytest.raises(SceneError) as e:
        parse_scene(scene(**over))
    msg = str(e.value)
    assert msg.startswith(key) and "\n" not in msg
