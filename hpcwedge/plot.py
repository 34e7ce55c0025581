"""`hpcwedge plot` (SPEC §4): one wedged configuration and the cones' mu^c, as a PNG.

Left panel: with a /model group, the undeformed body (light grey) and the whole body
deformed by the chosen wedged ray (configuration.load_configuration: interior nodes from
the condensation, on the body rebuilt from the stored scene), coloured by the element
values — von Mises stress of continuum elements, axial force of bars — with the reactions
at the contact nodes and the obstacle walls. When the body cannot be rebuilt (e.g. its
mesh file is gone) only the contact nodes are displaced, and the title says so. Without
a /model group (raw stiffness scenes), bars of r_n and u_n per contact node.
Right panel: the mu^c of every cone of the run, with the run's mu and the global mu^c.

Drawn with matplotlib's Agg canvas on a bare Figure (no pyplot, no display).
"""
from __future__ import annotations

import json
import math
import os
import tempfile

import numpy as np

from .results import check_items, index, index_range, open_result

DISP_FRACTION = 0.10     # largest drawn displacement / body size
ARROW_FRACTION = 0.15    # largest drawn reaction arrow / body size
WALL_FRACTION = 0.12     # length of a wall segment / body size
MAX_TICKS = 40           # per-item tick labels only up to this many bars


def plot_result(path: str, output: str, run: int = -1, ray: int = 0) -> None:
    """Draw run `run` (Python-style index, -1 = last) and its wedged ray `ray` of the
    result file `path`, and save the figure as PNG to `output` (atomically).

    ValueError (one line) for a 3D result, a bad run or ray index (PlotError), or a file that
    is missing, damaged or not a hpcwedge result (results.FileError).
    """
    data = _load(path, run, ray)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13, 5.5), dpi=100)
    FigureCanvasAgg(fig)
    ax1, ax2 = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.15, 1]})
    _config_panel(ax1, data)
    _cones_panel(ax2, data)
    fig.suptitle(f"{data['name']}: run {data['run']} of {data['n_runs']} (mu = {data['mu']:.6g}), "
                 f"m = {data['m']} contact node{'s' if data['m'] != 1 else ''}", fontsize=12)
    fig.tight_layout()
    _save_atomic(fig, output)


# --------------------------------------------------------------------------- reading

class PlotError(ValueError):
    """A figure that cannot be drawn (bad run or ray index, a 3D result): one line."""


def _load(path: str, run: int, ray: int) -> dict:
    """The data of the figure; results.FileError for a missing, damaged or malformed file."""
    with open_result(path, passthrough=(PlotError,)) as f:
        return _read(f, path, run, ray)


def _read(f, path: str, run: int, ray: int) -> dict:
    a = f.attrs
    dim = int(a["dim"])
    if dim == 3:
        raise PlotError("plot: 3D results are not drawn yet")
    if dim != 2:
        raise PlotError(f"plot: {path}: dim must be 2 or 3, got {dim}")
    m = int(a["m"])
    keys = sorted(f["runs"])
    n_runs = len(keys)
    k = index(run, n_runs)
    if k is None:
        raise PlotError(f"plot: run {run} out of range (the result has {n_runs} run(s): {index_range(n_runs)})")
    g = f["runs"][keys[k]]
    rays = np.asarray(g["rays"][()], dtype=float) if "rays" in g else None
    if rays is not None:
        rays = rays.reshape(-1, 4 * m) if rays.size else np.zeros((0, 4 * m))
        if rays.shape[1] != 4 * m:
            raise PlotError(f"plot: {path}: run {k} rays have {rays.shape[1]} entries, expected 4m = {4 * m}")
    n_rays = 0 if rays is None else len(rays)
    j = index(ray, n_rays) if n_rays else (0 if ray in (0, -1) else None)
    if j is None:
        what = f"0..{n_rays - 1} or -{n_rays}..-1" if n_rays else "only 0 when there are none"
        raise PlotError(f"plot: ray {ray} out of range (run {k} has {n_rays} wedged ray(s): {what})")
    mu_c = float(a["mu_c"]) if "mu_c" in a else math.nan
    out = {"name": _str(a.get("name", os.path.basename(path))), "dim": dim, "m": m,
           "run": k, "n_runs": n_runs, "mu": float(g.attrs["mu"]),
           "mu_c": None if not math.isfinite(mu_c) else mu_c,
           "rays": rays, "ray": j if n_rays else None,
           "cones": json.loads(_str(g["cones_json"][()])) if "cones_json" in g else None,
           "model": None}
    check_items(out["cones"], None, n_rays, m)
    if "model" in f:
        mg = f["model"]
        mdl = {"coords": np.asarray(mg["coords"][()], dtype=float),
               "contact_nodes": np.asarray(mg["contact_nodes"][()], dtype=int),
               "normals": np.asarray(mg["normals"][()], dtype=float),
               "cells": {name[len("cells_"):]: np.asarray(mg[name][()], dtype=int)
                         for name in mg if name.startswith("cells_")}}
        if mdl["coords"].ndim != 2 or mdl["coords"].shape[1] != 2 or len(mdl["contact_nodes"]) != m \
                or mdl["normals"].shape != (m, 2):
            raise PlotError(f"plot: {path}: /model does not match dim 2 and m = {m}")
        out["model"] = mdl
        out["config"], out["config_note"] = None, None
        if n_rays:
            from .configuration import ConfigurationError, load_configuration
            try:
                out["config"] = load_configuration(path, run=k, ray=j)
            except ConfigurationError as e:
                out["config_note"] = str(e)
    return out


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


def _bars_panel(ax, un, rn, head: str) -> None:
    m = len(un)
    x = np.arange(m)
    w = 0.38
    ax.bar(x - w / 2, rn, w, color="tab:red", label="r_n (normal reaction)")
    ax.bar(x + w / 2, un, w, color="tab:blue", label="u_n (normal gap)")
    ax.axhline(0.0, color="black", lw=0.8)
    ax.set_xlabel("contact node (position in the contact list)")
    ax.set_ylabel("value (ray normalised to sum r_n = 1)")
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
    from matplotlib.colors import TwoSlopeNorm

    from .configuration import AXIAL_FORCE, VON_MISES
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
        v = values[AXIAL_FORCE]["line"]
        lim = max(float(np.abs(v).max()), 1e-300)
        lc = LineCollection(Y[np.asarray(cells["line"]).reshape(-1, 2)], array=v, cmap="coolwarm",
                            norm=TwoSlopeNorm(0.0, -lim, lim), linewidths=2.0, zorder=2, label=label)
        ax.add_collection(lc)
        fig.colorbar(lc, ax=ax, shrink=0.8, label="bar axial force (tension > 0)")


# --------------------------------------------------------------------------- right panel

def _cones_panel(ax, d: dict) -> None:
    from matplotlib.patches import Patch

    title = f"mu^c of the cones at mu = {d['mu']:.6g}"
    cones = d["cones"]
    glob = "none" if d["mu_c"] is None else f"{d['mu_c']:.6g}"
    if cones is None:
        _message(ax, f"cones were not computed for this run\n(global mu^c = {glob})", title)
        return
    if not cones:
        _message(ax, f"the run has no cones\n(global mu^c = {glob})", title)
        return
    vals = [c.get("mu_c") for c in cones]
    if all(v is None for v in vals):
        _message(ax, f"{len(cones)} cone(s); mu^c not computed", title)
        return
    x = np.arange(len(cones))
    y = np.array([np.nan if v is None else float(v) for v in vals])
    has_ray = np.array([d["ray"] is not None and d["ray"] in c.get("rays", []) for c in cones])
    colors = np.where(has_ray, "tab:orange", "tab:blue")
    ax.bar(x, np.nan_to_num(y), 0.7, color=colors)
    handles = []
    if has_ray.any():
        handles.append(Patch(color="tab:orange", label=f"cone with the drawn ray {d['ray']}"))
    if (~has_ray).any():
        handles.append(Patch(color="tab:blue", label="other cones" if has_ray.any() else "cones"))
    top = np.nanmax(np.append(y, [d["mu"]] + ([d["mu_c"]] if d["mu_c"] is not None else [])))
    for i in np.flatnonzero(np.isnan(y)):
        ax.text(x[i], 0.02 * top, "mu^c n/a", ha="center", va="bottom", fontsize=8, rotation=90,
                color=colors[i])
    ax.axhline(d["mu"], color="black", ls="--", lw=1.2, label=f"run mu = {d['mu']:.6g}")
    if d["mu_c"] is not None:
        ax.axhline(d["mu_c"], color="tab:green", lw=1.5, label=f"global mu^c = {d['mu_c']:.6g}")
    else:
        ax.plot([], [], " ", label="global mu^c: none")
    ax.set_ylim(0, 1.15 * top if top > 0 else 1.0)
    half = max(len(cones), 4) / 2
    ax.set_xlim((len(cones) - 1) / 2 - half, (len(cones) - 1) / 2 + half)
    ax.set_xlabel("cone")
    ax.set_ylabel("mu^c")
    if len(cones) <= MAX_TICKS:
        ax.set_xticks(x)
        if len(cones) <= 6:
            ax.set_xticklabels([f"{i}\n({len(c.get('rays', []))} rays)" for i, c in enumerate(cones)],
                               fontsize=8)
    line_handles, _ = ax.get_legend_handles_labels()
    ax.legend(handles=line_handles + handles, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2, fontsize=8, frameon=False)
    ax.set_title(title, fontsize=10)


# --------------------------------------------------------------------------- helpers

def _message(ax, text: str, title: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", fontsize=11, transform=ax.transAxes)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title, fontsize=10)


def _save_atomic(fig, output: str) -> None:
    folder = os.path.dirname(os.path.abspath(output)) or "."
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".png", dir=folder)
    os.close(fd)
    try:
        fig.savefig(tmp, format="png")
        os.replace(tmp, output)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
