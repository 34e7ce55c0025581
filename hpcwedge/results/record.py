"""What a solve found (SPEC §4): Cone and Pattern (the items of a run), Run (the answers at
one mu), Result (every answer of a scene) and SolveStats (the stats object of the result
file). pipeline.run_scene makes them; results/hdf5.py stores and reads them; Result.to_dict
is the `show --json` object, built from the fields alone."""
from __future__ import annotations

import enum
import json
import math
from dataclasses import dataclass, field, fields, is_dataclass
from typing import TYPE_CHECKING

import numpy as np

from hpcwedge.version import __version__

if TYPE_CHECKING:
    from hpcwedge.contact.problem import ContactProblem
    from hpcwedge.models.record import Model
    from hpcwedge.scene.parse import Scene


class Unset(enum.Enum):
    """The value of a field its stage did not compute: the key is absent from the JSON
    (falsy, so `if item.mu_c_polished` reads it as not polished)."""

    NOT_COMPUTED = 0

    def __bool__(self) -> bool:
        return False

    def __repr__(self) -> str:
        return "NOT_COMPUTED"


NOT_COMPUTED = Unset.NOT_COMPUTED


def _item_dict(item) -> dict:
    """A Cone's or Pattern's JSON object: its fields in order, NOT_COMPUTED ones left out."""
    return {f.name: v for f in fields(item) if (v := getattr(item, f.name)) is not NOT_COMPUTED}


@dataclass(frozen=True)
class Cone:
    """A maximal cone of cross-complementary rays at one mu (2D): its wedged and trivial
    rays (indices into the run's lists), the nodes where u_n = 0 and r_n = 0 on all of it,
    its mu^c (None: no value, or not computed) and whether that value is certified
    (SPEC §4; NOT_COMPUTED: no mu^c stage ran)."""

    rays: list[int]
    trivial_rays: list[int]
    zero_u: list[int]
    zero_r: list[int]
    mu_c: float | None = None
    mu_c_polished: bool | None | Unset = NOT_COMPUTED

    def to_dict(self) -> dict:
        """The cone's object in `show --json`."""
        return _item_dict(self)

    @classmethod
    def from_dict(cls, d: dict) -> Cone:
        """The cone of a checked JSON object (results.hdf5.check_items)."""
        return cls(d["rays"], d.get("trivial_rays", []), d["zero_u"], d["zero_r"], d.get("mu_c"),
                   d.get("mu_c_polished", NOT_COMPUTED))


@dataclass(frozen=True)
class Pattern:
    """A feasible sign pattern at one mu: its contact nodes (the others are gaps), its mu^c
    (None: no value, or not computed), whether every solver left it undecided (kept,
    flagged) and whether its mu^c is certified (SPEC §4; NOT_COMPUTED: no mu^c stage ran)."""

    contact: list[int]
    mu_c: float | None = None
    undecided: bool = False
    mu_c_polished: bool | None | Unset = NOT_COMPUTED

    def to_dict(self) -> dict:
        """The pattern's object in `show --json`."""
        return _item_dict(self)

    @classmethod
    def from_dict(cls, d: dict) -> Pattern:
        """The pattern of a checked JSON object (results.hdf5.check_items)."""
        return cls(d["contact"], d.get("mu_c"), d.get("undecided", False), d.get("mu_c_polished", NOT_COMPUTED))


def _count(name: str) -> property:
    """A read-only property: len(self.<name>); None while that field is None, unless a
    reader left the array unread and kept its stored count (Run.stored_counts)."""
    def count(self):
        v = getattr(self, name)
        if v is not None:
            return len(v)
        return None if self.stored_counts is None else self.stored_counts.get(name)
    return property(count, doc=f"len({name}), None when the scene did not ask for it")


def plain(value, default=None):
    """`value` as the result file's JSON reads it back (tuples as lists, keys as strings;
    default: json.dumps's, for values JSON has no type for)."""
    return json.loads(json.dumps(value, default=default))


def plain_number(o):
    """json.dumps's default for numpy numbers and arrays (TypeError for anything else)."""
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))


@dataclass
class Run:
    """The answers at one mu; a field the scene did not ask for is None. stored_counts: the
    counts ("rays", "trivial_rays") of ray arrays a reader left unread
    (results.hdf5.read_result(with_rays=False)); None when the arrays are here."""

    mu: float
    rays: np.ndarray | None = None            # (R, 2n) wedged rays [u, r], sum(r_n) = 1
    trivial_rays: np.ndarray | None = None    # (T, 2n) rigid lift-offs, sum(u_n) = 1
    ray_zero: np.ndarray | None = None        # (R, 3m) zero flags of the wedged rays
    cones: list[Cone] | None = None
    patterns: list[Pattern] | None = None
    stored_counts: dict | None = field(default=None, repr=False)

    n_wedged_rays = _count("rays")
    n_trivial_rays = _count("trivial_rays")
    n_cones = _count("cones")
    n_patterns = _count("patterns")

    def to_dict(self, with_rays: bool = True) -> dict:
        """The run's object in `show --json` (rays as nested lists; with_rays False: null)."""
        def rows(v):
            return None if v is None or not with_rays else np.asarray(v).tolist()
        return {"mu": float(self.mu), "n_wedged_rays": self.n_wedged_rays, "n_trivial_rays": self.n_trivial_rays,
                "n_cones": self.n_cones, "n_patterns": self.n_patterns,
                "rays": rows(self.rays), "trivial_rays": rows(self.trivial_rays),
                "cones": None if self.cones is None else [c.to_dict() for c in self.cones],
                "patterns": None if self.patterns is None else [p.to_dict() for p in self.patterns]}


@dataclass(frozen=True)
class StoredModel:
    """The part of a body's Model a result file keeps (/model: for figures): node
    coordinates (n, dim), contact nodes (m,), normals (m, dim), cells {kind: int array}."""

    coords: np.ndarray
    contact_nodes: np.ndarray
    normals: np.ndarray
    cells: dict


@dataclass
class Result:
    """Every answer of one scene (pipeline.run_scene): one Run per listed mu, the global mu^c,
    the stages run, their timings and the solve's stats (SolveStats.as_dict()); version: the
    hpcwedge that solved it. Read back from its file (results.hdf5.read_result), `model` is
    the StoredModel the file keeps and `problem` is None (contact.build rebuilds both from
    `scene`)."""

    scene: Scene
    m: int
    runs: list[Run]
    mu_c: float | None = None
    mu_c_status: str | None = None     # "found" | "none_at_any_mu" | "none_up_to_mu_max" | None
    complete: bool = True
    stages: list[str] = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    model: Model | StoredModel | None = None
    problem: ContactProblem | None = None
    version: str = __version__

    def to_dict(self, with_rays: bool = True) -> dict:
        """The `hpcwedge show --json` object of this result (SPEC §4), as its result file
        gives it (results.hdf5.dump_result_json): stages, timings and stats as their JSON
        reads back, rays as nested lists (with_rays False: null)."""
        s = self.scene
        mu_c = None if self.mu_c is None or math.isnan(self.mu_c) else float(self.mu_c)
        return {"name": str(s.name), "dim": int(s.dim), "m": int(self.m), "complete": bool(self.complete),
                "mu_c": mu_c, "mu_c_status": self.mu_c_status or None,
                "runs": [run.to_dict(with_rays) for run in self.runs],
                "timings": plain(self.timings), "stages": plain(self.stages),
                "stats": plain(self.stats, plain_number), "version": self.version, "scene_hash": s.hash,
                "inputs": plain(s.input_digests)}


@dataclass
class TreeStats:
    """stats.bnb of the patterns stage: a sign-pattern tree's counters summed over every mu
    (the same for every split of the work) and partitions (2^m per mu: a brute force's solves).
    solves: the tree's feasibility problems (2D: LPs, 3D: SOCPs); lps: linear programs besides
    them (3D: the pyramid LPs of SOCPs no attempt decided; 2D: 0)."""

    nodes: int
    solves: int
    skipped: int
    pruned: int
    undecided: int
    lps: int
    partitions: int

    @classmethod
    def of(cls, counters: dict, partitions: int) -> TreeStats:
        """From a patterns job's counters (absent: 0)."""
        return cls(*(counters.get(f.name, 0) for f in fields(cls)[:-1]), partitions=partitions)


@dataclass
class GlobalRouteStats:
    """stats.bnb after a global mu^c search (global_mu_c.global_mu_critical's BnBStats, its route
    "tree" or "milp" and MILP counts); it replaces the patterns stage's TreeStats. solves and
    lps count the trees' and the mu^c computations' (lps: the pyramid LPs of SOCPs no attempt
    decided; the 2D MILP route adds the LP check of each pattern a MILP returns). undecided
    counts every solve that decided nothing, the bracket's dives and the mu^c computations'
    included; those leave the answer certified (nothing is pruned on doubt, and a polished
    value is certified). unsettled: the settling tree's patterns whose mu^c computation came
    back without a value and with undecided solves; only these (and unpolished values)
    leave the global mu^c uncertified. bound_solves: the certified lower bound's
    conic programs (mu_c.lower_bound); bound_certified: 1 when it met the incumbent and ended
    the search (no settling tree, no further MILP step)."""

    solves: int = 0
    skipped: int = 0
    undecided: int = 0
    nodes: int = 0
    route: str = "tree"
    milp_solves: int = 0
    milp_nodes: int = 0
    pruned: int = 0
    lps: int = 0
    unsettled: int = 0
    bound_solves: int = 0
    bound_certified: int = 0


@dataclass
class SymmetryStats:
    """stats.symmetry: the node symmetry group's order; representatives: the orbit
    representatives found per mu (patterns stage, order > 1; else None)."""

    order: int
    representatives: list[int] | None = None


@dataclass
class SolveStats:
    """The statistics of one solve; Result.stats is as_dict(), the stats object of the result
    file (SPEC §4). Fields in the file's key order; None: absent from the file."""

    dd: list = field(default_factory=list)   # 2D rays: per mu {"mu", **dd.DDResult.stats}
    lp_solves: int = 0                       # mu^c stage: LP/SOCP solves
    mu_c_polished: int = 0                   # mu^c values polished (pencil / KKT)
    mu_c_unpolished: int = 0                 # ... upper bounds not certified
    lp_undecided: int = 0                    # mu^c stage solves no solver decided
    symmetry: SymmetryStats | None = None
    patterns_undecided: int | None = None    # patterns kept undecided (flagged)
    bnb: TreeStats | GlobalRouteStats | None = None
    socp_statuses: dict | None = None        # 3D patterns: {solver status: count}
    numerics: dict | None = None             # numerics.NumericsReport.as_dict()
    parallel: dict | None = None             # Engine.summary()
    environment: dict | None = None          # environment.environment()

    def add(self, solves: int = 0, undecided: int = 0, polished: int = 0, unpolished: int = 0) -> None:
        """Count mu^c computations: LP/SOCP solves, undecided solves, values (un)polished."""
        self.lp_solves += solves
        self.lp_undecided += undecided
        self.mu_c_polished += polished
        self.mu_c_unpolished += unpolished

    def as_dict(self) -> dict:
        """The stats object: the fields that are not None, records as dicts (theirs likewise)."""
        def plain(r):
            return {f.name: plain(v) if is_dataclass(v) else v for f in fields(r)
                    if (v := getattr(r, f.name)) is not None}
        return plain(self)


