"""Scene tables from Python values: a dict, a built-in's parameters, a condensed stiffness, a
truss. Each builder returns the table (the TOML file's structure, SPEC §3) that
parse.parse_scene validates; `plain_table` makes a table plain (lists, numbers, strings)
and writes it as TOML text, which Scene.text keeps."""
from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

from hpcwedge.models.library import BUILTIN_DIM
from hpcwedge.scene.values import COMPUTE_DEFAULTS, NUMBER_TYPES, RUN_DEFAULTS, SceneError, array

#: the friction coefficient at which the Python constructors enumerate when no `mu` is given
#: (the SPEC's example). mu^c does not depend on it: with no wedged cone at mu, the global
#: mu^c is searched below mu_max.
DEFAULT_MU = 0.65


def plain_table(data: Mapping) -> tuple[dict, str]:
    """(the table with plain values, its TOML text); SceneError naming a bad key or value."""
    if not isinstance(data, Mapping):
        raise SceneError(f"scene: must be a table (a dict), got {type(data).__name__}")
    plain = _plain(data, "")
    return plain, _toml(plain)


def builtin_table(kind: str, *, mu: float | Sequence[float] = DEFAULT_MU, name: str | None = None,
                  **params: Any) -> dict:
    """The table of a built-in model; params: its generator's parameters and any [compute] or
    [run] option."""
    if not isinstance(kind, str) or kind not in BUILTIN_DIM:
        raise SceneError(f"model.kind: {kind!r} is not a built-in model (one of {', '.join(BUILTIN_DIM)}; "
                         "Scene.from_stiffness, Scene.from_truss or Scene.load for the others)")
    model = {k: v for k, v in params.items() if k not in COMPUTE_DEFAULTS and k not in RUN_DEFAULTS}
    options = {k: v for k, v in params.items() if k not in model}
    return {"name": name or kind, "dim": BUILTIN_DIM[kind], "model": {"kind": kind, **model},
            "friction": {"mu": mu}, **_tables(options)}


def stiffness_table(K: Any, *, dim: int, null_space: Any = None, mu: float | Sequence[float] = DEFAULT_MU,
                    name: str = "stiffness", **options: Any) -> dict:
    """The table of a condensed stiffness given as an array (kind = "stiffness")."""
    model = {"kind": "stiffness", "K": K, "null_space": null_space}
    return {"name": name, "dim": dim, "model": model, "friction": {"mu": mu}, **_tables(options)}


def truss_table(nodes: Any, bars: Any, *, contact_nodes: Any, normals: Any, EA: Any = 1.0,
                supports: Any = None, tangents: Any = None, mu: float | Sequence[float] = DEFAULT_MU,
                name: str = "truss", **options: Any) -> dict:
    """The table of a truss given as arrays (kind = "truss"); dim from the nodes' coordinates."""
    dim = array(nodes, "model.nodes", 2).shape[1]
    model = {"kind": "truss", "nodes": nodes, "bars": bars, "EA": EA, "supports": supports}
    contact = {"nodes": contact_nodes, "normals": normals, "tangents": tangents}
    return {"name": name, "dim": dim, "model": model, "contact": contact, "friction": {"mu": mu},
            **_tables(options)}


def _tables(options: Mapping) -> dict:
    """{"compute": {...}, "run": {...}} of keyword options; SceneError for any other key."""
    out: dict = {"compute": {}, "run": {}}
    for k, v in options.items():
        table = "compute" if k in COMPUTE_DEFAULTS else "run" if k in RUN_DEFAULTS else None
        if table is None:
            raise SceneError(f"{k}: unknown option (compute: {', '.join(COMPUTE_DEFAULTS)}; "
                             f"run: {', '.join(RUN_DEFAULTS)})")
        out[table][k] = v
    return out


def _plain(value: Any, key: str) -> Any:
    """value with numpy arrays and scalars as Python lists and numbers, scipy sparse matrices
    as dense lists, tuples as lists and None entries of tables left out; SceneError naming
    the key for anything TOML cannot hold."""
    if isinstance(value, Mapping):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise SceneError(f"{key + '.' if key else ''}{k!r}: keys must be strings")
            if v is not None:
                out[k] = _plain(v, f"{key}.{k}" if key else k)
        return out
    if hasattr(value, "toarray") and hasattr(value, "nnz"):               # scipy sparse
        value = value.toarray()
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):    # numpy array or scalar
        numeric = getattr(value, "dtype", None) is not None and value.dtype.kind in "fiu"
        value = value.tolist()
        if numeric:
            return value                           # nested lists of Python floats / ints
    if isinstance(value, (list, tuple)):
        if set(map(type, value)) <= NUMBER_TYPES:      # a row of numbers: nothing to convert
            return list(value)
        return [_plain(v, key) for v in value]
    if isinstance(value, (bool, int, float, str)):
        return value
    raise SceneError(f"{key or 'scene'}: a scene value is a number, string, boolean, list or table, "
                     f"got {type(value).__name__}")


_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _toml(table: dict) -> str:
    """The scene table (plain values: _plain) as TOML text: top-level values first, then
    one [section] per table, nested tables inline; tomllib.loads gives the table back."""
    lines = [f"{_key(k)} = {_value(v)}" for k, v in table.items() if not isinstance(v, dict)]
    for k, v in table.items():
        if isinstance(v, dict):
            lines += ["", f"[{_key(k)}]"] + [f"{_key(kk)} = {_value(vv)}" for kk, vv in v.items()]
    return "\n".join(lines) + "\n"


def _key(k: str) -> str:
    return k if _BARE_KEY.fullmatch(k) else _string(k)


def _string(s: str) -> str:
    return json.dumps(s, ensure_ascii=False).replace("\x7f", "\\u007f")


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("nan" if math.isnan(v) else ("inf" if v > 0 else "-inf"))
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, list):
        if set(map(type, v)) <= NUMBER_TYPES:          # repr of a float is TOML's (nan, inf, -inf too)
            return "[" + ", ".join(map(repr, v)) + "]"
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
