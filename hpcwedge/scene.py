"""Scenes (SPEC §3): TOML -> a validated, frozen Scene, and the plan of stages.

Every error is a SceneError whose one-line message names the key and the
reason; the command line turns it into exit status 2 with nothing written.
"""
from __future__ import annotations

import hashlib
import inspect
import math
import os
import tomllib
from dataclasses import dataclass, field

import numpy as np

from .models.library import BUILTIN_DIM, BUILTINS  # the one table of built-ins

KINDS = ("stiffness", "truss", "mesh") + tuple(BUILTINS)

TOP_KEYS = {"name", "dim", "model", "friction", "compute", "run", "contact"}
COMPUTE_DEFAULTS = {"enumerate": True, "mu_c": "cones", "mu_c_method": "accurate",
                    "mu_c_tol": 1e-6, "mu_max": 100.0, "exact": False,
                    "exact_fallback_max_m": 10}
RUN_DEFAULTS = {"checkpoint_every_s": 60.0, "task_budget": 64}


class SceneError(ValueError):
    """Bad input: the message is one line naming the key and the reason."""


@dataclass(frozen=True)
class Plan:
    """Which stages a scene needs (the one place that decides what to skip)."""

    condense: bool       # a model to assemble and condense (not a raw K)
    rays: bool           # 2D: complementary extreme rays per listed mu
    cones: bool          # 2D: cross-complementarity cliques
    patterns: bool       # 3D (2D with enumerate = "patterns"): feasible sign patterns per listed mu
    mu_c_cones: bool     # mu^c of every cone / pattern
    mu_c_global: bool


@dataclass(frozen=True)
class Scene:
    name: str
    dim: int
    kind: str
    model: dict
    contact: dict
    mu: tuple[float, ...]
    enumerate: bool | str
    mu_c: str
    mu_c_method: str
    mu_c_tol: float
    mu_max: float
    exact: bool
    checkpoint_every_s: float
    text: str = field(repr=False, default="")
    base_dir: str = "."
    task_budget: int = 64          # run.task_budget: tree nodes per sign-pattern task (parallel.py)
    #: compute.exact_fallback_max_m: a 2D float enumeration whose decisions were too close to
    #: call is redone in exact arithmetic when m is at most this (0: never; pipeline.py)
    exact_fallback_max_m: int = 10

    @property
    def hash(self) -> str:
        return hashlib.sha256(self.text.encode()).hexdigest()

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


def load_scene(path: str) -> Scene:
    """Read and validate a scene file."""
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except OSError as e:
        raise SceneError(f"{path}: cannot read ({e.strerror})") from None
    try:
        text = raw.decode()
        data = tomllib.loads(text)
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise SceneError(f"{path}: not valid TOML ({e})") from None
    return parse_scene(data, text=text, base_dir=os.path.dirname(os.path.abspath(path)))


def parse_scene(data: dict, text: str = "", base_dir: str = ".") -> Scene:
    _unknown(data, TOP_KEYS, "")
    name = data.get("name")
    if not isinstance(name, str) or not name:
        raise SceneError("name: required, a non-empty string")
    dim = data.get("dim")
    if dim not in (2, 3) or isinstance(dim, bool):
        raise SceneError(f"dim: must be 2 or 3, got {dim!r}")
    model = data.get("model")
    if not isinstance(model, dict) or "kind" not in model:
        raise SceneError("model.kind: required")
    kind = model["kind"]
    if kind not in KINDS:
        raise SceneError(f"model.kind: unknown kind {kind!r} (one of {', '.join(KINDS)})")
    if kind in BUILTIN_DIM and BUILTIN_DIM[kind] != dim:
        raise SceneError(f"dim: {kind} is a {BUILTIN_DIM[kind]}D model, scene says dim = {dim}")
    if kind == "mesh":
        raise SceneError("model.kind: 'mesh' scenes are not supported yet")
    friction = data.get("friction")
    if not isinstance(friction, dict) or "mu" not in friction:
        raise SceneError("friction.mu: required (one value or a list)")
    _unknown(friction, {"mu"}, "friction.")
    mus = friction["mu"] if isinstance(friction["mu"], list) else [friction["mu"]]
    if not mus:
        raise SceneError("friction.mu: empty list")
    for v in mus:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise SceneError(f"friction.mu: every value must be a finite number > 0, got {v!r}")
    compute = dict(COMPUTE_DEFAULTS)
    given = data.get("compute", {})
    _unknown(given, set(COMPUTE_DEFAULTS), "compute.")
    compute.update(given)
    if compute["enumerate"] not in (True, False, "rays", "patterns"):
        raise SceneError(f"compute.enumerate: true, false, \"rays\" or \"patterns\", "
                         f"got {compute['enumerate']!r}")
    if compute["mu_c"] not in ("none", "global", "cones"):
        raise SceneError(f"compute.mu_c: \"none\", \"global\" or \"cones\", got {compute['mu_c']!r}")
    if compute["mu_c_method"] not in ("accurate", "bisection"):
        raise SceneError(f"compute.mu_c_method: \"accurate\" or \"bisection\", got {compute['mu_c_method']!r}")
    for key in ("mu_c_tol", "mu_max"):
        v = compute[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise SceneError(f"compute.{key}: must be a finite number > 0, got {v!r}")
    if not isinstance(compute["exact"], bool):
        raise SceneError(f"compute.exact: true or false, got {compute['exact']!r}")
    v = compute["exact_fallback_max_m"]
    if isinstance(v, bool) or not isinstance(v, int) or v < 0:
        raise SceneError(f"compute.exact_fallback_max_m: must be a whole number >= 0, got {v!r}")
    if compute["exact"] and dim == 3:
        raise SceneError("compute.exact: exact arithmetic is for 2D scenes (3D problems are conic)")
    run = dict(RUN_DEFAULTS)
    run.update(data.get("run", {}))
    _unknown(run, set(RUN_DEFAULTS), "run.")
    v = run["checkpoint_every_s"]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or v <= 0:
        raise SceneError(f"run.checkpoint_every_s: must be a number > 0, got {v!r}")
    v = run["task_budget"]
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise SceneError(f"run.task_budget: must be a whole number >= 1, got {v!r}")
    contact = data.get("contact", {})
    if not isinstance(contact, dict):
        raise SceneError("contact: must be a table")
    params = {k: v for k, v in model.items() if k != "kind"}
    if kind in BUILTINS:
        _check_builtin(kind, params)
    return Scene(name=name, dim=dim, kind=kind, model=params, contact=contact,
                 mu=tuple(sorted(float(v) for v in mus)), enumerate=compute["enumerate"],
                 mu_c=compute["mu_c"], mu_c_method=compute["mu_c_method"],
                 mu_c_tol=float(compute["mu_c_tol"]), mu_max=float(compute["mu_max"]),
                 exact=compute["exact"], checkpoint_every_s=float(run["checkpoint_every_s"]),
                 text=text, base_dir=base_dir, task_budget=run["task_budget"],
                 exact_fallback_max_m=compute["exact_fallback_max_m"])


def _unknown(table, allowed, prefix):
    if not isinstance(table, dict):
        raise SceneError(f"{prefix.rstrip('.') or 'scene'}: must be a table")
    for k in table:
        if k not in allowed:
            raise SceneError(f"{prefix}{k}: unknown key (allowed: {', '.join(sorted(allowed))})")


def _check_builtin(kind: str, params: dict) -> None:
    sig = inspect.signature(BUILTINS[kind])
    for k, v in params.items():
        if k not in sig.parameters:
            raise SceneError(f"model.{k}: unknown parameter of {kind} (allowed: {', '.join(sig.parameters)})")
        default = sig.parameters[k].default
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise SceneError(f"model.{k}: must be a finite number, got {v!r}")
        if isinstance(default, int) and not isinstance(default, bool):
            if not isinstance(v, int) or v < 1:
                raise SceneError(f"model.{k}: must be a whole number >= 1, got {v!r}")


def array(value, key: str, ndim: int | None = None) -> np.ndarray:
    """A finite float array from a scene value, or a SceneError naming key."""
    from .model import as_float_array
    try:
        return as_float_array(value, key, ndim)
    except ValueError as e:
        raise SceneError(str(e)) from None
