"""Built-in models (SPEC §6). Units consistent and arbitrary; lengths: plug height 1, bottom width 1.

Conventions shared by all built-ins: the obstacle's walls are at an angle (theta / taper) from
the vertical, the opening widening upward; contact normals point into the body, i.e. inward
and upward; 2D tangents t = (n_y, -n_x) (pointing down the wall on the left side).
"""
from __future__ import annotations

import dataclasses
import inspect
import math
import numbers

import numpy as np
import scipy.sparse as sp

from hpcwedge.models.continuum import ContinuumAssembly, continuum_material
from hpcwedge.models.patch import check_patch_size, with_contact_patch
from hpcwedge.models.record import Model, contact_frames
from hpcwedge.models.rigid import rigid_modes
from hpcwedge.models.truss import truss_model

#: the least value of each whole-number parameter of a built-in (scene.py checks scenes by it)
WHOLE_MINIMUM = {"plug2d": {"rows": 2, "cols": 2}, "plug3d": {"levels": 1, "ring": 3},
                 "block2d": {"rows": 1, "cols": 1, "refine": 1}}


def _int(v, key: str, kind: str) -> int:
    lo = WHOLE_MINIMUM[kind][key]
    if isinstance(v, bool) or not isinstance(v, numbers.Integral) or int(v) < lo:
        raise ValueError(f"model.{key}: must be a whole number >= {lo}, got {v!r}")
    return int(v)


def _real(v, key: str, lo: float, hi: float, lo_open: bool = False, hi_open: bool = True) -> float:
    if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(float(v)):
        raise ValueError(f"model.{key}: must be a finite number, got {v!r}")
    x = float(v)
    if (x < lo or (lo_open and x == lo)) or (x > hi or (hi_open and x == hi)):
        lb, rb = ("(" if lo_open else "["), (")" if hi_open else "]")
        raise ValueError(f"model.{key}: must lie in {lb}{lo:g}, {hi:g}{rb}, got {x:g}")
    return x


def _wall_normals_2d(side: np.ndarray, tau: float) -> np.ndarray:
    """side: (m,) -1 left / +1 right -> (m, 2) normals into the body: left (c, s), right (-c, s)."""
    return np.stack([-side * math.cos(tau), np.full(side.shape, math.sin(tau))], axis=1)


def vgroove_bar(theta_deg: float = 30.0, eps: float = 0.0, EA: float = 1.0) -> Model:
    """One bar between (-1, 0) and (1, 0) (k = EA/L = EA/2) in a V groove opening upward.

    Walls at theta from vertical; contact nodes [0, 1]; normals into the body
    (cos θ, sin θ) at the left node, (-cos θ, sin θ) at the right node.
    eps >= 0: isotropic ground springs at both nodes (K += eps I); eps > 0 makes the body
    supported (rigid_modes has 0 columns), eps = 0 leaves it free (3 columns).
    Analytic mu^c = tan θ + eps / (k sin 2θ).
    """
    th = math.radians(_real(theta_deg, "theta_deg", 0.0, 90.0, lo_open=True))
    eps = _real(eps, "eps", 0.0, math.inf)
    EA = _real(EA, "EA", 0.0, math.inf, lo_open=True)
    side = np.array([-1.0, 1.0])
    mdl = truss_model([[-1.0, 0.0], [1.0, 0.0]], [[0, 1]], EA, None, [0, 1], _wall_normals_2d(side, th))
    if eps > 0:
        mdl = dataclasses.replace(mdl, K=(mdl.K + eps * sp.identity(4, format="csr")).tocsr(),
                                  rigid_modes=np.zeros((4, 0)))
    return mdl


def _grid_bars(rows: int, cols: int) -> np.ndarray:
    """Bars of a rows x cols node grid (node = j*cols + i): row bars, column bars, both diagonals."""
    node = np.arange(rows * cols).reshape(rows, cols)
    parts = [np.stack([node[:, :-1].ravel(), node[:, 1:].ravel()], 1),        # along rows
             np.stack([node[:-1, :].ravel(), node[1:, :].ravel()], 1),        # along columns
             np.stack([node[:-1, :-1].ravel(), node[1:, 1:].ravel()], 1),     # diagonal /
             np.stack([node[:-1, 1:].ravel(), node[1:, :-1].ravel()], 1)]     # diagonal \
    return np.concatenate(parts).astype(np.int64)


def plug2d(rows: int = 4, cols: int = 3, taper_deg: float = 10.0) -> Model:
    """Truss cork in a 2D bottle neck: rows x cols nodes, node = j*cols + i (row j, column i).

    Row j at y = j/(rows-1), spanning |x| <= 0.5 + y tan τ with columns evenly spaced; bars
    along rows and columns and both diagonals of every cell, EA = 1. Contact nodes: left
    column bottom to top, then right column (m = 2 rows); normals left (cos τ, sin τ), right
    (-cos τ, sin τ). Free body (3 rigid modes). Global mu^c = tan τ.
    """
    rows, cols = _int(rows, "rows", "plug2d"), _int(cols, "cols", "plug2d")
    tau = math.radians(_real(taper_deg, "taper_deg", 0.0, 90.0))
    y = np.arange(rows) / (rows - 1)
    hw = 0.5 + y * math.tan(tau)
    s = np.arange(cols) / (cols - 1)
    X = np.stack([((2 * s[None, :] - 1) * hw[:, None]).ravel(), np.repeat(y, cols)], axis=1)
    left = np.arange(rows) * cols
    contact = np.concatenate([left, left + cols - 1])
    side = np.repeat([-1.0, 1.0], rows)
    return truss_model(X, _grid_bars(rows, cols), 1.0, None, contact, _wall_normals_2d(side, tau))


def plug3d(levels: int = 2, ring: int = 5, taper_deg: float = 10.0) -> Model:
    """Truss cork in a conical hole: `levels` rings of `ring` nodes plus a centre node per level.

    Numbering: ring node k of level j = j*ring + k (angle 2πk/ring), centre of level j =
    levels*ring + j. Level j at z = j/(levels-1) (z = 0 if levels = 1), radius 0.5 + z tan τ.
    Bars (EA = 1): along rings, radii (centre to ring), between levels ring-to-ring,
    centre-to-centre and centre-to-ring of the other level (without these the centres of a
    plain frustum could slide together along the axis: an interior mechanism), and ring
    diagonals (j, k)-(j+1, k±1). Contact nodes: all ring nodes, level by
    level (m = levels*ring); normal n = -cos τ e_r + sin τ e_z (into the body, up), t1 = e_phi
    (counter-clockwise seen from above), t2 = n x t1. Free body: 6 rigid modes.
    levels = 1 is flat: the centre node is then a mechanism out of plane (condense() rejects it).
    """
    levels, ring = _int(levels, "levels", "plug3d"), _int(ring, "ring", "plug3d")
    tau = math.radians(_real(taper_deg, "taper_deg", 0.0, 90.0))
    z = np.arange(levels) / (levels - 1) if levels > 1 else np.zeros(1)
    r = 0.5 + z * math.tan(tau)
    phi = 2 * np.pi * np.arange(ring) / ring
    c, s = np.cos(phi), np.sin(phi)
    Xr = np.stack([(r[:, None] * c).ravel(), (r[:, None] * s).ravel(), np.repeat(z, ring)], axis=1)
    Xc = np.stack([np.zeros(levels), np.zeros(levels), z], axis=1)
    X = np.concatenate([Xr, Xc])
    rn = np.arange(levels * ring).reshape(levels, ring)
    cn = levels * ring + np.arange(levels)
    nxt = np.roll(rn, -1, axis=1)
    prv = np.roll(rn, 1, axis=1)
    parts = [np.stack([rn.ravel(), nxt.ravel()], 1),                                  # rings
             np.stack([np.repeat(cn, ring), rn.ravel()], 1),                            # radii
             np.stack([rn[:-1].ravel(), rn[1:].ravel()], 1),                            # ring-to-ring
             np.stack([cn[:-1], cn[1:]], 1),                                            # centre-to-centre
             np.stack([np.repeat(cn[:-1], ring), rn[1:].ravel()], 1),                   # centre j to ring j+1
             np.stack([np.repeat(cn[1:], ring), rn[:-1].ravel()], 1),                   # centre j+1 to ring j
             np.stack([rn[:-1].ravel(), nxt[1:].ravel()], 1),                           # diagonal k -> k+1
             np.stack([rn[:-1].ravel(), prv[1:].ravel()], 1)]                           # diagonal k -> k-1
    bars = np.concatenate(parts).astype(np.int64)
    er = np.stack([np.tile(c, levels), np.tile(s, levels), np.zeros(levels * ring)], axis=1)
    ez = np.array([0.0, 0.0, 1.0])
    normals = -math.cos(tau) * er + math.sin(tau) * ez
    t1 = np.stack([-np.tile(s, levels), np.tile(c, levels), np.zeros(levels * ring)], axis=1)
    return truss_model(X, bars, 1.0, None, rn.ravel(), normals, t1)


def block2d(rows: int = 5, cols: int = 2, refine: int = 1, taper_deg: float = 10.0,
            E: float = 1.0, nu: float = 0.3, thickness: float = 1.0, contact_patch: float = 0.0,
            contact_patch_kind: str = "rigid") -> Model:
    """Plane-stress Q4 plug: trapezoid of height 1, width 1 at the bottom, sides at τ from vertical.

    Coarse grid rows x cols elements, each split refine x refine (uniform bilinear subdivision,
    which for this shape is the uniform grid in (x/half-width, y)). Fine grid R = rows*refine
    element rows, C = cols*refine columns; node (J, I) = J*(C+1) + I at y = J/R,
    x = (2I/C - 1)(0.5 + y tan τ); element (J, I) = J*C + I with corners counter-clockwise.
    Contact nodes: coarse side nodes, left side bottom to top (J = j*refine, I = 0), then right
    side (I = C); m = 2(rows+1); normals as plug2d. Free body (3 rigid modes).
    contact_patch = a > 0: a rigid foot of half-width a under every contact node (the boundary
    nodes within a of it move with it rigidly: models/patch.py); 0 = point contacts.
    contact_patch_kind = "hat": the contact DOFs are hat-weighted means over the patches instead.
    K is assembled on first access (model.assembly: condense_distributed assembles rows only).
    """
    rows, cols = _int(rows, "rows", "block2d"), _int(cols, "cols", "block2d")
    refine = _int(refine, "refine", "block2d")
    tau = math.radians(_real(taper_deg, "taper_deg", 0.0, 90.0))
    E = _real(E, "E", 0.0, math.inf, lo_open=True)
    nu = _real(nu, "nu", -1.0, 0.5, lo_open=True)
    thickness = _real(thickness, "thickness", 0.0, math.inf, lo_open=True)
    R, C = rows * refine, cols * refine
    y = np.arange(R + 1) / R
    hw = 0.5 + y * math.tan(tau)
    s = np.arange(C + 1) / C
    X = np.empty(((R + 1) * (C + 1), 2))
    X[:, 0] = ((2 * s[None, :] - 1) * hw[:, None]).ravel()
    X[:, 1] = np.repeat(y, C + 1)
    node = np.arange((R + 1) * (C + 1), dtype=np.int64).reshape(R + 1, C + 1)
    quads = np.stack([node[:-1, :-1].ravel(), node[:-1, 1:].ravel(),
                      node[1:, 1:].ravel(), node[1:, :-1].ravel()], axis=1)
    left = np.arange(rows + 1, dtype=np.int64) * refine * (C + 1)
    contact = np.concatenate([left, left + C])
    side = np.repeat([-1.0, 1.0], rows + 1)
    nrm, tan = contact_frames(_wall_normals_2d(side, tau), 2, len(contact))
    a = check_patch_size(contact_patch)
    asm = ContinuumAssembly(X, {"quad": quads}, E, nu, thickness, key="model.quads")
    mdl = Model(dim=2, coords=X, K=None, assembly=asm, fixed_dofs=np.zeros(0, dtype=np.int64), contact_nodes=contact,
                normals=nrm, tangents=tan, rigid_modes=rigid_modes(X, 2), cells={"quad": quads},
                material=continuum_material(len(quads), E, nu, thickness, "model"))
    return with_contact_patch(mdl, a, contact_patch_kind)


#: built-in generators by scene `model.kind`, and their dimension
BUILTINS = {"vgroove_bar": vgroove_bar, "plug2d": plug2d, "plug3d": plug3d, "block2d": block2d}
BUILTIN_DIM = {"vgroove_bar": 2, "plug2d": 2, "plug3d": 3, "block2d": 2}


def builtin(kind: str, params: dict | None = None) -> Model:
    """Build a built-in model from scene parameters; ValueError naming the key on unknown names."""
    if kind not in BUILTINS:
        raise ValueError(f"model.kind: unknown built-in {kind!r} (choose from {', '.join(BUILTINS)}, "
                         "stiffness, truss, mesh)")
    fn = BUILTINS[kind]
    params = dict(params or {})
    accepted = list(inspect.signature(fn).parameters)
    for k in params:
        if k not in accepted:
            raise ValueError(f"model.{k}: unknown parameter for {kind} (accepted: {', '.join(accepted)})")
    return fn(**params)


#: the contact nodes of each built-in from its parameters, before it is built
_CONTACTS = {"vgroove_bar": lambda p: 2, "plug2d": lambda p: 2 * p["rows"],
             "plug3d": lambda p: p["levels"] * p["ring"], "block2d": lambda p: 2 * (p["rows"] * p["refine"] + 1)}


def contact_count(kind: str, params: dict) -> int:
    """m of the built-in `kind` with `params` (its defaults for the others), without building it."""
    sig = inspect.signature(BUILTINS[kind]).parameters
    return int(_CONTACTS[kind]({k: params.get(k, v.default) for k, v in sig.items()}))
