"""Rigid obstacle surfaces (planes and cones) and the contact normals they give.

Scene tables (SPEC §3 extension), in 2D or 3D coordinates:

    {type = "plane", point = [..], normal = [..]}                    a line in 2D
    {type = "cone", apex = [..], axis = [..], half_angle_deg = 10}    a V in 2D

A cone is the surface swept by the rays from `apex` at `half_angle_deg` (0 < α < 90) from
`axis` (only the nappe the axis points into). The sign of a plane's normal and the side of
a cone do not matter: each contact node's normal is oriented into the body afterwards
(`orient_into_body`). Lengths are those of the mesh.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hpcwedge.models.record import as_float_array, contact_frames

OBSTACLE_KEYS = {"plane": ("point", "normal"), "cone": ("apex", "axis", "half_angle_deg")}


@dataclass(frozen=True)
class Plane:
    """The plane (2D: line) through `point` (dim,) with unit `normal` (dim,)."""

    point: np.ndarray
    normal: np.ndarray

    def distance(self, x: np.ndarray) -> np.ndarray:
        """(n,) unsigned distances of the points x (n, dim) to the plane."""
        return np.abs((x - self.point) @ self.normal)

    def frame(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Unit normals (n, dim) at the feet of x (sign arbitrary); no preferred tangent (None)."""
        return np.broadcast_to(self.normal, x.shape).copy(), None


@dataclass(frozen=True)
class Cone:
    """The cone with `apex` (dim,), unit `axis` (dim,) and half-angle `alpha` (radians)."""

    apex: np.ndarray
    axis: np.ndarray
    alpha: float

    def _polar(self, x: np.ndarray):
        d = x - self.apex
        h = d @ self.axis                                     # along the axis
        rho = d - h[:, None] * self.axis                      # radial vector
        return h, rho, np.linalg.norm(rho, axis=1)

    def distance(self, x: np.ndarray) -> np.ndarray:
        """(n,) distances of x (n, dim) to the nappe (to the apex when x projects behind it)."""
        h, _, r = self._polar(x)
        ca, sa = math.cos(self.alpha), math.sin(self.alpha)
        return np.where(h * ca + r * sa >= 0, np.abs(r * ca - h * sa), np.hypot(h, r))

    def frame(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit normals (n, dim) sin α axis − cos α e_r (towards the axis), and (3D) the
        circumferential tangents axis × e_r; rows for points on the axis are NaN."""
        _, rho, r = self._polar(x)
        with np.errstate(divide="ignore", invalid="ignore"):
            er = np.where(r[:, None] > 0, rho / r[:, None], np.nan)
        n = math.sin(self.alpha) * self.axis - math.cos(self.alpha) * er
        t1 = np.cross(self.axis, er) if x.shape[1] == 3 else None
        return n, t1


def _unit(v, key: str, dim: int) -> np.ndarray:
    a = _point(v, key, dim)
    nrm = float(np.linalg.norm(a))
    if nrm == 0.0:
        raise ValueError(f"{key}: zero vector")
    return a / nrm


def _point(v, key: str, dim: int) -> np.ndarray:
    a = as_float_array(v, key, ndim=1)
    if a.shape != (dim,):
        raise ValueError(f"{key}: expected {dim} coordinates, got {a.shape[0]}")
    return a


def parse_obstacles(tables, dim: int, key: str = "obstacle") -> list[Plane | Cone]:
    """Obstacles from scene tables (see the module docstring); ValueError naming
    `<key>[i].<field>` on a missing/unknown field, a wrong length, NaN, a zero vector or
    a half-angle outside (0, 90) degrees."""
    if not isinstance(tables, list) or not tables:
        raise ValueError(f"{key}: expected a non-empty list of tables")
    out: list[Plane | Cone] = []
    for i, t in enumerate(tables):
        k = f"{key}[{i}]"
        if not isinstance(t, dict):
            raise ValueError(f"{k}: expected a table")
        kind = t.get("type")
        if kind not in OBSTACLE_KEYS:
            raise ValueError(f"{k}.type: must be \"plane\" or \"cone\", got {kind!r}")
        fields = OBSTACLE_KEYS[kind]
        for f in t:
            if f != "type" and f not in fields:
                raise ValueError(f"{k}.{f}: unknown key for a {kind} (allowed: type, {', '.join(fields)})")
        for f in fields:
            if f not in t:
                raise ValueError(f"{k}.{f}: required for a {kind}")
        if kind == "plane":
            out.append(Plane(_point(t["point"], f"{k}.point", dim), _unit(t["normal"], f"{k}.normal", dim)))
        else:
            a = t["half_angle_deg"]
            if isinstance(a, bool) or not isinstance(a, (int, float)) or not 0.0 < a < 90.0:
                raise ValueError(f"{k}.half_angle_deg: must be a number in (0, 90), got {a!r}")
            out.append(Cone(_point(t["apex"], f"{k}.apex", dim), _unit(t["axis"], f"{k}.axis", dim),
                            math.radians(a)))
    return out


def obstacle_frames(x: np.ndarray, obstacles: list[Plane | Cone], tol: float, labels: np.ndarray,
                    key: str = "obstacle", tol_note: str = "") -> tuple[np.ndarray, np.ndarray | None]:
    """Normals (m, dim) of the nearest obstacle surface at the contact points x (m, dim), and
    (3D) preferred tangents t1 (m, 3) or None.

    Each point takes the surface with the least distance (the first on ties); the distance
    must be <= tol. Normal signs are arbitrary here (see orient_into_body). In 3D, t1 is the
    cone's circumferential direction for cone nodes and the default of model.contact_frames
    for plane nodes. labels (m,): node ids for the messages; tol_note: where tol comes from.
    ValueError naming `key` for a point off every surface or at a cone's apex.
    """
    m, dim = x.shape
    dist = np.stack([ob.distance(x) for ob in obstacles])                  # (n_obstacles, m)
    which = np.argmin(dist, axis=0)
    d = dist[which, np.arange(m)]
    far = np.flatnonzero(d > tol)
    if far.size:
        i = int(far[np.argmax(d[far])])
        raise ValueError(f"{key}: contact node {int(labels[i])} (contact position {i}) is {d[i]:.3g} from the "
                         f"nearest obstacle surface, more than the tolerance {tol:.3g}{tol_note}")
    n = np.empty((m, dim))
    t1 = np.full((m, dim), np.nan) if dim == 3 else None
    for j, ob in enumerate(obstacles):
        sel = np.flatnonzero(which == j)
        if not sel.size:
            continue
        nj, tj = ob.frame(x[sel])
        bad = sel[~np.all(np.isfinite(nj), axis=1)]
        if bad.size:
            i = int(bad[0])
            raise ValueError(f"{key}[{j}]: contact node {int(labels[i])} (contact position {i}) is at the "
                             "apex of the cone: its normal is undefined")
        n[sel] = nj
        if t1 is not None and tj is not None:
            t1[sel] = tj
    if t1 is not None:
        miss = ~np.all(np.isfinite(t1), axis=1)
        if miss.all():
            t1 = None
        elif miss.any():
            t1[miss] = contact_frames(n[miss], 3, int(miss.sum()))[1][:, 0]
    return n, t1


def orient_into_body(normals: np.ndarray, inward: np.ndarray, labels: np.ndarray,
                     key: str = "obstacle") -> np.ndarray:
    """Flip each normal (m, dim) to the side of `inward` (m, dim), a vector from the contact
    node into the body (e.g. towards the centroids of its elements). ValueError naming `key`
    when inward is (nearly) tangent to the surface: the side of the body is undefined."""
    s = (normals * inward).sum(axis=1)
    amb = np.flatnonzero(np.abs(s) <= 1e-6 * np.linalg.norm(inward, axis=1))
    if amb.size:
        i = int(amb[0])
        raise ValueError(f"{key}: cannot tell on which side of the obstacle the body lies at contact node "
                         f"{int(labels[i])} (contact position {i}): its elements are tangent to the surface")
    return np.where(s[:, None] < 0, -normals, normals)
