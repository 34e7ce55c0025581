"""Scenes made in Python: a dict, a built-in's parameters, a condensed stiffness, a truss.

Every one becomes a scene table that goes through the one validator (parse.parse_scene), so
every check, default and error (a SceneError naming the key) is the parser's; the table is
kept as TOML text (Scene.text): its hash identifies the scene, and a result file stores it.
"""
from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Mapping, Sequence
from typing import Any

from hpcwedge.scene.parse import COMPUTE_DEFAULTS, NUMBER_TYPES, RUN_DEFAULTS, Scene, SceneError, array, parse_scene

#: the friction coefficient at which the Python constructors enumerate when no `mu` is given
#: (the SPEC's example). mu^c does not depend on it: with no wedged cone at mu, the global
#: mu^c is searched below mu_max.
DEFAULT_MU = 0.65


# --------------------------------------------------------------------------- scenes

def scene_from_dict(data: Mapping, *, base_dir: str | None = None) -> Scene:
    """The Scene of a scene table given as a dict (the TOML file's structure, SPEC §3).

    Parameters
    ----------
    data : Mapping
        ``{"name", "dim", "model": {...}, "friction": {"mu": ...}, "compute": {...}, ...}``.
        Values may be numpy arrays and scalars and tuples (stored as lists); a key whose
        value is None is left out (its default applies).
    base_dir : str, optional
        The folder that relative file names (``model.file``) are relative to; default: the
        current directory at the time of the call.

    Returns
    -------
    Scene
        Validated by scene.parse_scene; ``Scene.text`` is the table as TOML.

    Raises
    ------
    SceneError
        One line naming the key and the reason.

    Examples
    --------
    >>> s = scene_from_dict({"name": "v", "dim": 2, "model": {"kind": "vgroove_bar"},
    ...                      "friction": {"mu": [0.5, 1.0]}})
    >>> s.mu, s.kind
    ((0.5, 1.0), 'vgroove_bar')
    >>> scene_from_dict({"name": "v", "dim": 2, "model": {"kind": "vgroove_bar"},
    ...                  "friction": {"mu": -1}})
    Traceback (most recent call last):
    hpcwedge.scene.parse.SceneError: friction.mu: every value must be a finite number > 0, got -1
    """
    if not isinstance(data, Mapping):
        raise SceneError(f"scene: must be a table (a dict), got {type(data).__name__}")
    plain = _plain(data, "")
    text = _toml(plain)
    # the table as its TOML text reads back (tests/test_api: the same), without parsing it
    # again (a 1,000 x 1,000 K: 6.5 s of tomllib)
    return parse_scene(plain, text=text, base_dir=os.path.abspath(base_dir or os.getcwd()))


def builtin_scene(kind: str, *, mu: float | Sequence[float] = DEFAULT_MU, name: str | None = None,
                  **params: Any) -> Scene:
    """The scene of a built-in model (SPEC §6).

    Parameters
    ----------
    kind : str
        ``"plug2d"``, ``"plug3d"``, ``"block2d"`` or ``"vgroove_bar"``.
    mu : float or sequence of float
        The friction coefficient(s) to enumerate at (friction.mu).
    name : str, optional
        The scene's name (default: the kind).
    **params
        The model's parameters (``rows``, ``taper_deg``...) and any [compute] or [run]
        option (``mu_c="global"``, ``enumerate=False``, ``symmetry=False``...).

    Examples
    --------
    >>> s = builtin_scene("plug2d", rows=3, mu=[0.3, 0.65], mu_c="global")
    >>> s.dim, s.model, s.mu, s.mu_c
    (2, {'rows': 3}, (0.3, 0.65), 'global')
    >>> builtin_scene("plug2d", row=3)
    Traceback (most recent call last):
    hpcwedge.scene.parse.SceneError: model.row: unknown parameter of plug2d (allowed: rows, cols, taper_deg)
    """
    from hpcwedge.models.library import BUILTIN_DIM
    if not isinstance(kind, str) or kind not in BUILTIN_DIM:
        raise SceneError(f"model.kind: {kind!r} is not a built-in model (one of {', '.join(BUILTIN_DIM)}; "
                         "Scene.from_stiffness, Scene.from_truss or Scene.load for the others)")
    model = {k: v for k, v in params.items() if k not in COMPUTE_DEFAULTS and k not in RUN_DEFAULTS}
    options = {k: v for k, v in params.items() if k not in model}
    return scene_from_dict({"name": name or kind, "dim": BUILTIN_DIM[kind], "model": {"kind": kind, **model},
                            "friction": {"mu": mu}, **_tables(options)})


def stiffness_scene(K: Any, *, dim: int, null_space: Any = None, mu: float | Sequence[float] = DEFAULT_MU,
                    name: str = "stiffness", **options: Any) -> Scene:
    """The scene of a condensed stiffness given as an array (``kind = "stiffness"``).

    Parameters
    ----------
    K : array_like or scipy sparse matrix, (dim*m, dim*m)
        The condensed, block-ordered local stiffness of the m contact nodes (SPEC §1, §3);
        kept dense (it is dense once condensed).
    dim : int
        2 or 3.
    null_space : array_like, optional
        Its rigid modes as columns; without it a singular K must have an unambiguous null
        space (the parser's rank test).
    mu, name, **options
        As for `builtin_scene` ([compute] and [run] options only).

    Notes
    -----
    The table is checked here; K itself (symmetric, semidefinite, its null space) when the
    scene is solved, as for a scene file.

    Examples
    --------
    One contact node: mu^c = K_tt / |K_nt| (SPEC §6).

    >>> s = stiffness_scene([[2.0, 1.0], [1.0, 4.0]], dim=2, mu=5.0)
    >>> round(solve(s).mu_c, 12)
    4.0
    >>> solve(stiffness_scene([[1.0, 2.0], [0.0, 1.0]], dim=2))
    Traceback (most recent call last):
    hpcwedge.scene.parse.SceneError: model.K: not symmetric (max |K - K^T| = 2)
    """
    model = {"kind": "stiffness", "K": K, "null_space": null_space}
    return scene_from_dict({"name": name, "dim": dim, "model": model, "friction": {"mu": mu},
                            **_tables(options)})


def truss_scene(nodes: Any, bars: Any, *, contact_nodes: Any, normals: Any, EA: Any = 1.0,
                supports: Any = None, tangents: Any = None, mu: float | Sequence[float] = DEFAULT_MU,
                name: str = "truss", **options: Any) -> Scene:
    """The scene of a truss given as arrays (``kind = "truss"``); dim is the number of
    coordinates per node.

    Parameters
    ----------
    nodes : array_like, (n, dim)
        Node coordinates.
    bars : array_like of int, (b, 2)
        0-based node pairs.
    contact_nodes : array_like of int, (m,)
        The nodes in contact, in the order of the contact list.
    normals : array_like, (m, dim)
        Their contact normals (into the body); 3D: optional `tangents` (m, dim).
    EA : float or array_like, (b,)
        Axial stiffness, one or per bar.
    supports : array_like of int, (s, 2), optional
        [node, dof] pairs held fixed.
    mu, name, **options
        As for `builtin_scene` ([compute] and [run] options only).

    Examples
    --------
    A bar between two walls at 30 degrees from vertical (vgroove_bar): mu^c = tan 30.

    >>> s = truss_scene([[-1.0, 0.0], [1.0, 0.0]], [[0, 1]], contact_nodes=[0, 1], EA=2.0,
    ...                 normals=[[math.cos(math.pi / 6), math.sin(math.pi / 6)],
    ...                          [-math.cos(math.pi / 6), math.sin(math.pi / 6)]])
    >>> abs(solve(s).mu_c - math.tan(math.pi / 6)) < 1e-12
    True
    """
    dim = array(nodes, "model.nodes", 2).shape[1]
    model = {"kind": "truss", "nodes": nodes, "bars": bars, "EA": EA, "supports": supports}
    contact = {"nodes": contact_nodes, "normals": normals, "tangents": tangents}
    return scene_from_dict({"name": name, "dim": dim, "model": model, "contact": contact,
                            "friction": {"mu": mu}, **_tables(options)})


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
