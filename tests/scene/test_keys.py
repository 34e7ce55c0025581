"""The table of scene keys (keys.py) and the records that checkpoints and results compare
(parse.scene_record, parse.changed_settings)."""
import pytest

from hpcwedge.scene import keys
from hpcwedge.scene.parse import changed_settings, parse_scene, scene_record
from hpcwedge.scene.values import COMPUTE_DEFAULTS, RUN_DEFAULTS, SceneError

TEXT = 'name = "s"\ndim = 2\n[model]\nkind = "plug2d"\n[friction]\nmu = [0.5, 1.0]\n[run]\ncheckpoint_every_s = 0.1\n'

#: another valid value of every [compute] and [run] key
OTHER = {"enumerate": "rays", "mu_c": "global", "mu_c_method": "bisection", "mu_c_tol": 1e-5, "mu_max": 50.0,
         "exact": True, "exact_fallback_max_m": 3, "checkpoint_every_s": 2.0, "task_budget": 5,
         "symmetry": False, "face_split": 2, "condense": "serial", "max_memory_gb": 8, "screens": True,
         "progress_every_s": 60.0}


def _toml(v) -> str:
    return ("true" if v else "false") if isinstance(v, bool) else f'"{v}"' if isinstance(v, str) else repr(v)


def test_defaults_and_settings_come_from_the_table():
    assert COMPUTE_DEFAULTS == {k.name: k.default for k in keys.KEYS if k.table == "compute"}
    assert list(RUN_DEFAULTS) == [k.name for k in keys.KEYS if k.table == "run"]
    assert set(OTHER) == set(COMPUTE_DEFAULTS) | set(RUN_DEFAULTS)
    assert [k.path for k in keys.KEYS if k.setting] == ["run.checkpoint_every_s", "run.progress_every_s",
                                                         "run.max_memory_gb"]
    assert {k.path for k in keys.KEYS if k.setting} == set(keys.SETTINGS)
    assert keys.table("model.plug3d")["ring"].values == "≥ 3"        # models.library.WHOLE_MINIMUM
    assert keys.table("compute")["mu_c"].path == "compute.mu_c" and keys.table("scene")["dim"].path == "dim"


def test_every_key_is_described(monkeypatch):
    for table, ks in keys.tables().items():
        for k in ks.values():
            assert k.type and k.meaning.endswith((".", ")")), (table, k.name)
    monkeypatch.delitem(keys.BUILTIN, "rows")       # a built-in's parameter without a meaning
    with pytest.raises(KeyError, match="no meaning for model.plug2d.rows"):
        keys.builtin_keys("plug2d")


def test_the_parser_lists_the_tables_values():
    """The parser's messages name the allowed values the table gives the reference."""
    base = {"name": "s", "dim": 2, "model": {"kind": "plug2d"}, "friction": {"mu": 0.5}}
    for key in ("enumerate", "mu_c", "mu_c_method"):
        with pytest.raises(SceneError) as e:
            parse_scene({**base, "compute": {key: "nope"}})
        assert str(e.value) == f"compute.{key}: {keys.table('compute')[key].values}, got 'nope'"
    with pytest.raises(SceneError, match="compute.zz: unknown key"):
        parse_scene({**base, "compute": {"zz": 1}})


def test_the_same_scene_is_an_equal_record():
    """Comments, layout, a default written out, the order of the listed mu: the same record,
    no setting changed; a run setting: named, in SETTINGS order; anything else: another scene."""
    assert changed_settings(TEXT, "# a comment\n" + TEXT.replace(" = ", "=")) == []
    assert changed_settings(TEXT, TEXT + 'condense = "auto"\n[compute]\nmu_max = 100.0\n') == []
    assert changed_settings(TEXT, TEXT.replace("[0.5, 1.0]", "[1.0, 0.5]")) == []
    both = TEXT.replace("0.1", "30.0\nmax_memory_gb = 64")
    assert changed_settings(TEXT, both) == ["run.max_memory_gb", "run.checkpoint_every_s"]
    assert changed_settings(TEXT, TEXT + "progress_every_s = 1\n") == ["run.progress_every_s"]
    assert changed_settings(TEXT, TEXT.replace("0.5,", "0.6,")) is None
    assert changed_settings(TEXT, TEXT.replace('"s"', '"t"')) is None
    assert changed_settings(TEXT, "name = ") is None                  # not TOML
    assert changed_settings(TEXT + "retired_key = 1\n", TEXT) is None   # a scene no longer valid
    assert scene_record(parse_scene({"name": "s", "dim": 2, "model": {"kind": "plug2d"}, "friction": {"mu": 1}},
                                    text="x", base_dir="/a")) == \
        scene_record(parse_scene({"name": "s", "dim": 2, "model": {"kind": "plug2d"}, "friction": {"mu": [1.0]}}))


@pytest.mark.parametrize("key", sorted(OTHER))
def test_every_key_but_the_settings_changes_the_record(key):
    """Another value of a run setting is named; of any other [compute] or [run] key, it is
    another scene (the run settings of SPEC §5)."""
    base = TEXT.replace("checkpoint_every_s = 0.1\n", "")
    line = f"{key} = {_toml(OTHER[key])}\n"
    other = base + line if key in RUN_DEFAULTS else f"{base}[compute]\n{line}"
    assert changed_settings(base, other) == ([f"run.{key}"] if f"run.{key}" in keys.SETTINGS else None)
