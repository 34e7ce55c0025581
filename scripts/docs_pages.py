"""Generated documentation pages: the scene reference and the benchmark tables.

The scene reference is built from the parser's own key sets and defaults (hpcwedge/scene.py:
TOP_KEYS, COMPUTE_DEFAULTS, RUN_DEFAULTS, MESH_MODEL_KEYS, ...; models/obstacle.py:
OBSTACLE_KEYS; the built-ins' signatures in models/library.py), so it cannot drift from what
a scene may say: only the meaning of each key is written here, in MEANINGS (one table, key ->
(type, unit, meaning)). A key the parser accepts without a meaning is an error (KeyError), and
so is a meaning for a key the parser no longer accepts (tests/test_docs.py).

The benchmark tables are rendered from results/*.json (never copied by hand); see BENCHMARKS.

Used by scripts/mkdocs_hooks.py at build time; `python scripts/docs_pages.py scene` prints the
reference page.
"""
from __future__ import annotations

import inspect
import json
import math
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REQUIRED = "required"
NONE = "—"

#: key -> (type, unit, meaning), per table. Tables: "scene" (top level), "friction",
#: "compute", "run", "model.<kind>", "contact.<kind>", "obstacle.<type>", and "builtin" for
#: the parameters of the built-in models (shared by name across them).
MEANINGS: dict[str, dict[str, tuple[str, str, str]]] = {
    "scene": {
        "name": ("string", "", "Name of the scene, copied into the result."),
        "dim": ("2 or 3", "", "Dimension. 2: rays and cones; 3: sign patterns."),
        "model": ("table", "", "The body: `kind` and the kind's keys (below)."),
        "friction": ("table", "", "Friction coefficients (`mu`)."),
        "compute": ("table", "", "What to compute."),
        "run": ("table", "", "How to run it (checkpoints, tasks, memory)."),
        "contact": ("table", "", "Contact nodes and their frames (truss and mesh)."),
        "obstacle": ("array of tables", "", "Rigid obstacle surfaces (mesh): normals from the nearest one."),
    },
    "model": {
        "kind": ("string", "", "The kind of body: {kinds}. The other keys of [model] depend on it (below)."),
    },
    "friction": {
        "mu": ("number or list of numbers", "1", "Coulomb friction coefficients to enumerate at, each in [1e-6, 1e6]."),
    },
    "compute": {
        "enumerate": ('true, false, "rays" or "patterns"', "",
                      "2D: rays and cones (true), rays only (\"rays\"), sign patterns (\"patterns\"); "
                      "3D always sign patterns; false: nothing is enumerated."),
        "mu_c": ('"none", "global" or "cones"', "",
                 "Critical friction coefficient: none, only the global mu^c (cheapest route), or "
                 "mu^c of every cone / pattern and the global one."),
        "mu_c_method": ('"accurate" or "bisection"', "",
                        "accurate: bracket then a verified polish to ~1e-12; bisection: plain, to `mu_c_tol` (benchmarks)."),
        "mu_c_tol": ("number", "relative", "Tolerance of the plain bisection (`mu_c_method = \"bisection\"`)."),
        "mu_max": ("number", "1", "Largest mu searched for mu^c; beyond it mu^c is null (`none_up_to_mu_max`)."),
        "exact": ("boolean", "", "2D: exact rational arithmetic throughout (verification; small problems)."),
        "exact_fallback_max_m": ("integer ≥ 0", "contact nodes",
                                 "2D: a float run with decisions too close to call is redone exactly up to this m (0: never)."),
    },
    "run": {
        "checkpoint_every_s": ("number > 0", "s", "Period of the master's checkpoint `RESULT.h5.ckpt`."),
        "task_budget": ("integer ≥ 1", "tree nodes", "Sign-pattern tree nodes per task before a subtree is handed back."),
        "symmetry": ("boolean", "", "Use the node symmetries of K (orbits of patterns, mu^c once per orbit)."),
        "face_split": ('"auto" or integer ≥ 0', "nodes",
                       "2D: branching nodes of the double-description split over faces (\"auto\": 3 from m = 16 on)."),
        "condense": ('"auto", "serial" or "distributed"', "",
                     "Under mpirun: where the static condensation runs (\"auto\": distributed from 2·10^6 DOFs)."),
        "max_memory_gb": ('"auto" or number > 0', "GB",
                          "Memory a run may use, shared by the ranks on a host (\"auto\": 80 % of what is "
                          "available at start). A run about to exceed it stops early, naming this key."),
    },
    "model.stiffness": {
        "K": ("2D array", "force/length", "Condensed, block-ordered stiffness [n.., t..] (3D: [n.., t1.., t2..]), inline."),
        "file": ("path", "", "K (and optionally `null_space`) in a .npy, .npz or .h5 file, relative to the scene file."),
        "null_space": ("2D array", "", "Rigid modes (columns) of a free body; none: a supported body."),
    },
    "model.truss": {
        "nodes": ("array (n, dim)", "length", "Node coordinates."),
        "bars": ("array (b, 2)", "", "Bars as pairs of 0-based node ids."),
        "EA": ("number or array (b,)", "force", "Axial stiffness of every bar (default 1)."),
        "supports": ("array of [node, dof]", "", "Fixed DOFs; none: a free body (rigid modes from the geometry)."),
    },
    "contact.truss": {
        "nodes": ("array of integers", "", "Contact nodes (0-based node ids)."),
        "normals": ("array (m, dim)", "", "Obstacle normal at each contact node, into the body."),
        "tangents": ("array (m, dim)", "", "3D: t1 per contact node (t2 = n × t1); default: the axis least aligned with n."),
    },
    "model.mesh": {
        "file": ("path", "", "Mesh file meshio reads (Gmsh .msh, .vtu, .inp, ...), relative to the scene file."),
        "E": ("number > 0", "force/length²", "Young's modulus (default 1)."),
        "nu": ("number in (-1, 0.5)", "1", "Poisson's ratio (default 0.3)."),
        "thickness": ("number > 0", "length", "2D plane stress: thickness (default 1)."),
        "supports": ("array of [node, dof]", "", "Fixed DOFs by node id; none of the support keys: a free body."),
        "support_group": ("string or list", "", "Mesh group(s) whose nodes are supported."),
        "support_dofs": ("array of integers", "", "Only these components of `support_group` nodes (default all)."),
        "contact_patch": ("number ≥ 0", "length", "Half-width a of a contact patch under every contact node (0: point contacts)."),
        "contact_patch_kind": ('"rigid" or "hat"', "", "rigid foot, or hat-weighted mean displacement of the patch."),
    },
    "contact.mesh": {
        "group": ("string or list", "", "Mesh group(s) holding the contact nodes (or `nodes`)."),
        "nodes": ("array of integers", "", "Contact node ids (0-based, in meshio's node order)."),
        "normals": ("array (m, dim)", "", "Normals per contact node instead of obstacles."),
        "tangents": ("array (m, dim)", "", "3D: t1 per contact node, with `normals`."),
        "obstacle": ("array of tables", "", "Obstacles given inside [contact] instead of [[obstacle]]."),
        "tolerance": ("number > 0", "× median element size", "Contact nodes must lie this close to an obstacle (default 1e-4)."),
    },
    "obstacle.plane": {
        "type": ('"plane"', "", "A plane (a line in 2D)."),
        "point": ("array (dim,)", "length", "A point of the plane."),
        "normal": ("array (dim,)", "", "Its normal (either sign)."),
    },
    "obstacle.cone": {
        "type": ('"cone"', "", "A cone's nappe (a V in 2D)."),
        "apex": ("array (dim,)", "length", "Apex."),
        "axis": ("array (dim,)", "", "Axis direction (the nappe opens along it)."),
        "half_angle_deg": ("number", "degree", "Half-angle between the axis and the surface."),
    },
    "builtin": {
        "theta_deg": ("number", "degree", "Groove half-angle."),
        "eps": ("number", "force/length", "Ground spring stiffness (0: a free bar)."),
        "EA": ("number", "force", "Axial stiffness of the bars."),
        "rows": ("integer ≥ 1", "", "Rows of the grid (contact nodes 2(rows+1))."),
        "cols": ("integer ≥ 1", "", "Columns of the grid."),
        "taper_deg": ("number", "degree", "Taper of the walls from the vertical (the axis in 3D); mu^c = tan(taper)."),
        "levels": ("integer ≥ 1", "", "Levels (rings) of contact nodes."),
        "ring": ("integer ≥ 1", "", "Contact nodes per ring."),
        "refine": ("integer ≥ 1", "", "Each coarse element split refine × refine (mesh refinement)."),
        "E": ("number > 0", "force/length²", "Young's modulus."),
        "nu": ("number", "1", "Poisson's ratio."),
        "thickness": ("number > 0", "length", "Plane-stress thickness."),
        "contact_patch": ("number ≥ 0", "length", "Half-width of the contact patches (0: point contacts)."),
        "contact_patch_kind": ('"rigid" or "hat"', "", "Patch model (see model.mesh)."),
    },
}


def accepted_keys() -> dict[str, dict[str, object]]:
    """{table: {key: default}} as the parser has them (REQUIRED where there is no default,
    NONE where absence has a meaning of its own). Tables as in MEANINGS, plus
    "model.<builtin>" for each built-in; read from hpcwedge.scene, models.obstacle and
    models.library, never written here."""
    from hpcwedge import scene
    from hpcwedge.models.library import BUILTINS
    from hpcwedge.models.mesh import DEFAULT_TOLERANCE
    from hpcwedge.models.obstacle import OBSTACLE_KEYS
    req = {"name", "dim", "model", "friction"}
    out: dict[str, dict[str, object]] = {
        "scene": {k: (REQUIRED if k in req else NONE) for k in sorted(scene.TOP_KEYS)},
        "model": {"kind": REQUIRED},
        "friction": {"mu": REQUIRED},
        "compute": dict(scene.COMPUTE_DEFAULTS),
        "run": dict(scene.RUN_DEFAULTS),
    }
    # issue 11 gives stiffness and truss tables explicit key sets in scene.py; before that the
    # stiffness keys lived in build.py and a truss took any key (tests/test_docs.py probes the parser)
    stiffness = getattr(scene, "STIFFNESS_MODEL_KEYS", {"K", "file", "null_space"})
    truss = getattr(scene, "TRUSS_MODEL_KEYS", set(MEANINGS["model.truss"]))
    truss_contact = getattr(scene, "TRUSS_CONTACT_KEYS", set(MEANINGS["contact.truss"]))
    defaults = {"EA": 1.0, "E": 1.0, "nu": 0.3, "thickness": 1.0, "contact_patch": 0.0,
                "contact_patch_kind": "rigid", "tolerance": DEFAULT_TOLERANCE}
    for table, keys in (("model.stiffness", stiffness), ("model.truss", truss),
                        ("contact.truss", truss_contact), ("model.mesh", scene.MESH_MODEL_KEYS),
                        ("contact.mesh", scene.MESH_CONTACT_KEYS)):
        out[table] = {k: defaults.get(k, NONE) for k in sorted(keys)}
    for kind, fields in OBSTACLE_KEYS.items():
        out[f"obstacle.{kind}"] = {"type": REQUIRED, **{f: REQUIRED for f in fields}}
    for kind, fn in BUILTINS.items():
        out[f"model.{kind}"] = {p.name: p.default for p in inspect.signature(fn).parameters.values()}
    return out


def meaning(table: str, key: str) -> tuple[str, str, str]:
    """(type, unit, meaning) of a key; KeyError naming it when MEANINGS lacks it."""
    t = "builtin" if table.startswith("model.") and table[6:] not in ("stiffness", "truss", "mesh") else table
    try:
        return MEANINGS[t][key]
    except KeyError:
        raise KeyError(f"scripts/docs_pages.py MEANINGS: no meaning for {table}.{key}") from None


def stale_meanings() -> list[str]:
    """Keys with a meaning that the parser no longer accepts."""
    acc = accepted_keys()
    used_builtin = {k for t, keys in acc.items() if t.startswith("model.")
                    and t[6:] not in ("stiffness", "truss", "mesh") for k in keys}
    out = []
    for t, keys in MEANINGS.items():
        have = used_builtin if t == "builtin" else set(acc.get(t, {}))
        out += [f"{t}.{k}" for k in keys if k not in have]
    return out


def _fmt(v: object) -> str:
    if v in (REQUIRED, NONE) and isinstance(v, str):
        return v
    if isinstance(v, bool):
        return "`true`" if v else "`false`"
    if isinstance(v, str):
        return f'`"{v}"`'
    return f"`{v!r}`"


TITLES = {
    "scene": "Top level", "model": "[model]", "friction": "[friction]", "compute": "[compute]", "run": "[run]",
    "model.stiffness": '[model] kind = "stiffness"', "model.truss": '[model] kind = "truss"',
    "contact.truss": "[contact] of a truss", "model.mesh": '[model] kind = "mesh"',
    "contact.mesh": "[contact] of a mesh", "obstacle.plane": '[[obstacle]] type = "plane"',
    "obstacle.cone": '[[obstacle]] type = "cone"',
}


def scene_reference() -> str:
    """The Markdown page of every scene key: table, type, default, unit, meaning."""
    from hpcwedge import scene
    lines = ["# Scene reference", "",
             "Every key a scene file may hold, generated at build time from the parser's own key",
             "sets and defaults (`hpcwedge/scene.py`, `models/obstacle.py`, the built-ins'",
             "signatures in `models/library.py`; meanings: `scripts/docs_pages.py`). Any other",
             "key is an error naming it. A built-in `model.kind` takes only its generator's",
             "parameters; its `[contact]` is fixed by the model.", "",
             "*required*: no default. *—*: optional, no default (absent has its own meaning,",
             "given in the text). Units: the scene's own consistent units (mu^c does not depend on",
             "them: stiffnesses are rescaled internally).", ""]
    for table, keys in accepted_keys().items():
        title = TITLES.get(table) or f'[model] kind = "{table[6:]}" (built-in)'
        lines += [f"## {title}", "", "| key | type | default | unit | meaning |",
                  "|---|---|---|---|---|"]
        for k, default in keys.items():
            typ, unit, text = meaning(table, k)
            text = text.replace("{kinds}", ", ".join(f"`{k}`" for k in scene.KINDS))
            lines.append(f"| `{k}` | {typ} | {_fmt(default)} | {unit} | {text} |")
        lines.append("")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# benchmarks: tables rendered from results/*.json

def _load(name: str) -> dict:
    with open(os.path.join(ROOT, "results", name)) as f:
        return json.load(f)


def _num(v: object, digits: int = 3) -> str:
    if v is None:
        return "–"
    if isinstance(v, bool) or isinstance(v, str):
        return str(v)
    if isinstance(v, int):
        return f"{v:,}"
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    return f"{v:.{digits}g}"


def table(header: list[str], rows: list[list[object]]) -> str:
    """A Markdown table; numbers formatted by _num."""
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(_num(c) if not isinstance(c, str) else c for c in r) + " |" for r in rows]
    return "\n".join(out)


#: benchmark name -> function rendering its Markdown table from results/*.json
BENCHMARKS: dict = {}


def render_markers(markdown: str) -> str:
    """Replace every `<!-- bench: NAME -->` line by BENCHMARKS[NAME]() (KeyError if unknown)."""
    out = []
    for line in markdown.split("\n"):
        s = line.strip()
        if s.startswith("<!-- bench:") and s.endswith("-->"):
            name = s[len("<!-- bench:"):-3].strip()
            if name not in BENCHMARKS:
                raise KeyError(f"<!-- bench: {name} -->: no such table in scripts/docs_pages.py BENCHMARKS")
            out.append(BENCHMARKS[name]())
        else:
            out.append(line)
    return "\n".join(out)


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "scene"
    if what == "scene":
        print(scene_reference())
