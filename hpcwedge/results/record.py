"""What a solve found (SPEC §4): Run (the answers at one mu), Result (every answer of a
scene) and SolveStats (the stats object of the result file). pipeline.run_scene makes them;
resultfile.py stores and reads them."""
from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field, fields, is_dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from hpcwedge.contact.problem import ContactProblem
    from hpcwedge.models.record import Model
    from hpcwedge.scene.parse import Scene


def _count(name: str) -> property:
    """A read-only property: len(self.<name>), None while that field is None."""
    return property(lambda self: None if getattr(self, name) is None else len(getattr(self, name)),
                    doc=f"len({name}), None when the scene did not ask for it")


@dataclass
class Run:
    """The answers at one mu; a field the scene did not ask for is None."""

    mu: float
    rays: np.ndarray | None = None            # (R, 2n) wedged rays [u, r], sum(r_n) = 1
    trivial_rays: np.ndarray | None = None    # (T, 2n) rigid lift-offs, sum(u_n) = 1
    ray_zero: np.ndarray | None = None        # (R, 3m) zero flags of the wedged rays
    cones: list[dict] | None = None           # {"rays", "trivial_rays", "zero_u", "zero_r", "mu_c"}
    patterns: list[dict] | None = None        # {"contact", "mu_c"}

    n_wedged_rays = _count("rays")
    n_trivial_rays = _count("trivial_rays")
    n_cones = _count("cones")
    n_patterns = _count("patterns")


@dataclass
class Result:
    """Every answer of one scene (pipeline.run_scene): one Run per listed mu, the global mu^c,
    the stages run, their timings and the solve's stats (SolveStats.as_dict())."""

    scene: Scene
    m: int
    runs: list[Run]
    mu_c: float | None = None
    mu_c_status: str | None = None     # "found" | "none_at_any_mu" | "none_up_to_mu_max" | None
    complete: bool = True
    stages: list[str] = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    model: Model | None = None
    problem: ContactProblem | None = None

    def to_dict(self, with_rays: bool = True) -> dict:
        """The `hpcwedge show --json` object of this result (SPEC §4): written to a temporary
        result file and read back by resultfile.read_result, the one JSON writer (so the two
        never differ; it costs a write and a read of the file)."""
        from hpcwedge.results.hdf5 import read_result, write_result
        with tempfile.TemporaryDirectory(prefix="hpcwedge-") as folder:
            path = os.path.join(folder, "result.h5")
            write_result(path, self)
            return read_result(path, with_rays=with_rays)


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
    leave the global mu^c uncertified."""

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


