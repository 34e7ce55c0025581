"""The one table of scene keys (SPEC §3): per key its path, type, allowed values, default,
unit and meaning, and whether it is a run setting (SPEC §5: it changes neither the answers
nor their bits) or changes the answers. The parser's defaults and unknown-key checks, the
API's options and the generated scene reference (scripts/docs_pages.py) read it.

Tables: "scene" (top level), "model", "friction", "compute", "run", "model.<kind>" and
"contact.<kind>" of the stiffness, truss, mesh and matrix kinds, "obstacle.<type>"; a built-in's
[model] keys are its generator's parameters (models/library.py), their meanings in BUILTIN.
"""
from __future__ import annotations

import enum
import inspect
from dataclasses import dataclass

from hpcwedge.models.library import BUILTINS, WHOLE_MINIMUM
from hpcwedge.models.mesh import DEFAULT_TOLERANCE
from hpcwedge.models.patch import KINDS as PATCH_KINDS


class Absent(enum.Enum):
    """A key without a default: REQUIRED, or OPTIONAL (absent has a meaning of its own)."""

    REQUIRED = "required"
    OPTIONAL = "—"


REQUIRED, OPTIONAL = Absent.REQUIRED, Absent.OPTIONAL

#: friction coefficients (friction.mu, compute.mu_max) outside this range overflow or
#: underflow the cone constraints (mu = 1e300, 1e-300: NaN rays, "cone not pointed")
MU_RANGE = (1e-6, 1e6)
#: compute.mu_c_tol is relative: below a few rounding units (2.2e-16) a bisection would never end
MU_C_TOL_MIN = 1e-15
#: model.kind: the kinds of body, the built-ins last
KINDS = ("stiffness", "truss", "mesh", "matrix") + tuple(BUILTINS)
#: run.face_split: at most this many branching nodes
FACE_SPLIT_MAX = 8
ENUMERATE = (True, False, "rays", "patterns")
MU_C = ("none", "global", "cones")
MU_C_METHODS = ("accurate", "bisection")
#: run.condense: where the condensation runs under mpirun (run/batch.py, condense.condense_distributed)
CONDENSE_MODES = ("auto", "serial", "distributed")
#: the run settings, in the order a note on changed settings names them
SETTINGS = ("run.max_memory_gb", "run.checkpoint_every_s", "run.progress_every_s")


@dataclass(frozen=True)
class Key:
    """One key of a table: `values` is what the type admits ("" for any value of it)."""

    table: str
    name: str
    type: str
    default: object
    values: str
    unit: str
    meaning: str

    @property
    def path(self) -> str:
        """The key as a scene file and its errors name it: "compute.mu_c_tol", "model.EA"."""
        head = self.table.split(".")[0]
        return self.name if head == "scene" else f"{head}.{self.name}"

    @property
    def setting(self) -> bool:
        """A run setting (SETTINGS): a checkpoint resumes, and a result stands, under another value."""
        return self.path in SETTINGS


def choices(values) -> str:
    """'"a", "b" or "c"' (true / false bare) as the parser's messages list allowed values."""
    text = [("true" if v else "false") if isinstance(v, bool) else f'"{v}"' for v in values]
    return ", ".join(text[:-1]) + " or " + text[-1]


_MU = f"[{MU_RANGE[0]:g}, {MU_RANGE[1]:g}]"

KEYS: tuple[Key, ...] = (
    Key("scene", "compute", "table", OPTIONAL, "", "", "What to compute."),
    Key("scene", "contact", "table", OPTIONAL, "", "", "Contact nodes and their frames (truss and mesh)."),
    Key("scene", "dim", "integer", REQUIRED, "2 or 3", "", "Dimension. 2: rays and cones; 3: sign patterns."),
    Key("scene", "friction", "table", REQUIRED, "", "", "Friction coefficients (`mu`)."),
    Key("scene", "model", "table", REQUIRED, "", "", "The body: `kind` and the kind's keys (below)."),
    Key("scene", "name", "string", REQUIRED, "non-empty", "", "Name of the scene, copied into the result."),
    Key("scene", "obstacle", "array of tables", OPTIONAL, "", "",
        "Rigid obstacle surfaces (mesh): normals from the nearest one."),
    Key("scene", "run", "table", OPTIONAL, "", "", "How to run it (checkpoints, tasks, memory)."),
    Key("model", "kind", "string", REQUIRED, ", ".join(f"`{k}`" for k in KINDS), "",
        "The kind of body. The other keys of [model] depend on it (below)."),
    Key("friction", "mu", "number or list of numbers", REQUIRED, _MU, "1",
        "Coulomb friction coefficients to enumerate at, each listed once (a run per value, in increasing order)."),
    Key("compute", "enumerate", "boolean or string", True, choices(ENUMERATE), "",
        "2D: rays and cones (true), rays only (\"rays\"), sign patterns (\"patterns\"); "
        "3D always sign patterns; false: nothing is enumerated."),
    Key("compute", "mu_c", "string", "cones", choices(MU_C), "",
        "Critical friction coefficient: none, only the global mu^c (cheapest route), or "
        "mu^c of every cone / pattern and the global one."),
    Key("compute", "mu_c_method", "string", "accurate", choices(MU_C_METHODS), "",
        "accurate: bracket then a verified polish to ~1e-12; bisection: plain, to `mu_c_tol` (benchmarks)."),
    Key("compute", "mu_c_tol", "number", 1e-6, f"[{MU_C_TOL_MIN:g}, 1)", "relative",
        "Tolerance of the plain bisection (`mu_c_method = \"bisection\"`)."),
    Key("compute", "mu_max", "number", 100.0, _MU, "1",
        "Largest mu searched for mu^c; beyond it mu^c is null (`none_up_to_mu_max`)."),
    Key("compute", "exact", "boolean", False, "", "",
        "2D: exact rational arithmetic throughout (verification; small problems)."),
    Key("compute", "exact_fallback_max_m", "integer", 10, "≥ 0", "contact nodes",
        "2D: a float run with decisions too close to call is redone exactly up to this m (0: never)."),
    Key("run", "checkpoint_every_s", "number", 60.0, "> 0", "s", "Period of the master's checkpoint `RESULT.h5.ckpt`."),
    Key("run", "progress_every_s", "number", 10.0, "> 0", "s",
        "Period of the progress lines on stderr when it is no terminal (a batch log; `-q`: none)."),
    Key("run", "task_budget", "integer", 64, "≥ 1", "tree nodes",
        "Sign-pattern tree nodes per task before a subtree is handed back."),
    Key("run", "symmetry", "boolean", True, "", "",
        "Use the node symmetries of K (orbits of patterns, mu^c once per orbit)."),
    Key("run", "face_split", "string or integer", "auto", f'"auto" or 0..{FACE_SPLIT_MAX}', "nodes",
        "2D: branching nodes of the double-description split over faces (\"auto\": 3 from m = 16 on)."),
    Key("run", "condense", "string", "auto", choices(CONDENSE_MODES), "",
        "Under mpirun: where the static condensation runs (\"auto\": distributed from 2·10^6 DOFs)."),
    Key("run", "max_memory_gb", "string or number", "auto", '"auto" or > 0', "GB",
        "Memory a run may use, shared by the ranks on a host (\"auto\": 80 % of what is "
        "available at start). A run about to exceed it stops early, naming this key."),
    Key("run", "screens", "boolean", False, "", "",
        "3D: LP screens (COIN-OR CLP) before the SOCP of every sign-pattern tree node with 40 % of the "
        "nodes fixed: fewer SOCPs (plug3d 3 × 6: 6.7 per pattern against 57), about the same time."),
    Key("model.stiffness", "K", "2D array", OPTIONAL, "", "force/length",
        "Condensed, block-ordered stiffness [n.., t..] (3D: [n.., t1.., t2..]), inline."),
    Key("model.stiffness", "file", "path", OPTIONAL, "", "",
        "K (and optionally `null_space`) in a .npy, .npz or .h5 file, relative to the scene file."),
    Key("model.stiffness", "null_space", "2D array", OPTIONAL, "", "",
        "Rigid modes (columns) of a free body; none: a supported body."),
    Key("model.truss", "EA", "number or array (b,)", 1.0, "", "force", "Axial stiffness of every bar."),
    Key("model.truss", "bars", "array (b, 2)", OPTIONAL, "", "", "Bars as pairs of 0-based node ids."),
    Key("model.truss", "nodes", "array (n, dim)", OPTIONAL, "", "length", "Node coordinates."),
    Key("model.truss", "supports", "array of [node, dof]", OPTIONAL, "", "",
        "Fixed DOFs; none: a free body (rigid modes from the geometry)."),
    Key("contact.truss", "nodes", "array of integers", OPTIONAL, "", "", "Contact nodes (0-based node ids)."),
    Key("contact.truss", "normals", "array (m, dim)", OPTIONAL, "", "",
        "Obstacle normal at each contact node, into the body."),
    Key("contact.truss", "tangents", "array (m, dim)", OPTIONAL, "", "",
        "3D: t1 per contact node (t2 = n × t1); default: the axis least aligned with n."),
    Key("model.mesh", "E", "number", 1.0, "> 0", "force/length²", "Young's modulus."),
    Key("model.mesh", "contact_patch", "number", 0.0, "≥ 0", "length",
        "Half-width a of a contact patch under every contact node (0: point contacts)."),
    Key("model.mesh", "contact_patch_kind", "string", "rigid", choices(PATCH_KINDS), "",
        "rigid foot, or hat-weighted mean displacement of the patch."),
    Key("model.mesh", "file", "path", REQUIRED, "", "",
        "Mesh file meshio reads (Gmsh .msh, .vtu, .inp, ...), relative to the scene file."),
    Key("model.mesh", "nu", "number", 0.3, "(-1, 0.5)", "1", "Poisson's ratio."),
    Key("model.mesh", "support_dofs", "array of integers", OPTIONAL, "", "",
        "Only these components of `support_group` nodes (default all)."),
    Key("model.mesh", "support_group", "string or list", OPTIONAL, "", "", "Mesh group(s) whose nodes are supported."),
    Key("model.mesh", "supports", "array of [node, dof]", OPTIONAL, "", "",
        "Fixed DOFs by node id; none of the support keys: a free body."),
    Key("model.mesh", "thickness", "number", 1.0, "> 0", "length", "2D plane stress: thickness."),
    Key("contact.mesh", "group", "string or list", OPTIONAL, "", "",
        "Mesh group(s) holding the contact nodes (or `nodes`)."),
    Key("contact.mesh", "nodes", "array of integers", OPTIONAL, "", "",
        "Contact node ids (0-based, in meshio's node order)."),
    Key("contact.mesh", "normals", "array (m, dim)", OPTIONAL, "", "",
        "Normals per contact node instead of obstacles."),
    Key("contact.mesh", "obstacle", "array of tables", OPTIONAL, "", "",
        "Obstacles given inside [contact] instead of [[obstacle]]."),
    Key("contact.mesh", "tangents", "array (m, dim)", OPTIONAL, "", "", "3D: t1 per contact node, with `normals`."),
    Key("contact.mesh", "tolerance", "number", DEFAULT_TOLERANCE, "> 0", "× median element size",
        "Contact nodes must lie this close to an obstacle."),
    Key("model.matrix", "K", "path", REQUIRED, "", "",
        "Stiffness assembled by another FE code: MatrixMarket .mtx (symmetric or general storage), PETSc "
        "binary .petsc or scipy.sparse .npz, (dim·nodes)², node-major DOFs (node i: dim·i .. dim·i + dim - 1), "
        "supports not applied; relative to the scene file."),
    Key("model.matrix", "nodes", "path or array (n, dim)", REQUIRED, "", "length",
        "Node coordinates: .csv (x,y[,z] per line, one header line allowed), .npy, or inline; "
        "they give the rigid modes and the pictures."),
    Key("model.matrix", "supports", "array of [node, dof]", OPTIONAL, "", "",
        "Fixed DOFs; none: a free body (K must annihilate the nodes' rigid modes)."),
    Key("model.matrix", "mesh", "path", OPTIONAL, "", "",
        "Cells for pictures and VTU (a file meshio reads), the same node numbering; none: nodes only."),
    Key("contact.matrix", "nodes", "array of integers", REQUIRED, "", "", "Contact nodes (0-based node ids)."),
    Key("contact.matrix", "normals", "array (m, dim)", REQUIRED, "", "",
        "Obstacle normal at each contact node, into the body."),
    Key("contact.matrix", "tangents", "array (m, dim)", OPTIONAL, "", "",
        "3D: t1 per contact node (t2 = n × t1); default: the axis least aligned with n."),
    Key("obstacle.plane", "type", "string", REQUIRED, '"plane"', "", "A plane (a line in 2D)."),
    Key("obstacle.plane", "point", "array (dim,)", REQUIRED, "", "length", "A point of the plane."),
    Key("obstacle.plane", "normal", "array (dim,)", REQUIRED, "", "", "Its normal (either sign)."),
    Key("obstacle.cone", "type", "string", REQUIRED, '"cone"', "", "A cone's nappe (a V in 2D)."),
    Key("obstacle.cone", "apex", "array (dim,)", REQUIRED, "", "length", "Apex."),
    Key("obstacle.cone", "axis", "array (dim,)", REQUIRED, "", "", "Axis direction (the nappe opens along it)."),
    Key("obstacle.cone", "half_angle_deg", "number", REQUIRED, "(0, 90)", "degree",
        "Half-angle between the axis and the surface."),
)

#: name -> (type, values, unit, meaning) of a built-in's parameter, shared by name across the
#: built-ins; the defaults are the generators' own, a whole number's least value WHOLE_MINIMUM
BUILTIN: dict[str, tuple[str, str, str, str]] = {
    "theta_deg": ("number", "(0, 90)", "degree", "vgroove_bar: angle of the groove's walls from the vertical."),
    "eps": ("number", "≥ 0", "force/length", "vgroove_bar: isotropic ground springs at both nodes (0: a free bar); "
            "mu^c = tan θ + eps/(k sin 2θ), k = EA/2."),
    "EA": ("number", "> 0", "force", "Axial stiffness of the bars."),
    "rows": ("integer", "", "", "Rows of nodes (plug2d: m = 2 rows contact nodes) or of elements "
             "(block2d: m = 2 (rows + 1))."),
    "cols": ("integer", "", "", "Columns of nodes (plug2d) or of elements (block2d)."),
    "taper_deg": ("number", "[0, 90)", "degree", "Taper of the walls from the vertical (from the axis in 3D); these "
                  "free plugs have global mu^c = tan(taper) for a taper > 0 (at 0 it depends on the body: plug2d "
                  "4 × 3 gives 0.839)."),
    "levels": ("integer", "", "", "plug3d: levels of nodes, each a ring plus a centre node (1 is flat: a mechanism, "
               "refused when condensed)."),
    "ring": ("integer", "", "", "plug3d: contact nodes per ring (m = levels × ring)."),
    "refine": ("integer", "", "", "block2d: each coarse element split refine × refine (mesh refinement)."),
    "E": ("number", "> 0", "force/length²", "Young's modulus."),
    "nu": ("number", "(-1, 0.5)", "1", "Poisson's ratio."),
    "thickness": ("number", "> 0", "length", "Plane-stress thickness."),
    "contact_patch": ("number", "≥ 0", "length", "Half-width of the contact patches (0: point contacts)."),
    "contact_patch_kind": ("string", choices(PATCH_KINDS), "", "Patch model (see model.mesh)."),
}


def builtin_keys(kind: str) -> tuple[Key, ...]:
    """The [model] keys of a built-in: its generator's parameters, in order; KeyError naming a
    parameter that BUILTIN does not describe."""
    out = []
    for p in inspect.signature(BUILTINS[kind]).parameters.values():
        if p.name not in BUILTIN:
            raise KeyError(f"hpcwedge/scene/keys.py BUILTIN: no meaning for model.{kind}.{p.name}")
        type_, values, unit, meaning = BUILTIN[p.name]
        lo = WHOLE_MINIMUM.get(kind, {}).get(p.name)
        out.append(Key(f"model.{kind}", p.name, type_, p.default, f"≥ {lo}" if lo is not None else values,
                       unit, meaning))
    return tuple(out)


def table(name: str) -> dict[str, Key]:
    """{key name: Key} of one table, in the table's order (built-ins: "model.<kind>")."""
    if name.startswith("model.") and name[6:] in BUILTINS:
        return {k.name: k for k in builtin_keys(name[6:])}
    return {k.name: k for k in KEYS if k.table == name}


def tables() -> dict[str, dict[str, Key]]:
    """Every table, in order: those of KEYS, then one per built-in."""
    names = dict.fromkeys(k.table for k in KEYS)
    return {n: table(n) for n in [*names, *(f"model.{kind}" for kind in BUILTINS)]}


def defaults(name: str) -> dict[str, object]:
    """{key: default} of a table whose keys all have one ([compute], [run])."""
    return {k.name: k.default for k in table(name).values()}

