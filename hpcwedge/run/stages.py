"""The records the pipeline's stages return (run/pipeline.py files them into the Result)."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hpcwedge.contact.problem import ContactProblem, Parametrization
from hpcwedge.models.record import Model
from hpcwedge.mu_c.critical import MuC
from hpcwedge.parallel.engine import Engine
from hpcwedge.patterns.symmetry import Symmetry
from hpcwedge.progress import Progress
from hpcwedge.rays.numerics import NumericsReport
from hpcwedge.results.record import Cone, GlobalRouteStats, Pattern, TreeStats
from hpcwedge.scene.parse import Scene

OrbitKey = tuple[int, int]


@dataclass
class Condensed:
    """The condense stage: the model (None: a raw K scene), its contact problem, the seconds
    the condensation took (0 for a raw K)."""

    model: Model | None
    problem: ContactProblem
    seconds: float = 0.0


@dataclass
class Context:
    """What the stages after condensation share."""

    scene: Scene
    m: int
    param: Parametrization
    numerics: NumericsReport
    exact_param: Callable[[], Parametrization]   # the exact parametrisation, made on first call
    #: the float engines' (LP/SOCP trees, mu^c): always the float route's orthonormal one —
    #: the exact one's rational bases, rounded, left plug2d's mu^c at a 0.1 deg taper 2.6e-4
    #: off (and 0.65, unbracketed) under compute.exact = true
    float_param: Parametrization
    symmetry: Symmetry | None                    # the node symmetries (order > 1), or None
    engine: Engine
    progress: Progress

    @property
    def scale(self) -> float | None:
        """mu^c's coordinates: the balanced scale (numerics.NumericsReport.scale)."""
        return self.numerics.scale


@dataclass
class Rays:
    """The rays stage at one mu: the wedged rays (u in the scene's units), the trivial ones,
    the wedged rays' zero flags (canonical order); zero, wedged: every ray's zero flags and
    which rays are wedged (the cones stage's input); stats: the double description's."""

    mu: float
    rays: np.ndarray
    trivial_rays: np.ndarray
    ray_zero: np.ndarray
    zero: np.ndarray
    wedged: np.ndarray
    stats: dict


@dataclass
class Cones:
    """The cones stage at one mu: its Cones (mu^c not computed yet)."""

    items: list[Cone]


@dataclass
class PatternSets:
    """The patterns stage: per mu its Patterns (canonical order, mu^c not computed yet), how many are undecided, the tree's counters, the 3D solver statuses
    (2D: None) and per mu the orbit representatives found (no symmetry: None)."""

    items: list[list[Pattern]]
    undecided: int
    tree: TreeStats
    statuses: dict | None
    representatives: list[int] | None


@dataclass
class MuCValues:
    """The mu_c stage: the MuC of every orbit key (one task each); keyed: per run asked the
    keys of its cones then its patterns, in the run's order (mu_c_keys); first: the keys of
    the first run that lists any cone or pattern (None: no run does)."""

    by_key: dict[OrbitKey, MuC]
    keyed: list[list[OrbitKey]]
    first: list[OrbitKey] | None


@dataclass
class GlobalMuC:
    """The global_mu_c stage: mu^c (None: none) and its status; search: the global route's
    stats when it searched (None: the least listed value), with its mu^c counts."""

    mu_c: float | None
    status: str | None
    search: GlobalRouteStats | None = None
    polished: int = 0
    unpolished: int = 0
