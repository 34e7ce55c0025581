"""`hpcwedge plot` (SPEC §4): one wedged configuration and the mu^c of a run's cones or
sign patterns, as a PNG.

2D (`--ray J`). Left panel: with a /model group, the undeformed body (light grey) and the
whole body deformed by the chosen wedged ray (configuration.load_configuration: interior
nodes from the condensation, on the body rebuilt from the stored scene), coloured by the
element values — von Mises stress of continuum elements, axial force of bars — with the
reactions at the contact nodes and the obstacle walls. When the body cannot be rebuilt
(e.g. its mesh file is gone) only the contact nodes are displaced, and the title says so.
Without a /model group (raw stiffness scenes), bars of r_n and u_n per contact node.
Right panel: the mu^c of every cone of the run, with the run's mu and the global mu^c.

3D (`--pattern J`). Left panel: the body in perspective, undeformed (light grey) and
deformed by a feasible point of sign pattern J at the run's mu (load_configuration
pattern=J): bars coloured by axial force, or the mesh's boundary faces by von Mises stress;
the pattern's contact set C (filled) and gap set G (open) marked, the reactions as arrows
pointing at the contact nodes from the obstacle side, and the obstacle: the scene's
[[obstacle]] cones and planes as translucent surfaces, else (built-in bodies) a small wall
square in the tangent plane of every contact node. When the body cannot be rebuilt (there is
then no point of the pattern to draw), the undeformed body with C and G marked, and the
title says why; without a /model group, bars of r_n and u_n of the pattern's point.
Right: the mu^c of every pattern of the run (pattern J highlighted) with the run's mu and
the global mu^c, and below it the number of feasible patterns against mu, one point per
run (steps between runs).

Drawn with matplotlib's Agg canvas on a bare Figure (no pyplot, no display).
"""
from __future__ import annotations

import json
import math
import os

import numpy as np

from .files import replace_atomic
from .results import check_items, index, index_range, open_result

DISP_FRACTION = 0.10     # largest drawn displacement / body size
ARROW_FRACTION = 0.15    # largest drawn reaction arrow / body size (3D: twice that)
WALL_FRACTION = 0.12     # length of a wall segment / body size
MAX_TICKS = 40           # per-item tick labels only up to this many bars
AXIAL_LABEL = "bar axial force (tension > 0)"
VON_MISES_PERCENTILE = 95  # 3D: the colour scale ends here (point contacts concentrate the stress)
#: boundary faces of the 3D cells (meshio / VTK node order), for the drawn surface
CELL_FACES = {"tetra": ((0, 2, 1), (0, 1, 3), (1, 2, 3), (0, 3, 2)),
              "hexahedron": ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6),
                             (3, 0, 4, 7))}


def plot_result(path: str, output: str, run: int = -1, ray: int | None = None,
                pattern: int | None = None) -> None:
    """Draw run `run` (Python-style index, -1 = last) of the result file `path` and save the
    figure as PNG to `output` (atomically): for a 2D result its wedged ray `ray` (default 0),
    for a 3D result its sign pattern `pattern` (default 0).

    ValueError (one line) for a bad run, ray or pattern index, `pattern` given for a 2D or
    `ray` for a 3D result (PlotError), or a file that is missing, damaged or not a hpcwedge
    result (results.FileError).
    """
    data = _load(path, run, ray, pattern)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    what = f"m = {data['m']} contact node{'s' if data['m'] != 1 else ''}"
    if data["dim"] == 2:
        fig = Figure(figsize=(13, 5.5), dpi=100)
        FigureCanvasAgg(fig)
        ax1, ax2 = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.15, 1]})
        _config_panel(ax1, data)
        _cones_panel(ax2, data)
    else:
        fig = Figure(figsize=(15, 7.5), dpi=100)
        FigureCanvasAgg(fig)
        _figure_3d(fig, data)
    fig.suptitle(f"{data['name']}: run {data['run']} of {data['n_runs']} (mu = {data['mu']:.6g}), {what}",
                 fontsize=12)
    if data["dim"] == 2:
        fig.tight_layout()
    _save_atomic(fig, output)


# --------------------------------------------------------------------------- reading

class PlotError(ValueError):
    """A figure that cannot be drawn (bad run, ray or pattern index, the wrong option for
    the dimension): one line."""


def _load(path: str, run: int, ray: int | None = None, pattern: int | None = None) -> dict:
    """The data of the figure; results.FileError for a missing, damaged or malformed file."""
    with open_result(path, passthrough=(PlotError,)) as f:
        return _read(f, path, run, ray, pattern)


def _run_group(f, run: int):
    """(index k, number of runs, the HDF5 group) of run `run`; PlotError when out of range."""
    keys = sorted(f["runs"])
    k = index(run, len(keys))
    if k is None:
        raise PlotError(f"plot: run {run} out of range (the result has {len(keys)} run(s): "
                        f"{index_range(len(keys))})")
    return k, len(keys), f["runs"][keys[k]]


def _item_index(j: int, n: int, name: str, noun: str, k: int) -> int | None:
    """Index j into a run's n items (None when there are none and j is 0 or -1), else PlotError."""
    i = index(j, n) if n else (0 if j in (0, -1) else None)
    if i is None:
        what = index_range(n) if n else "only 0 when there are none"
        raise PlotError(f"plot: {name} {j} out of range (run {k} has {n} {noun}(s): {what})")
    return i if n else None


def _read_model(f, path: str, dim: int, m: int) -> dict | None:
    """The /model group (coords, contact_nodes, normals, cells), or None without one."""
    if "model" not in f:
        return None
    mg = f["model"]
    mdl = {"coords": np.asarray(mg["coords"][()], dtype=float),
           "contact_nodes": np.asarray(mg["contact_nodes"][()], dtype=int),
           "normals": np.asarray(mg["normals"][()], dtype=float),
           "cells": {name[len("cells_"):]: np.asarray(mg[name][()], dtype=int)
                     for name in mg if name.startswith("cells_")}}
    if mdl["coords"].ndim != 2 or mdl["coords"].shape[1] != dim or len(mdl["contact_nodes"]) != m \
            or mdl["normals"].shape != (m, dim):
        raise PlotError(f"plot: {path}: /model does not match dim {dim} and m = {m}")
    return mdl


def _configuration(path: str, k: int, **item):
    """(Configuration of the item, None) or (None, the one-line reason it cannot be made)."""
    from .recovery import ConfigurationError, load_configuration
    try:
        return load_configuration(path, run=k, **item), None
    except ConfigurationError as e:
        return None, str(e)


def _read(f, path: str, run: int, ray: int | None = None, pattern: int | None = None) -> dict:
    a = f.attrs
    dim = int(a["dim"])
    if dim not in (2, 3):
        raise PlotError(f"plot: {path}: dim must be 2 or 3, got {dim}")
    if dim == 2 and pattern is not None:
        raise PlotError("plot: --pattern is for 3D results; this result is 2D (draw a wedged ray with --ray)")
    if dim == 3 and ray is not None:
        raise PlotError("plot: --ray is for 2D results; this result is 3D (draw a sign pattern with --pattern)")
    if dim == 3:
        return _read_3d(f, path, run, 0 if pattern is None else pattern)
    ray = 0 if ray is None else ray
    m = int(a["m"])
    k, n_runs, g = _run_group(f, run)
    rays = np.asarray(g["rays"][()], dtype=float) if "rays" in g else None
    if rays is not None:
        rays = rays.reshape(-1, 4 * m) if rays.size else np.zeros((0, 4 * m))
        if rays.shape[1] != 4 * m:
            raise PlotError(f"plot: {path}: run {k} rays have {rays.shape[1]} entries, expected 4m = {4 * m}")
    n_rays = 0 if rays is None else len(rays)
    j = _item_index(ray, n_rays, "ray", "wedged ray", k)
    out = {"name": _str(a.get("name", os.path.basename(path))), "dim": dim, "m": m,
           "run": k, "n_runs": n_runs, "mu": float(g.attrs["mu"]), "mu_c": _mu_c(a),
           "rays": rays, "ray": j,
           "cones": json.loads(_str(g["cones_json"][()])) if "cones_json" in g else None,
           "model": _read_model(f, path, dim, m)}
    check_items(out["cones"], None, n_rays, m)
    if out["model"] is not None:
        out["config"], out["config_note"] = (None, None) if j is None else _configuration(path, k, ray=j)
    return out


def _mu_c(attrs) -> float | None:
    v = float(attrs["mu_c"]) if "mu_c" in attrs else math.nan
    return v if math.isfinite(v) else None


def _read_3d(f, path: str, run: int, pattern: int) -> dict:
    a = f.attrs
    m = int(a["m"])
    k, n_runs, g = _run_group(f, run)
    patterns = json.loads(_str(g["patterns_json"][()])) if "patterns_json" in g else None
    check_items(None, patterns, 0, m)
    j = _item_index(pattern, len(patterns or []), "pattern", "sign pattern", k)
    counts = []
    for key in sorted(f["runs"]):
        r = f["runs"][key]
        counts.append((float(r.attrs["mu"]), int(r.attrs["n_patterns"]) if "n_patterns" in r.attrs else None))
    out = {"name": _str(a.get("name", os.path.basename(path))), "dim": 3, "m": m,
           "run": k, "n_runs": n_runs, "mu": float(g.attrs["mu"]), "mu_c": _mu_c(a),
           "patterns": patterns, "pattern": j, "counts": counts,
           "model": _read_model(f, path, 3, m), "config": None, "config_note": None,
           "obstacles": None, "point": None}
    scene = _stored_scene(f, path)
    if scene is not None and scene.obstacles:
        from .models.obstacle import parse_obstacles
        try:
            out["obstacles"] = parse_obstacles(scene.obstacles, 3, scene.obstacle_key)
        except ValueError:
            pass                                           # drawn as wall squares instead
    if j is None:
        return out
    if out["model"] is not None:
        out["config"], out["config_note"] = _configuration(path, k, pattern=j)
    elif scene is not None:                                # raw stiffness: the pattern's point only
        from .recovery import ConfigurationError, pattern_point
        try:
            out["point"] = pattern_point(scene, None, patterns[j]["contact"], out["mu"])
        except (ConfigurationError, ValueError) as e:
            out["config_note"] = str(e).splitlines()[0]
    return out


def _stored_scene(f, path: str):
    """The Scene parsed from the result's stored scene text (files relative to the recorded
    scene folder, else the result's), or None when it does not parse any more."""
    import tomllib

    from .scene import SceneError, parse_scene
    if "scene_text" not in f:
        return None
    text = _str(f["scene_text"][()])
    base = _str(f.attrs["scene_dir"]) if "scene_dir" in f.attrs else ""
    if not os.path.isdir(base):
        base = os.path.dirname(os.path.abspath(path))
    try:
        return parse_scene(tomllib.loads(text), text=text, base_dir=base)
    except (SceneError, tomllib.TOMLDecodeError, ValueError):
        return None


def _str(v) -> str:
    return v.decode() if isinstance(v, bytes) else str(v)


# --------------------------------------------------------------------------- left panel

def _split(ray_vec: np.ndarray, m: int):
    u, r = ray_vec[:2 * m], ray_vec[2 * m:]
    return u[:m], u[m:], r[:m], r[m:]          # u_n, u_t, r_n, r_t


def _config_panel(ax, d: dict) -> None:
    if d["rays"] is None:
        _message(ax, "wedged rays were not enumerated for this run\n(compute.enumerate = false)",
                 "wedged configuration")
        return
    if d["ray"] is None:
        _message(ax, f"no wedged configuration at mu = {d['mu']:.6g}\n(the run has no wedged rays)",
                 "wedged configuration")
        return
    m = d["m"]
    un, ut, rn, rt = _split(d["rays"][d["ray"]], m)
    head = f"wedged ray {d['ray']} of {len(d['rays'])}"
    if d["model"] is None:
        _bars_panel(ax, un, rn, head)
    else:
        _body_panel(ax, d["model"], un, ut, rn, rt, head, d.get("config"), d.get("config_note"))


def _bars_panel(ax, un, rn, head: str, what: str = "ray") -> None:
    m = len(un)
    x = np.arange(m)
    w = 0.38
    ax.bar(x - w / 2, rn, w, color="tab:red", label="r_n (normal reaction)")
    ax.bar(x + w / 2, un, w, color="tab:blue", label="u_n (normal gap)")
    ax.axhline(0.0, color="black", lw=0.8)
    ax.set_xlabel("contact node (position in the contact list)")
    ax.set_ylabel(f"value ({what} normalised to sum r_n = 1)")
    if m <= MAX_TICKS:
        ax.set_xticks(x)
    ax.legend(loc="best", fontsize=9)
    ax.set_title(f"{head}: r_n and u_n per contact node\n(raw stiffness scene, no geometry)", fontsize=10)


def _body_panel(ax, mdl: dict, un, ut, rn, rt, head: str, config=None, note: str | None = None) -> None:
    from matplotlib.collections import LineCollection

    X = mdl["coords"]
    c = mdl["contact_nodes"]
    n = mdl["normals"]
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    t = np.stack([n[:, 1], -n[:, 0]], axis=1)          # 2D tangent t = (n_y, -n_x)
    reac = rn[:, None] * n + rt[:, None] * t
    if config is not None:
        D = config.displacement
    else:                                                # contact nodes only
        D = np.zeros_like(X)
        D[c] = un[:, None] * n + ut[:, None] * t
    size = float(np.max(np.ptp(X, axis=0))) if len(X) > 1 else 1.0
    size = size if size > 0 else 1.0
    dmax = float(np.max(np.linalg.norm(D, axis=1)))
    scale = DISP_FRACTION * size / dmax if dmax > 0 else 0.0
    Y = X + scale * D

    def segments(P):
        segs = []
        for kind, cells in mdl["cells"].items():
            if cells.size == 0:
                continue
            cells = cells.reshape(len(cells), -1)
            if kind == "line" or cells.shape[1] == 2:
                segs.extend(P[cells])
            else:                                        # polygons (quad, ...): closed outlines
                for cell in cells:
                    segs.append(P[np.append(cell, cell[0])])
        return segs

    what = "whole body" if config is not None else "contact nodes"
    values = config.element_values if config is not None else {}
    ax.add_collection(LineCollection(segments(X), colors="0.78", linewidths=1.2, zorder=1,
                                     label="undeformed"))
    if values:
        _coloured_body(ax, mdl["cells"], Y, values, f"{what} displaced (x{scale:.3g})")
    else:
        ax.add_collection(LineCollection(segments(Y), colors="tab:blue", linewidths=1.4, zorder=2,
                                         label=f"{what} displaced (x{scale:.3g})"))
    if not mdl["cells"]:
        ax.plot(X[:, 0], X[:, 1], ".", color="0.7")

    # obstacle walls: segments through each (undeformed) contact node along its tangent,
    # with short hatches on the obstacle side (-n)
    h = WALL_FRACTION * size / 2
    walls, hatch = [], []
    for p, ni, ti in zip(X[c], n, t):
        walls.append([p - h * ti, p + h * ti])
        for s in np.linspace(-0.8, 0.8, 5):
            q = p + s * h * ti
            hatch.append([q, q - 0.35 * h * (ni + ti)])
    ax.add_collection(LineCollection(walls, colors="black", linewidths=2.0, zorder=3, label="obstacle wall"))
    ax.add_collection(LineCollection(hatch, colors="black", linewidths=0.7, zorder=3))

    ax.plot(Y[c, 0], Y[c, 1], "o", ms=4, color="tab:blue", zorder=4)
    rmax = float(np.max(np.linalg.norm(reac, axis=1)))
    if rmax > 0:
        R = ARROW_FRACTION * size / rmax * reac
        ax.quiver(Y[c, 0], Y[c, 1], R[:, 0], R[:, 1], angles="xy", scale_units="xy", scale=1.0,
                  color="tab:red", width=0.005, zorder=5, label="reaction r")
    for i, p in enumerate(Y[c]):
        ax.annotate(str(i), p, xytext=(-9 * n[i, 0] - 4, -9 * n[i, 1] - 4), textcoords="offset points",
                    fontsize=7, color="0.3")

    pts = np.vstack([X, Y, X[c] - 0.6 * h * n, X[c] + h * t, X[c] - h * t]
                    + ([Y[c] + ARROW_FRACTION * size / rmax * reac] if rmax > 0 else []))
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.06 * max(float(np.max(hi - lo)), 1e-12)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal", adjustable="box")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=4, fontsize=8, frameon=False)
    first = (f"{head}: the whole body (interior from the condensation)" if config is not None else
             f"{head}: only contact nodes displaced ({note or 'body not rebuilt'})")
    ax.set_title(f"{first}\ndisplacement x{scale:.3g} (largest = {DISP_FRACTION:.0%} of body size); "
                 f"arrows: reactions", fontsize=9)


def _coloured_body(ax, cells: dict, Y: np.ndarray, values: dict, label: str) -> None:
    """The deformed body Y (n, 2): continuum cells filled by von Mises stress, bars coloured
    by axial force (diverging, tension red), each with a colour bar."""
    from matplotlib.collections import LineCollection, PolyCollection

    from .recovery import AXIAL_FORCE, VON_MISES
    fig = ax.figure
    if VON_MISES in values:
        polys, vals = [], []
        for kind, v in values[VON_MISES].items():
            polys.extend(Y[np.asarray(cells[kind]).reshape(len(v), -1)])
            vals.append(v)
        pc = PolyCollection(polys, array=np.concatenate(vals), cmap="viridis", edgecolors="0.25",
                            linewidths=0.4, zorder=2, label=label)
        ax.add_collection(pc)
        fig.colorbar(pc, ax=ax, shrink=0.8, label="von Mises stress (element centroid)")
    if AXIAL_FORCE in values:
        lc = LineCollection(Y[np.asarray(cells["line"]).reshape(-1, 2)], linewidths=2.0, zorder=2, label=label)
        ax.add_collection(lc)
        fig.colorbar(_axial_colours(lc, values[AXIAL_FORCE]["line"]), ax=ax, shrink=0.8,
                     label=AXIAL_LABEL)


def _axial_colours(lc, v: np.ndarray):
    """Colour the bars of `lc` by their axial forces v: diverging about 0, tension red."""
    from matplotlib.colors import TwoSlopeNorm
    lim = max(float(np.abs(v).max()), 1e-300)
    lc.set_array(v)
    lc.set_cmap("coolwarm")
    lc.set_norm(TwoSlopeNorm(0.0, -lim, lim))
    return lc


# --------------------------------------------------------------------------- 3D

def _figure_3d(fig, d: dict) -> None:
    """The 3D layout: the body (left, both rows), patterns' mu^c (right top), counts (right bottom)."""
    import mpl_toolkits.mplot3d  # noqa: F401  (registers the "3d" projection)

    body = d["model"] is not None and d["pattern"] is not None
    gs = fig.add_gridspec(2, 2, width_ratios=[1.25, 1], height_ratios=[1.35, 1], left=0.035 if body else 0.06,
                          right=0.97, bottom=0.08, top=0.9 if body else 0.85, wspace=0.12 if body else 0.2,
                          hspace=0.6)
    ax1 = fig.add_subplot(gs[:, 0], projection="3d" if body else None)
    pats = d["patterns"]
    j = d["pattern"]
    if pats is None:
        _message(ax1, "sign patterns were not enumerated for this run\n(compute.enumerate = false)",
                 "wedged configuration")
    elif j is None:
        _message(ax1, f"no feasible sign pattern at mu = {d['mu']:.6g}\n(no wedged configuration)",
                 "wedged configuration")
    elif body:
        _body_3d(ax1, d)
    else:
        head = f"sign pattern {j} of {len(pats)}, contact {pats[j]['contact']}"
        if d["point"] is None:
            _message(ax1, f"no point of the pattern to draw\n({d['config_note']})", head)
        else:
            u, r = d["point"]
            _bars_panel(ax1, u[:d["m"]], r[:d["m"]], head, "a feasible point of the pattern")
    marked = [i == j for i in range(len(pats or []))]
    _mu_c_panel(fig.add_subplot(gs[0, 1]), d, pats, "sign pattern", marked, f"drawn pattern {j}",
                lambda p: f"(|C| = {len(p['contact'])})")
    _counts_panel(fig.add_subplot(gs[1, 1]), d)


def _boundary(cells: dict) -> tuple[list, list, list]:
    """(faces, the cell type and index owning each, segments) of the cells to draw: the
    boundary faces (seen by one cell only) of the 3D cells, and the bars."""
    faces, owner = [], []
    for kind, q in cells.items():
        if kind not in CELL_FACES or not len(q):
            continue
        q = np.asarray(q).reshape(len(q), -1)
        F = np.concatenate([q[:, f] for f in CELL_FACES[kind]])            # face-major
        _, first, count = np.unique(np.sort(F, axis=1), axis=0, return_index=True, return_counts=True)
        for i in np.sort(first[count == 1]):
            faces.append(F[i])
            owner.append((kind, int(i % len(q))))
    bars = np.asarray(cells["line"]).reshape(-1, 2) if "line" in cells else np.zeros((0, 2), dtype=int)
    return faces, owner, bars


def _body_3d(ax, d: dict) -> None:
    """The body in perspective: undeformed and deformed, C/G nodes, reactions, obstacle."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    from .recovery import AXIAL_FORCE, VON_MISES
    mdl, cfg, m = d["model"], d["config"], d["m"]
    pat, j = d["patterns"][d["pattern"]], d["pattern"]
    X, c = mdl["coords"], mdl["contact_nodes"]
    n = mdl["normals"] / np.maximum(np.linalg.norm(mdl["normals"], axis=1, keepdims=True), 1e-300)
    if cfg is not None:
        D, reac = cfg.displacement, cfg.reaction[c]
    else:                          # no point of the pattern without the body: the body as it is
        D = np.zeros_like(X)
        reac = np.zeros((m, 3))
    size = max(float(np.max(np.ptp(X, axis=0))), 1e-300) if len(X) > 1 else 1.0
    dmax = float(np.max(np.linalg.norm(D, axis=1)))
    scale = DISP_FRACTION * size / dmax if dmax > 0 else 0.0
    Y = X + scale * D
    faces, owner, bars = _boundary(mdl["cells"])
    values = cfg.element_values if cfg is not None else {}

    ax.computed_zorder = False                # layers below, not depth-sorted: the nodes stay on top
    edges = [X[b] for b in bars] + [X[np.append(f, f[0])] for f in faces]
    ax.add_collection3d(Line3DCollection(edges, colors="0.72", linewidths=0.6, zorder=1, label="undeformed"))
    label = f"deformed (displacement x{scale:.3g})" if cfg is not None else "body (not rebuilt: undeformed)"
    if faces:
        vm = values.get(VON_MISES)
        pc = Poly3DCollection([Y[f] for f in faces], edgecolors="0.3", linewidths=0.2, alpha=0.6, zorder=3,
                              label=label)
        if vm:
            v = np.array([vm[kind][e] for kind, e in owner])
            top = float(np.percentile(v, VON_MISES_PERCENTILE))
            pc.set_array(v)
            pc.set_cmap("viridis")
            pc.set_clim(0.0, top if top > 0 else None)
            ax.figure.colorbar(pc, ax=ax, shrink=0.5, pad=0.1, extend="max" if v.max() > top else "neither",
                               label=f"von Mises stress (colours end at the {VON_MISES_PERCENTILE}th percentile)")
        else:
            pc.set_facecolor("tab:blue")
        ax.add_collection3d(pc)
    if len(bars):
        lc = Line3DCollection([Y[b] for b in bars], linewidths=2.0, zorder=3, label=label)
        if AXIAL_FORCE in values:
            ax.figure.colorbar(_axial_colours(lc, values[AXIAL_FORCE]["line"]), ax=ax, shrink=0.5, pad=0.1,
                               label=AXIAL_LABEL)
        else:
            lc.set_color("tab:blue")
        ax.add_collection3d(lc)

    ext = [X, Y]
    drawn = _obstacles_3d(ax, d["obstacles"], X[c], n, size)
    if drawn is not None:
        ext.append(drawn)
    in_c = np.isin(np.arange(m), pat["contact"])
    P = Y[c]
    ax.scatter(*P[in_c].T, s=40, color="tab:red", edgecolors="black", linewidths=0.6, depthshade=False,
               zorder=6, label=f"contact set C ({int(in_c.sum())}): u_n = 0")
    ax.scatter(*P[~in_c].T, s=40, facecolors="white", edgecolors="tab:blue", linewidths=1.5,
               depthshade=False, zorder=6, label=f"gap set G ({int((~in_c).sum())}): r_n = 0")
    rmax = float(np.max(np.linalg.norm(reac, axis=1))) if m else 0.0
    if rmax > 0:
        R = 2 * ARROW_FRACTION * size / rmax * reac
        ax.quiver(*P.T, *R.T, pivot="tip", color="tab:red", linewidths=1.6, arrow_length_ratio=0.25,
                  zorder=5, label="reaction (obstacle on body)")
        ext.append(P - R)
    for i, p in enumerate(P):
        q = p - 0.06 * size * n[i]
        ax.text(*q, str(i), fontsize=7, color="0.2", ha="center", va="center", zorder=7)
    pts = np.vstack(ext)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    mid, half = (lo + hi) / 2, np.maximum((hi - lo) / 2, 0.02 * size) * 1.02
    for setter, a, b in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), mid - half, mid + half):
        setter(a, b)
    ax.set_box_aspect(tuple(2 * half), zoom=1.05)
    ax.set_proj_type("persp", focal_length=0.4)
    ax.view_init(elev=22, azim=-58)
    ax.set_xlabel("x", fontsize=9, labelpad=-2)
    ax.set_ylabel("y", fontsize=9, labelpad=-2)
    ax.set_zlabel("z", fontsize=9, labelpad=-2)
    ax.tick_params(labelsize=7, pad=0)
    ax.figure.legend(*ax.get_legend_handles_labels(), loc="lower left", ncol=3, fontsize=8, frameon=False,
                     bbox_to_anchor=(0.01, 0.0))     # below the 3D box, which draws past its frame
    head = f"sign pattern {j} of {len(d['patterns'])}, contact C = {pat['contact']}"
    if cfg is not None:
        title = f"{head}:\nthe whole body at a feasible point; arrows: reactions, pointing at the nodes"
    else:
        import textwrap
        title = "\n".join([f"{head}: body not rebuilt, drawn undeformed"]
                          + textwrap.wrap(d["config_note"] or "no configuration", 100))
    ax.set_title(title, fontsize=9)


def _obstacles_3d(ax, obstacles: list | None, P: np.ndarray, n: np.ndarray, size: float):
    """The obstacle near the contact points P (m, 3) with normals n: the scene's cones and
    planes as translucent surfaces, else a wall square in each node's tangent plane.
    Returns the drawn points (for the axis limits) or None."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    from .models.obstacle import Cone
    if not len(P):
        return None
    h = WALL_FRACTION * size / 2
    polys, lines = [], []
    if obstacles:
        for ob in obstacles:
            if isinstance(ob, Cone):
                a = ob.axis
                e1 = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
                e1 /= np.linalg.norm(e1)
                e2 = np.cross(a, e1)
                t = (P - ob.apex) @ a
                ts = np.linspace(max(t.min() - 0.15 * size, 0.0), t.max() + 0.15 * size, 2)
                ph = np.linspace(0, 2 * np.pi, 49)
                ring = np.cos(ph)[:, None] * e1 + np.sin(ph)[:, None] * e2
                rows = [ob.apex + tk * a + tk * math.tan(ob.alpha) * ring for tk in ts]
                polys += [[rows[0][i], rows[0][i + 1], rows[1][i + 1], rows[1][i]] for i in range(len(ph) - 1)]
                lines += [rows[0], rows[1]] + [[rows[0][i], rows[1][i]] for i in range(0, len(ph) - 1, 4)]
            else:
                e1 = np.cross(ob.normal, [1.0, 0.0, 0.0] if abs(ob.normal[0]) < 0.9 else [0.0, 1.0, 0.0])
                e1 /= np.linalg.norm(e1)
                e2 = np.cross(ob.normal, e1)
                near = P[ob.distance(P) <= 1e-6 * size + 1e-3 * size]
                near = near if len(near) else P
                q = near - np.outer((near - ob.point) @ ob.normal, ob.normal)
                u, v = (q - ob.point) @ e1, (q - ob.point) @ e2
                pad = 0.1 * size
                corners = [(u.min() - pad, v.min() - pad), (u.max() + pad, v.min() - pad),
                           (u.max() + pad, v.max() + pad), (u.min() - pad, v.max() + pad)]
                polys.append([ob.point + cu * e1 + cv * e2 for cu, cv in corners])
        label = "obstacle surface"
    else:
        for p, ni in zip(P, n):
            e1 = np.cross(ni, [0.0, 0.0, 1.0] if abs(ni[2]) < 0.9 else [1.0, 0.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(ni, e1)
            polys.append([p + h * (s1 * e1 + s2 * e2) for s1, s2 in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
        label = "obstacle wall at each contact node"
    ax.add_collection3d(Poly3DCollection(polys, facecolor="tan", edgecolor="none" if obstacles else "0.4",
                                         linewidths=0.4, alpha=0.2, zorder=4, label=label))
    if lines:
        ax.add_collection3d(Line3DCollection(lines, colors="0.5", linewidths=0.5, zorder=4))
    return np.vstack([np.asarray(q) for q in polys])


# --------------------------------------------------------------------------- right panel

def _cones_panel(ax, d: dict) -> None:
    """2D: the mu^c of the run's cones, those holding the drawn ray highlighted."""
    cones = d["cones"]
    marked = [d["ray"] is not None and d["ray"] in c.get("rays", []) for c in cones or []]
    _mu_c_panel(ax, d, cones, "cone", marked, f"cone with the drawn ray {d['ray']}",
                lambda c: f"({len(c.get('rays', []))} rays)")


def _mu_c_panel(ax, d: dict, items: list | None, noun: str, marked: list, marked_label: str,
                tick_note) -> None:
    """Bars of the mu^c of a run's items (cones or sign patterns; None: not computed), the
    `marked` ones highlighted, with the run's mu and the global mu^c as lines."""
    from matplotlib.patches import Patch

    title = f"mu^c of the {noun}s at mu = {d['mu']:.6g}"
    glob = "none" if d["mu_c"] is None else f"{d['mu_c']:.6g}"
    if items is None:
        _message(ax, f"{noun}s were not computed for this run\n(global mu^c = {glob})", title)
        return
    if not items:
        _message(ax, f"the run has no {noun}s\n(global mu^c = {glob})", title)
        return
    vals = [c.get("mu_c") for c in items]
    if all(v is None for v in vals):
        _message(ax, f"{len(items)} {noun}(s); mu^c not computed", title)
        return
    x = np.arange(len(items))
    y = np.array([np.nan if v is None else float(v) for v in vals])
    has_ray = np.asarray(marked, dtype=bool)
    colors = np.where(has_ray, "tab:orange", "tab:blue")
    ax.bar(x, np.nan_to_num(y), 0.7 if len(items) <= 100 else 1.0, color=colors)
    handles = []
    if has_ray.any():
        handles.append(Patch(color="tab:orange", label=marked_label))
    if (~has_ray).any():
        handles.append(Patch(color="tab:blue", label=f"other {noun}s" if has_ray.any() else f"{noun}s"))
    top = np.nanmax(np.append(y, [d["mu"]] + ([d["mu_c"]] if d["mu_c"] is not None else [])))
    if len(items) > MAX_TICKS:                # thin bars: a marker above the highlighted ones
        ax.plot(x[has_ray], np.nan_to_num(y[has_ray]) + 0.04 * top, "v", color="tab:orange", ms=7)
    for i in np.flatnonzero(np.isnan(y)):
        ax.text(x[i], 0.02 * top, "mu^c n/a", ha="center", va="bottom", fontsize=8, rotation=90,
                color=colors[i])
    ax.axhline(d["mu"], color="black", ls="--", lw=1.2, label=f"run mu = {d['mu']:.6g}")
    if d["mu_c"] is not None:
        ax.axhline(d["mu_c"], color="tab:green", lw=1.5, label=f"global mu^c = {d['mu_c']:.6g}")
    else:
        ax.plot([], [], " ", label="global mu^c: none")
    ax.set_ylim(0, 1.15 * top if top > 0 else 1.0)
    half = max(len(items), 4) / 2
    ax.set_xlim((len(items) - 1) / 2 - half, (len(items) - 1) / 2 + half)
    ax.set_xlabel(noun)
    ax.set_ylabel("mu^c")
    if len(items) <= MAX_TICKS:
        ax.set_xticks(x)
        if len(items) <= 6:
            ax.set_xticklabels([f"{i}\n{tick_note(c)}" for i, c in enumerate(items)], fontsize=8)
    line_handles, _ = ax.get_legend_handles_labels()
    ax.legend(handles=line_handles + handles, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2,
              fontsize=8, frameon=False)
    ax.set_title(title, fontsize=10)


def _counts_panel(ax, d: dict) -> None:
    """3D: the number of feasible sign patterns of every run against its mu (steps between
    runs), the drawn run highlighted and the global mu^c marked."""
    pts = sorted((mu, n) for mu, n in d["counts"] if n is not None)
    title = "feasible sign patterns against mu"
    if not pts:
        _message(ax, "sign patterns were not enumerated\n(compute.enumerate = false)", title)
        return
    mus, ns = np.array([p[0] for p in pts]), np.array([p[1] for p in pts])
    if len(pts) > 1:
        ax.step(mus, ns, where="post", color="tab:blue", lw=1.2)
    ax.plot(mus, ns, "o", color="tab:blue", ms=5, label="runs of the result")
    here = [n for mu, n in pts if mu == d["mu"]]
    if here:
        ax.plot([d["mu"]], here[:1], "o", color="tab:orange", ms=8, label=f"this run (mu = {d['mu']:.6g})")
    if d["mu_c"] is not None:
        ax.axvline(d["mu_c"], color="tab:green", lw=1.5, label=f"global mu^c = {d['mu_c']:.6g}")
    lo = min(mus.min(), d["mu_c"] if d["mu_c"] is not None else mus.min())
    hi = mus.max()
    pad = 0.08 * (hi - lo) if hi > lo else 0.1 * max(hi, 1e-12)
    ax.set_xlim(lo - pad, hi + pad)
    ax.set_ylim(0, 1.15 * max(int(ns.max()), 1))
    ax.set_xlabel("mu")
    ax.set_ylabel("feasible patterns")
    ax.legend(loc="upper left", fontsize=8, frameon=False)
    ax.set_title(title, fontsize=10)


# --------------------------------------------------------------------------- helpers

def _message(ax, text: str, title: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", fontsize=11, transform=ax.transAxes)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title, fontsize=10)


def _save_atomic(fig, output: str) -> None:
    replace_atomic(output, lambda tmp: fig.savefig(tmp, format="png"), ".png")
