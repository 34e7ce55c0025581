"""Scene parsing and validation: every error is one line naming its key."""
import pytest

from hpcwedge.scene.parse import parse_scene
from hpcwedge.scene.values import SceneError

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


TRUSS = {"kind": "truss", "nodes": [[0.0, 0.0], [1.0, 0.0]], "bars": [[0, 1]], "EA": 1.0}
TRUSS_CONTACT = {"nodes": [0, 1], "normals": [[1.0, 1.0], [-1.0, 1.0]]}
MESH = {"kind": "mesh", "file": "m.msh"}
MESH_CONTACT = {"group": "walls", "normals": [[1.0, 1.0]]}
NAN, INF = float("nan"), float("inf")


@pytest.mark.parametrize("over,key", [
    # top level: a table given as a value, a number of the wrong type
    ({"run": 5}, "run"),
    ({"compute": 5}, "compute"),
    ({"friction": 0.5}, "friction"),
    ({"model": "plug2d"}, "model"),
    ({"contact": [1]}, "contact"),
    ({"dim": 2.0}, "dim"),
    ({"dim": True}, "dim"),
    # [friction]
    ({"friction": {"mu": "0.5"}}, "friction.mu"),
    ({"friction": {"mu": True}}, "friction.mu"),
    ({"friction": {"mu": INF}}, "friction.mu"),
    ({"friction": {"mu": 0.5, "muu": 1.0}}, "friction.muu"),
    ({"friction": {"mu": [0.5, 1e300]}}, "friction.mu"),        # overflowed the cone constraints
    ({"friction": {"mu": 5e-324}}, "friction.mu"),              # NaN rays
    ({"compute": {"mu_max": 1e300}}, "compute.mu_max"),
    # [compute]
    ({"compute": {"enumerate": 1}}, "compute.enumerate"),
    ({"compute": {"enumerate": 0.0}}, "compute.enumerate"),
    ({"compute": {"mu_max": INF}}, "compute.mu_max"),
    ({"compute": {"mu_c_tol": NAN}}, "compute.mu_c_tol"),
    ({"compute": {"mu_max": True}}, "compute.mu_max"),
    ({"compute": {"exact_fallback_max_m": 2.0}}, "compute.exact_fallback_max_m"),
    ({"compute": {"mu_c_tol": 1e-300, "mu_c_method": "bisection"}}, "compute.mu_c_tol"),   # bisected for ever
    ({"compute": {"mu_c_tol": 2.0}}, "compute.mu_c_tol"),
    # [run]
    ({"run": {"checkpoint_every_s": NAN}}, "run.checkpoint_every_s"),
    ({"run": {"checkpoint_every_s": INF}}, "run.checkpoint_every_s"),
    ({"run": {"checkpoint_every_s": "60"}}, "run.checkpoint_every_s"),
    ({"run": {"task_budget": True}}, "run.task_budget"),
    ({"run": {"face_split": 2.0}}, "run.face_split"),
    ({"run": {"symmetry": 1}}, "run.symmetry"),
    ({"run": {"screens": "lp"}}, "run.screens"),
    ({"run": {"checkpoint_every": 1}}, "run.checkpoint_every"),
    # stiffness: [model] and [contact]
    ({"model": {**BASE["model"], "null_spcae": [[1.0], [0.0]]}}, "model.null_spcae"),
    ({"model": {"kind": "stiffness", "file": 5}}, "model.file"),
    ({"model": {"kind": "stiffness", "K": [[2.0, True], [True, 1.0]]}}, "model.K[0][1]"),
    ({"contact": {"nodes": [0]}}, "contact.nodes"),
    # built-ins: [model] and [contact]
    ({"model": {"kind": "plug2d", "rows": True}}, "model.rows"),
    ({"model": {"kind": "plug2d", "rows": 1}}, "model.rows"),       # the model's own least value
    ({"model": {"kind": "plug3d", "ring": 2}, "dim": 3}, "model.ring"),
    ({"model": {"kind": "plug2d", "taper_deg": NAN}}, "model.taper_deg"),
    ({"model": {"kind": "plug2d"}, "contact": {"normals": [[1.0, 0.0]]}}, "contact.normals"),
    # truss: [model] and [contact]
    ({"model": {**TRUSS, "suports": [[0, 0]]}, "contact": TRUSS_CONTACT}, "model.suports"),
    ({"model": {**TRUSS, "EA": True}, "contact": TRUSS_CONTACT}, "model.EA"),
    ({"model": TRUSS, "contact": {**TRUSS_CONTACT, "tangent": [[1.0, 0.0]]}}, "contact.tangent"),
    ({"model": TRUSS, "contact": {**TRUSS_CONTACT, "normals": [[1.0, False], [-1.0, 1.0]]}},
     "contact.normals[0][1]"),
    # mesh: [model], [contact] and [[obstacle]]
    ({"model": {**MESH, "Young": 1.0}, "contact": MESH_CONTACT}, "model.Young"),
    ({"model": {**MESH, "E": True}, "contact": MESH_CONTACT}, "model.E"),
    ({"model": {**MESH, "nu": NAN}, "contact": MESH_CONTACT}, "model.nu"),
    ({"model": MESH, "contact": {**MESH_CONTACT, "normal": [[1.0, 1.0]]}}, "contact.normal"),
    ({"model": MESH, "contact": {**MESH_CONTACT, "tolerance": INF}}, "contact.tolerance"),
    ({"model": MESH, "contact": {"group": "walls"},
      "obstacle": [{"type": "plane", "point": [0.0, 0.0], "normall": [0.0, 1.0]}]}, "obstacle[0].normall"),
    ({"model": MESH, "contact": {"group": "walls"},
      "obstacle": [{"type": "cone", "apex": [0.0, 0.0], "axis": [0.0, 1.0], "half_angle_deg": NAN}]},
     "obstacle[0].half_angle_deg"),
])
def test_type_slips_typos_nan_name_the_key(over, key):
    """Every table of every model kind: an unknown key, a value of the wrong type (a boolean
    for a number included), NaN/inf or a value out of range is a one-line SceneError that
    starts with the key."""
    with pytest.raises(SceneError) as e:
        parse_scene(scene(**over))
    msg = str(e.value)
    assert msg.startswith(key + ":") and "\n" not in msg, msg


def test_whole_number_bounds_are_the_models_own():
    """A built-in's whole-number parameter is refused at parse time with the bound its model
    checks (models.library.WHOLE_MINIMUM), in the same words."""
    import inspect

    from hpcwedge.models.library import BUILTINS, WHOLE_MINIMUM, builtin
    for kind, f in BUILTINS.items():
        ints = {k for k, p in inspect.signature(f).parameters.items()
                if isinstance(p.default, int) and not isinstance(p.default, bool)}
        assert ints == set(WHOLE_MINIMUM.get(kind, {})), kind
        for k in ints:
            lo = WHOLE_MINIMUM[kind][k]
            with pytest.raises(ValueError) as built:
                builtin(kind, {k: lo - 1})
            with pytest.raises(SceneError) as parsed:
                parse_scene(scene(dim=3 if kind == "plug3d" else 2, model={"kind": kind, k: lo - 1}))
            assert str(parsed.value) == str(built.value) == f"model.{k}: must be a whole number >= {lo}, got {lo - 1}"


def test_valid_tables_of_every_kind_still_parse():
    """The catalogue's base tables are valid: each error above is the one slip it makes."""
    assert parse_scene(scene(model=TRUSS, contact=TRUSS_CONTACT)).kind == "truss"
    assert parse_scene(scene(model=MESH, contact=MESH_CONTACT)).kind == "mesh"
    assert parse_scene(scene(model={"kind": "plug2d", "rows": 3, "taper_deg": 5})).kind == "plug2d"
    assert parse_scene(scene(run={"checkpoint_every_s": 1e9}, compute={"enumerate": "rays"})).checkpoint_every_s == 1e9


def test_plan_steps_in_the_order_they_run():
    """Plan.steps: the stages after condensation that pipeline.run_scene loops over."""
    base = {"name": "p", "dim": 2, "model": {"kind": "plug2d"}, "friction": {"mu": 1.0}}

    def steps(**over):
        return parse_scene({**base, **over}).plan().steps()
    assert steps() == ("rays", "cones", "mu_c", "global_mu_c")
    assert steps(compute={"enumerate": "rays", "mu_c": "none"}) == ("rays",)
    assert steps(compute={"enumerate": False, "mu_c": "global"}) == ("mu_c", "global_mu_c")
    assert steps(compute={"enumerate": "patterns", "mu_c": "cones"}) == ("patterns", "mu_c", "global_mu_c")
    assert steps(compute={"enumerate": False, "mu_c": "none"}) == ()
    assert steps(dim=3, model={"kind": "plug3d"}) == ("patterns", "mu_c", "global_mu_c")


def test_plan_patterns_2d():
    s = parse_scene({"name": "t", "dim": 2, "model": {"kind": "plug2d"}, "friction": {"mu": [1.0]},
                     "compute": {"enumerate": "patterns"}})
    p = s.plan()
    assert p.patterns and not p.rays and not p.cones and s.task_budget == 64


def test_file_encoding(tmp_path):
    """load_scene reads UTF-8: a byte-order mark (as Windows editors write it) is dropped, the
    scene and its hash are those of the same file without it; text in another encoding is one
    line naming the byte and its line (before: tomllib's 'Invalid statement (at line 1,
    column 1)' for the mark, the codec's message for the rest)."""
    from hpcwedge.scene.parse import load_scene
    text = 'name = "café"\ndim = 2\n[model]\nkind = "plug2d"\n[friction]\nmu = [0.65]\n'
    plain, bom, latin = tmp_path / "a.toml", tmp_path / "b.toml", tmp_path / "c.toml"
    plain.write_bytes(text.encode())
    bom.write_bytes(b"\xef\xbb\xbf" + text.encode())
    latin.write_bytes(("# ok\n" + text).encode("latin-1"))
    a, b = load_scene(str(plain)), load_scene(str(bom))
    assert (b.name, b.text, b.hash) == (a.name, a.text, a.hash) == ("café", text, a.hash)
    with pytest.raises(SceneError, match=r"c\.toml: not UTF-8 text \(byte 0xe9 on line 2\)"):
        load_scene(str(latin))


# ---- near misses: "did you mean" ------------------------------------------------------------

def _osa_distance(a: str, b: str) -> int:
    """Optimal string alignment distance (edits: insert, delete, replace, swap neighbours), by
    the textbook dynamic programme: the independent route for values.one_edit_apart."""
    d = [[i + j if i * j == 0 else 0 for j in range(len(b) + 1)] for i in range(len(a) + 1)]
    for i in range(1, len(a) + 1):
        for j in range(1, len(b) + 1):
            d[i][j] = min(d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] != b[j - 1]))
            if i > 1 and j > 1 and a[i - 1] == b[j - 2] and a[i - 2] == b[j - 1]:
                d[i][j] = min(d[i][j], d[i - 2][j - 2] + 1)
    return d[len(a)][len(b)]


def test_one_edit_apart_is_distance_one():
    """one_edit_apart(a, b) holds exactly when the edit distance is 1, over every pair of
    strings of length <= 3 over {a, b, c} (brute force)."""
    import itertools

    from hpcwedge.scene.values import one_edit_apart
    words = [""] + ["".join(w) for n in (1, 2, 3) for w in itertools.product("abc", repeat=n)]
    for a in words:
        for b in words:
            assert one_edit_apart(a, b) == (_osa_distance(a, b) == 1), (a, b)


@pytest.mark.parametrize("where, data, message", [
    ("top", {**BASE, "nmae": "x"}, "nmae: unknown key; did you mean `name`?"),
    ("compute", scene(compute={"mu_cc": "cones"}), "compute.mu_cc: unknown key; did you mean `mu_c`?"),
    ("builtin", scene(model={"kind": "plug2d", "row": 3}), "model.row: unknown parameter of plug2d; did you mean `rows`?"),
])
def test_unknown_key_one_edit_away_says_did_you_mean(where, data, message):
    with pytest.raises(SceneError) as e:
        parse_scene(data)
    assert str(e.value).startswith(message), str(e.value)
    assert "(allowed:" in str(e.value)


def test_unknown_kind_one_edit_away_says_did_you_mean():
    with pytest.raises(SceneError, match=r"^model.kind: unknown kind 'plug2'; did you mean `plug2d`\? \(one of "):
        parse_scene(scene(model={"kind": "plug2"}))


def test_unknown_key_far_from_all_names_none():
    with pytest.raises(SceneError) as e:
        parse_scene(scene(compute={"zzzz": 1}))
    assert "did you mean" not in str(e.value)


def test_missing_required_key_names_its_near_miss():
    """`mus = [...]` instead of `mu`: the error for the missing mu names `mus` (issue 44)."""
    with pytest.raises(SceneError) as e:
        parse_scene({**BASE, "friction": {"mus": [0.5]}})
    assert str(e.value) == "friction.mu: required (one value or a list); found `mus`: did you mean `mu`?"
    with pytest.raises(SceneError) as e:
        parse_scene({**BASE, "model": {"knd": "plug2d"}})
    assert "model.kind: required" in str(e.value) and "`knd`" in str(e.value)
    with pytest.raises(SceneError) as e:
        parse_scene({**BASE, "friction": {"coefficient": [0.5]}})
    assert str(e.value) == "friction.mu: required (one value or a list)"
