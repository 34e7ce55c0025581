"""Scenes (SPEC §3): TOML -> a validated, frozen Scene, the plan of stages, and the record
that checkpoints and results compare (the part of a scene the answers depend on).

Every error is a SceneError whose one-line message names the key and the
reason; the command line turns it into exit status 2 with nothing written.
"""
from __future__ import annotations

import functools
import hashlib
import importlib.util
import math
import os
import tomllib
from dataclasses import dataclass, field, fields

from hpcwedge.models.library import BUILTIN_DIM, BUILTINS, WHOLE_MINIMUM  # the one table of built-ins
from hpcwedge.scene import keys, tables
from hpcwedge.scene.keys import CONDENSE_MODES, FACE_SPLIT_MAX, KINDS, MU_C_TOL_MIN, MU_RANGE, SETTINGS
from hpcwedge.scene.values import COMPUTE_DEFAULTS, NUMBER_TYPES, RUN_DEFAULTS, SceneError, did_you_mean, near_misses

#: the keys of each table (keys.py); a built-in's model keys are its generator's parameters,
#: and stiffness and built-in scenes have no [contact] keys
TOP_KEYS = set(keys.table("scene"))
MESH_MODEL_KEYS = set(keys.table("model.mesh"))     # values checked when the mesh is read: models/mesh.py
MESH_CONTACT_KEYS = set(keys.table("contact.mesh"))
STIFFNESS_MODEL_KEYS = set(keys.table("model.stiffness"))
TRUSS_MODEL_KEYS = set(keys.table("model.truss"))
TRUSS_CONTACT_KEYS = set(keys.table("contact.truss"))
MATRIX_MODEL_KEYS = set(keys.table("model.matrix"))     # values checked when read: contact/build.py
MATRIX_CONTACT_KEYS = set(keys.table("contact.matrix"))


@dataclass(frozen=True)
class Plan:
    """Which stages a scene needs (the one place that decides what to skip)."""

    condense: bool       # a model to assemble and condense (not a raw K)
    rays: bool           # 2D: complementary extreme rays per listed mu
    cones: bool          # 2D: cross-complementarity cliques
    patterns: bool       # 3D (2D with enumerate = "patterns"): feasible sign patterns per listed mu
    mu_c_cones: bool     # mu^c of every cone / pattern
    mu_c_global: bool

    def steps(self) -> tuple[str, ...]:
        """The stages after condensation, in order (pipeline.run_scene loops over them; every
        scene is condensed first: `condense` says whether a model is, else a raw K is read):
        "rays", "cones", "patterns", "mu_c" (per cone / pattern: of every listed mu with
        mu_c_cones, else of the first that lists any, for the global value), "global_mu_c"."""
        wanted = (self.rays, self.cones, self.patterns, self.mu_c_cones or self.mu_c_global, self.mu_c_global)
        return tuple(name for name, on in zip(STEPS, wanted) if on)


#: every stage a plan can hold after condensation, in the order they run (Plan.steps)
STEPS = ("rays", "cones", "patterns", "mu_c", "global_mu_c")


@dataclass(frozen=True)
class Scene:
    name: str
    dim: int
    kind: str
    model: dict
    contact: dict
    mu: tuple[float, ...]
    # [compute] (keys.py: the meanings and defaults of these and of [run])
    enumerate: bool | str
    mu_c: str
    mu_c_method: str
    mu_c_tol: float
    mu_max: float
    exact: bool
    exact_fallback_max_m: int   # a 2D float enumeration too close to call is redone exactly up to this m
    # [run]
    checkpoint_every_s: float
    progress_every_s: float     # the period of progress lines in a batch log (progress.Progress)
    task_budget: int            # tree nodes per sign-pattern task (parallel/)
    symmetry: bool              # use the node symmetries of K (symmetry.py)
    screens: bool               # 3D tree, LP screens before deep SOCPs (screens.py)
    face_split: int | str       # branching nodes of the 2D DD split (faces.branching_nodes)
    condense: str               # auto | serial | distributed (under mpirun)
    max_memory_gb: float | str  # "auto": from the machine's (progress.MemoryGuard)
    text: str = field(repr=False, default="")
    base_dir: str = "."
    obstacles: list | None = None  # mesh: obstacle tables ([[obstacle]] or contact.obstacle), raw
    obstacle_key: str = "obstacle"  # where they came from, for messages

    @property
    def hash(self) -> str:
        return hashlib.sha256(self.text.encode()).hexdigest()

    @property
    def input_files(self) -> tuple[str, ...]:
        """Absolute paths of the data files the scene names (model.file of a stiffness or mesh
        model; model.K, model.nodes when a file, model.mesh of a matrix), in a fixed order; the
        scene file itself is not among them."""
        names = {"stiffness": ("file",), "mesh": ("file",), "matrix": ("K", "nodes", "mesh")}.get(self.kind, ())
        files = [self.model.get(k) for k in names]
        return tuple(os.path.abspath(os.path.join(self.base_dir, f)) for f in files if isinstance(f, str) and f)

    @functools.cached_property
    def input_digests(self) -> dict[str, str]:
        """{"model.file k.npz": SHA-256 (hex) of the file's bytes} for every file in
        input_files, read once (the first use): with `hash` (the text), the identity of what a
        run depends on, kept in checkpoints and results. SceneError when a file is missing or
        unreadable."""
        out = {}
        for path in self.input_files:
            key, name = next(((f"model.{k}", v) for k, v in self.model.items() if isinstance(v, str)
                              and os.path.abspath(os.path.join(self.base_dir, v)) == path), ("file", path))
            h = hashlib.sha256()
            try:
                with open(path, "rb") as fh:
                    while chunk := fh.read(8 << 20):
                        h.update(chunk)
            except FileNotFoundError:
                raise SceneError(f"{key}: {name} not found") from None
            except OSError as e:
                raise SceneError(f"{key}: cannot read {name} ({e.strerror or type(e).__name__})") from None
            out[f"{key} {name}"] = h.hexdigest()
        return out

    def plan(self) -> Plan:
        enum = self.enumerate is not False
        patterns = enum and (self.dim == 3 or self.enumerate == "patterns")
        rays = self.dim == 2 and enum and not patterns
        return Plan(condense=self.kind != "stiffness",
                    rays=rays,
                    cones=rays and self.enumerate != "rays",
                    patterns=patterns,
                    mu_c_cones=self.mu_c == "cones",
                    mu_c_global=self.mu_c in ("global", "cones"))

    # the public API's constructors (api.py: a scene table, then parse_scene, the one validator)
    @classmethod
    def load(cls, path: str) -> Scene:
        """The scene of a TOML file (load_scene)."""
        return load_scene(path)

    @classmethod
    def from_dict(cls, data: dict, base_dir: str | None = None) -> Scene:
        """The scene of a scene table given as a dict (constructors.scene_from_dict)."""
        table, text = tables.plain_table(data)
        # the table as its TOML text reads back, without parsing it again (a 1,000 x 1,000 K:
        # 6.5 s of tomllib)
        return parse_scene(table, text=text, base_dir=os.path.abspath(base_dir or os.getcwd()))

    @classmethod
    def builtin(cls, kind: str, **options) -> Scene:
        """The scene of a built-in model (constructors.builtin_scene)."""
        return cls.from_dict(tables.builtin_table(kind, **options))

    @classmethod
    def from_stiffness(cls, K, **options) -> Scene:
        """The scene of a condensed stiffness array (constructors.stiffness_scene)."""
        return cls.from_dict(tables.stiffness_table(K, **options))

    @classmethod
    def from_truss(cls, nodes, bars, **options) -> Scene:
        """The scene of a truss given as arrays (constructors.truss_scene)."""
        return cls.from_dict(tables.truss_table(nodes, bars, **options))


def load_scene(path: str) -> Scene:
    """Read and validate a scene file."""
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except OSError as e:
        raise SceneError(f"{path}: cannot read ({e.strerror})") from None
    try:
        text = raw.decode("utf-8-sig")        # a byte-order mark (Windows editors) is dropped
    except UnicodeDecodeError as e:
        line = raw[:e.start].count(b"\n") + 1
        raise SceneError(f"{path}: not UTF-8 text (byte 0x{raw[e.start]:02x} on line {line}): save it "
                         f"as UTF-8") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{path}: not valid TOML ({e})") from None
    return parse_scene(data, text=text, base_dir=os.path.dirname(os.path.abspath(path)))


def parse_scene(data: dict, text: str = "", base_dir: str = ".") -> Scene:
    """The Scene of a scene table (TOML's structure, SPEC §3): every check, in a fixed order,
    one table at a time; SceneError naming the first bad key."""
    _unknown(data, TOP_KEYS, "")
    name, dim = _name_and_dim(data)
    kind = _model_kind(data, dim)
    mu = _friction(data)
    compute = _compute(data.get("compute", {}), dim)
    run = _run(data.get("run", {}))
    params, contact, obstacles, obstacle_key = _body(data, kind, dim)
    return Scene(name=name, dim=dim, kind=kind, model=params, contact=contact, mu=mu, **compute, **run,
                 text=text, base_dir=base_dir, obstacles=obstacles, obstacle_key=obstacle_key)


def _name_and_dim(data: dict) -> tuple[str, int]:
    name = data.get("name")
    if not isinstance(name, str) or not name:
        raise SceneError("name: required, a non-empty string")
    dim = data.get("dim")
    if isinstance(dim, bool) or not isinstance(dim, int) or dim not in (2, 3):
        raise SceneError(f"dim: must be 2 or 3, got {dim!r}")
    return name, dim


def _model_kind(data: dict, dim: int) -> str:
    """model.kind, one of KINDS, a built-in only in its own dimension."""
    kind = _table_with(data, "model", "kind")["kind"]
    if kind not in KINDS:
        near = did_you_mean(kind, KINDS) if isinstance(kind, str) else ""
        raise SceneError(f"model.kind: unknown kind {kind!r}{near} (one of {', '.join(KINDS)})")
    if kind in BUILTIN_DIM and BUILTIN_DIM[kind] != dim:
        raise SceneError(f"dim: {kind} is a {BUILTIN_DIM[kind]}D model, scene says dim = {dim}")
    return kind


def _friction(data: dict) -> tuple[float, ...]:
    """friction.mu: one value or a list, each in MU_RANGE and listed once; sorted."""
    friction = _table_with(data, "friction", "mu", " (one value or a list)")
    _unknown(friction, set(keys.table("friction")), "friction.")
    mus = friction["mu"] if isinstance(friction["mu"], list) else [friction["mu"]]
    if not mus:
        raise SceneError("friction.mu: empty list")
    for v in mus:
        if not _positive(v):
            raise SceneError(f"friction.mu: every value must be a finite number > 0, got {v!r}")
        if not MU_RANGE[0] <= v <= MU_RANGE[1]:
            raise SceneError(f"friction.mu: every value must lie in [{MU_RANGE[0]:g}, {MU_RANGE[1]:g}], got {v!r}")
    values = sorted(map(float, mus))
    twice = next((a for a, b in zip(values, values[1:]) if a == b), None)
    if twice is not None:
        # each value is one run: a repeated one would be computed again for the same answer
        raise SceneError(f"friction.mu: {twice!r} is listed twice (each value is one run)")
    return tuple(values)


def _compute(given, dim: int) -> dict:
    """The [compute] table with its defaults, checked: {key: value}, Scene's fields."""
    _unknown(given, set(COMPUTE_DEFAULTS), "compute.")
    compute = {**COMPUTE_DEFAULTS, **given}
    if not isinstance(compute["enumerate"], (bool, str)) or compute["enumerate"] not in keys.ENUMERATE:
        raise SceneError(f"compute.enumerate: {keys.choices(keys.ENUMERATE)}, got {compute['enumerate']!r}")
    for key, allowed in (("mu_c", keys.MU_C), ("mu_c_method", keys.MU_C_METHODS)):
        if compute[key] not in allowed:
            raise SceneError(f"compute.{key}: {keys.choices(allowed)}, got {compute[key]!r}")
    for key in ("mu_c_tol", "mu_max"):
        if not _positive(compute[key]):
            raise SceneError(f"compute.{key}: must be a finite number > 0, got {compute[key]!r}")
    if not MU_RANGE[0] <= compute["mu_max"] <= MU_RANGE[1]:
        raise SceneError(f"compute.mu_max: must lie in [{MU_RANGE[0]:g}, {MU_RANGE[1]:g}], got {compute['mu_max']!r}")
    if not MU_C_TOL_MIN <= compute["mu_c_tol"] < 1:
        raise SceneError(f"compute.mu_c_tol: a relative tolerance in [{MU_C_TOL_MIN:g}, 1), "
                         f"got {compute['mu_c_tol']!r}")
    if not isinstance(compute["exact"], bool):
        raise SceneError(f"compute.exact: true or false, got {compute['exact']!r}")
    if not _whole(compute["exact_fallback_max_m"], 0):
        raise SceneError(f"compute.exact_fallback_max_m: must be a whole number >= 0, "
                         f"got {compute['exact_fallback_max_m']!r}")
    if compute["exact"] and dim == 3:
        raise SceneError("compute.exact: exact arithmetic is for 2D scenes (3D problems are conic)")
    return {**compute, "mu_c_tol": float(compute["mu_c_tol"]), "mu_max": float(compute["mu_max"])}


def _run(given) -> dict:
    """The [run] table with its defaults, checked: {key: value}, Scene's fields."""
    _unknown(given, set(RUN_DEFAULTS), "run.")
    run = {**RUN_DEFAULTS, **given}
    for key in ("checkpoint_every_s", "progress_every_s"):
        if not _positive(run[key]):
            raise SceneError(f"run.{key}: must be a finite number > 0, got {run[key]!r}")
    if not _whole(run["task_budget"], 1):
        raise SceneError(f"run.task_budget: must be a whole number >= 1, got {run['task_budget']!r}")
    for key in ("symmetry", "screens"):
        if not isinstance(run[key], bool):
            raise SceneError(f"run.{key}: true or false, got {run[key]!r}")
    if run["screens"] and importlib.util.find_spec("cylp") is None:
        raise SceneError("run.screens: needs COIN-OR CLP, which is not installed (pip install 'hpcwedge[screens]', or cylp)")
    v = run["face_split"]
    if v != "auto" and (not _whole(v, 0) or v > FACE_SPLIT_MAX):
        raise SceneError(f"run.face_split: \"auto\" or a whole number 0..{FACE_SPLIT_MAX} (branching nodes), got {v!r}")
    v = run["max_memory_gb"]
    if v != "auto" and (isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < float("inf")):
        raise SceneError(f"run.max_memory_gb: \"auto\" or a number of GB > 0, got {v!r}")
    if run["condense"] not in CONDENSE_MODES:
        raise SceneError(f"run.condense: one of {', '.join(CONDENSE_MODES)}, got {run['condense']!r}")
    return {**run, "checkpoint_every_s": float(run["checkpoint_every_s"]),
            "progress_every_s": float(run["progress_every_s"])}


def _positive(v) -> bool:
    """v is a finite number > 0 (not a boolean)."""
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v) and v > 0


def _whole(v, lo: int) -> bool:
    """v is a whole number >= lo (not a boolean)."""
    return not isinstance(v, bool) and isinstance(v, int) and v >= lo


def _body(data: dict, kind: str, dim: int) -> tuple[dict, dict, list | None, str]:
    """(model parameters, [contact], obstacle tables or None, where they came from): the keys
    of the kind's tables and their value types; the mesh's values are checked when it is read."""
    contact = data.get("contact", {})
    if not isinstance(contact, dict):
        raise SceneError(f"contact: must be a table, got {contact!r}")
    params = {k: v for k, v in data["model"].items() if k != "kind"}
    _no_booleans(params, "model.")
    _no_booleans(contact, "contact.")
    if kind in BUILTINS:
        _check_builtin(kind, params)
        _unknown(contact, set(), "contact.")
    elif kind == "stiffness":
        _unknown(params, STIFFNESS_MODEL_KEYS, "model.")
        _unknown(contact, set(), "contact.")
        if "file" in params and (not isinstance(params["file"], str) or not params["file"]):
            raise SceneError(f"model.file: a file name (relative to the scene file), got {params['file']!r}")
    elif kind == "truss":
        _unknown(params, TRUSS_MODEL_KEYS, "model.")
        _unknown(contact, TRUSS_CONTACT_KEYS, "contact.")
    elif kind == "matrix":
        _check_matrix(params, contact)
    obstacles, obstacle_key = _obstacles(data, kind, contact, dim)
    if kind == "mesh":
        _check_mesh(params, contact, dim, obstacles is not None)
    return params, contact, obstacles, obstacle_key


def _obstacles(data: dict, kind: str, contact: dict, dim: int) -> tuple[list | None, str]:
    """The obstacle tables ([[obstacle]] or contact.obstacle, of a mesh), checked, and their key."""
    if not ("obstacle" in data or (kind == "mesh" and "obstacle" in contact)):
        return None, "obstacle"
    if kind != "mesh":
        raise SceneError("obstacle: obstacle surfaces are for kind = \"mesh\" (give contact.normals)")
    if "obstacle" in data and "obstacle" in contact:
        raise SceneError("obstacle: give [[obstacle]] tables or contact.obstacle, not both")
    obstacle_key = "obstacle" if "obstacle" in data else "contact.obstacle"
    obstacles = data["obstacle"] if "obstacle" in data else contact["obstacle"]
    from hpcwedge.models.obstacle import parse_obstacles
    try:
        parse_obstacles(obstacles, dim, obstacle_key)
    except ValueError as e:
        raise SceneError(str(e)) from None
    return obstacles, obstacle_key


def _table_with(data: dict, name: str, key: str, hint: str = "") -> dict:
    """data[name], a table that holds `key`; else a SceneError naming the table or the key."""
    table = data.get(name)
    if table is not None and not isinstance(table, dict):
        raise SceneError(f"{name}: must be a table, got {table!r}")
    if table is None or key not in table:
        near = near_misses(key, table or {})
        given = f"; found {' and '.join(f'`{k}`' for k in near)}: did you mean `{key}`?" if near else ""
        raise SceneError(f"{name}.{key}: required{hint}{given}")
    return table


def _unknown(table, allowed, prefix):
    if not isinstance(table, dict):
        raise SceneError(f"{prefix.rstrip('.') or 'scene'}: must be a table")
    for k in table:
        if k not in allowed:
            raise SceneError(f"{prefix}{k}: unknown key{did_you_mean(k, allowed)} (allowed: {', '.join(sorted(allowed))})"
                             if allowed
                             else f"{prefix}{k}: unknown key (this table takes no keys here)")





def _no_booleans(value, key: str) -> None:
    """SceneError naming the key of the first true/false inside `value` (a model or contact
    table: none of their keys takes a boolean, and numpy would read one as 1.0 or 0.0)."""
    if isinstance(value, bool):
        raise SceneError(f"{key}: a number or a name expected, got {str(value).lower()}")
    if isinstance(value, dict):
        for k, v in value.items():
            _no_booleans(v, f"{key}{k}" if key.endswith(".") else f"{key}.{k}")
    elif isinstance(value, list) and not set(map(type, value)) <= NUMBER_TYPES:     # else: a row of numbers
        for i, v in enumerate(value):
            _no_booleans(v, f"{key}[{i}]")


def _check_builtin(kind: str, params: dict) -> None:
    """A built-in's parameters (keys.py: its generator's, with their defaults) and their types."""
    allowed = keys.table(f"model.{kind}")
    for k, v in params.items():
        if k not in allowed:
            raise SceneError(f"model.{k}: unknown parameter of {kind}{did_you_mean(k, allowed)} "
                             f"(allowed: {', '.join(allowed)})")
        default = allowed[k].default
        if isinstance(default, str):
            continue                  # a choice (contact_patch_kind): checked in _check_patch
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise SceneError(f"model.{k}: must be a finite number, got {v!r}")
        if isinstance(default, int) and not isinstance(default, bool):
            lo = WHOLE_MINIMUM[kind][k]
            if not isinstance(v, int) or v < lo:
                raise SceneError(f"model.{k}: must be a whole number >= {lo}, got {v!r}")
    _check_patch(params)


def _check_patch(params: dict) -> None:
    """model.contact_patch, if given: a length >= 0; model.contact_patch_kind: one of
    models.patch.KINDS (models/patch.py)."""
    from hpcwedge.models.patch import KINDS, check_patch_size
    if "contact_patch" in params:
        try:
            check_patch_size(params["contact_patch"])
        except ValueError as e:
            raise SceneError(str(e)) from None
    if "contact_patch_kind" in params and params["contact_patch_kind"] not in KINDS:
        raise SceneError(f"model.contact_patch_kind: one of {', '.join(repr(k) for k in KINDS)}, "
                         f"got {params['contact_patch_kind']!r}")


def _check_matrix(params: dict, contact: dict) -> None:
    """Keys of a kind = "matrix" scene and which of them name files; the files are read and
    checked when the model is built (models/matrix.py)."""
    _unknown(params, MATRIX_MODEL_KEYS, "model.")
    _unknown(contact, MATRIX_CONTACT_KEYS, "contact.")
    for k in ("K", "mesh"):
        if (k == "K" or k in params) and (not isinstance(params.get(k), str) or not params[k]):
            raise SceneError(f"model.{k}: a file name (relative to the scene file), got {params.get(k)!r}")
    if "nodes" not in params or params["nodes"] == "":
        raise SceneError("model.nodes: required for a matrix, a .csv or .npy file or the coordinates")
    for k in ("nodes", "normals"):
        if k not in contact:
            raise SceneError(f"contact.{k}: required for a matrix")


def _check_mesh(params: dict, contact: dict, dim: int, has_obstacle: bool) -> None:
    """Keys and value types of a kind = "mesh" scene; the values against the mesh are
    checked when it is read (models/mesh.py)."""
    _unknown(params, MESH_MODEL_KEYS, "model.")
    _unknown(contact, MESH_CONTACT_KEYS, "contact.")
    if not isinstance(params.get("file"), str) or not params["file"]:
        raise SceneError("model.file: required for a mesh, a file name (relative to the scene file)")
    if dim == 3 and "thickness" in params:
        raise SceneError("model.thickness: only for 2D (plane stress) meshes")
    _check_patch(params)
    for k in ("E", "nu", "thickness"):
        v = params.get(k, 1.0)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise SceneError(f"model.{k}: must be a finite number, got {v!r}")
    for k, where in (("support_group", "model."), ("group", "contact.")):
        table = params if where == "model." else contact
        v = table.get(k)
        names = [v] if isinstance(v, str) else v
        if v is not None and (not isinstance(names, list) or not names
                              or not all(isinstance(g, str) and g for g in names)):
            raise SceneError(f"{where}{k}: a group name or a list of group names, got {v!r}")
    if ("group" in contact) == ("nodes" in contact):
        raise SceneError("contact.group / contact.nodes: give exactly one (a group of the mesh, or node ids)")
    if ("normals" in contact) == has_obstacle:
        raise SceneError("contact.normals / obstacle: give exactly one (normals per contact node, "
                         "or [[obstacle]] surfaces)")
    if "tangents" in contact and "normals" not in contact:
        raise SceneError("contact.tangents: only with contact.normals")
    v = contact.get("tolerance", 1.0)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise SceneError(f"contact.tolerance: must be a finite number > 0, got {v!r}")


#: Scene fields that are no key of the scene: its text, where it lies, where its obstacles came from
_NOT_KEYS = ("text", "base_dir", "obstacle_key")


def scene_record(scene: Scene) -> dict[str, object]:
    """The part of a scene that the answers depend on: every field but the run settings
    (keys.SETTINGS) and what is no key (the text, its folder). Two scenes with equal records
    have the same answers, bit for bit (SPEC §5)."""
    skip = {*_NOT_KEYS, *(path.split(".")[-1] for path in SETTINGS)}
    return {f.name: getattr(scene, f.name) for f in fields(scene) if f.name not in skip}


def changed_settings(saved: str, now: str) -> list[str] | None:
    """The run settings (keys.SETTINGS, "run.<key>") in which two scene texts differ when
    their records (scene_record) are equal: [] when they differ in comments, layout or
    defaults written out only; None when they are other scenes (or either is not a valid
    scene). The one rule of "the same scene" for checkpoints and results."""
    try:
        old, new = (parse_scene(tomllib.loads(t.lstrip("\ufeff"))) for t in (saved, now))
    except (tomllib.TOMLDecodeError, SceneError):
        return None
    if scene_record(old) != scene_record(new):
        return None
    return [path for path in SETTINGS if getattr(old, path.split(".")[-1]) != getattr(new, path.split(".")[-1])]
