"""`hpcwedge plot` (SPEC §4): one wedged configuration and the mu^c of a run's cones or
sign patterns, as a PNG, PDF or SVG (by the output's suffix: `figure_format`).

2D (`--ray J`). Left panel: with a /model group, the undeformed body (light grey) and the
whole body deformed by the chosen wedged ray (recovery.load_configuration: interior
nodes from the condensation, on the body rebuilt from the stored scene), coloured by the
element values — von Mises stress of continuum elements, axial force of bars — with the
reactions at the contact nodes and the obstacle walls. When the body cannot be rebuilt
(e.g. its mesh file is gone) only the contact nodes are displaced, and the title says so.
Without a /model group (raw stiffness scenes), bars of r_n and u_n per contact node.
Right panel: the mu^c of every cone of the run, with the run's mu and the global mu^c.

3D (`--pattern J`): the body in perspective with the sign pattern, its mu^c and the
feasible-pattern counts (plot3d.py).

Drawn with matplotlib's Agg canvas on a bare Figure (no pyplot, no display).
"""
from __future__ import annotations

import os

import numpy as np

from hpcwedge.contact.problem import blocks
from hpcwedge.files import replace_atomic
from hpcwedge.post.panels import (
    ARROW_FRACTION,
    AXIAL_LABEL,
    DISP_FRACTION,
    WALL_FRACTION,
    PlotError,
    axial_colours,
    bars_panel,
    message,
    mu_c_panel,
    read_figure,
)
from hpcwedge.results.hdf5 import open_result, read_items, read_rays

#: the figure formats by file suffix (no suffix: PNG)
FORMATS = {".png": "png", ".pdf": "pdf", ".svg": "svg", "": "png"}


def plot_result(path: str, output: str, run: int = -1, ray: int | None = None,
                pattern: int | None = None) -> str:
    """Draw run `run` (Python-style index, -1 = last) of the result file `path` and save the
    figure to `output` (atomically; PNG, PDF or SVG by its suffix, `figure_format`): for a
    2D result its wedged ray `ray` (default 0), for a 3D result its sign pattern `pattern`
    (default 0). Returns what was drawn, as export's label says it: "run 1 (mu = 0.65),
    wedged ray 0" (runs numbered from 0, as `show` lists them).

    ValueError (one line) for an output suffix of no known format, a bad run, ray or
    pattern index, `pattern` given for a 2D or `ray` for a 3D result (PlotError), or a file
    that is missing, damaged or not a hpcwedge result (files.FileError).
    """
    fmt = figure_format(output)
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
        from hpcwedge.post.plot3d import figure_3d
        figure_3d(fig, data)
    fig.suptitle(f"{data['name']}: {run_title(data['run'], data['n_runs'], data['mu'])}, {what}", fontsize=12)
    if data["dim"] == 2:
        fig.tight_layout()
    replace_atomic(output, lambda tmp: fig.savefig(tmp, format=fmt), "." + fmt)
    kind = "ray" if data["dim"] == 2 else "pattern"
    item = "" if data.get(kind) is None else f", {'wedged ray' if kind == 'ray' else 'sign pattern'} {data[kind]}"
    return f"run {data['run']} (mu = {data['mu']:.6g}){item}"


def run_title(k: int, n_runs: int, mu: float) -> str:
    """A figure's run, numbered from 0 as `show`, `--run` and the JSON's runs list number it:
    "run 1 (mu = 0.65) of runs 0-1", "run 0 (mu = 0.65), the only run"."""
    return f"run {k} (mu = {mu:.6g})" + (", the only run" if n_runs == 1 else f" of runs 0-{n_runs - 1}")


def figure_format(output: str) -> str:
    """The format of a figure written to `output`, from its suffix (FORMATS, any case; no
    suffix: "png"); PlotError for any other suffix."""
    suffix = os.path.splitext(os.fspath(output))[1]
    fmt = FORMATS.get(suffix.lower())
    if fmt is None:
        known = ", ".join(k for k in FORMATS if k)
        raise PlotError(f"plot: {os.fspath(output)}: no figure format for the suffix {suffix!r} "
                        f"(use {known})")
    return fmt


# --------------------------------------------------------------------------- reading



def _load(path: str, run: int, ray: int | None = None, pattern: int | None = None) -> dict:
    """The data of the figure; files.FileError for a missing, damaged or malformed file."""
    with open_result(path, passthrough=(PlotError,)) as f:
        return _read(f, path, run, ray, pattern)










def _read(f, path: str, run: int, ray: int | None = None, pattern: int | None = None) -> dict:
    """The figure data of the open result f (2D here, 3D: plot3d.read_3d); PlotError."""
    a = f.attrs
    dim = int(a["dim"])
    if dim not in (2, 3):
        raise PlotError(f"plot: {path}: dim must be 2 or 3, got {dim}")
    if dim == 2 and pattern is not None:
        raise PlotError("plot: --pattern is for 3D results; this result is 2D (draw a wedged ray with --ray; "
                        "`hpcwedge export --pattern J` writes a 2D sign pattern's configuration)")
    if dim == 3 and ray is not None:
        raise PlotError("plot: --ray is for 2D results; this result is 3D (draw a sign pattern with --pattern)")
    if dim == 3:
        from hpcwedge.post.plot3d import read_3d
        return read_3d(f, path, run, 0 if pattern is None else pattern)
    return read_figure(f, path, run, "ray", 0 if ray is None else ray, _rays_and_cones)


def _rays_and_cones(g, m: int) -> tuple:
    """(the run's wedged rays, its cones and sign patterns) of the run group g; files.FileError."""
    rays = read_rays(g, 4 * m)
    n_rays = 0 if rays is None else len(rays)
    more = {"cones": read_items(g, "cones", n_rays, m), "patterns": read_items(g, "patterns", n_rays, m)}
    return rays, more




# --------------------------------------------------------------------------- left panel

def _split(ray_vec: np.ndarray, m: int):
    return blocks(ray_vec, m, 4)              # u_n, u_t, r_n, r_t


def _config_panel(ax, d: dict) -> None:
    if d["rays"] is None:
        why = ("(compute.enumerate = false)" if d.get("patterns") is None else
               f'(compute.enumerate = "patterns": {len(d["patterns"])} sign patterns;\n'
               "hpcwedge export --pattern J writes one's configuration)")
        message(ax, f"wedged rays were not enumerated for this run\n{why}", "wedged configuration")
        return
    if d["ray"] is None:
        message(ax, f"no wedged configuration at mu = {d['mu']:.6g}\n(the run has no wedged rays)",
                 "wedged configuration")
        return
    m = d["m"]
    un, ut, rn, rt = _split(d["rays"][d["ray"]], m)
    head = f"wedged ray {d['ray']} of {len(d['rays'])}"
    if d["model"] is None:
        bars_panel(ax, un, rn, head)
    else:
        _body_panel(ax, d["model"], un, ut, rn, rt, head, d.get("config"), d.get("config_note"))




def _body_panel(ax, mdl: dict, un, ut, rn, rt, head: str, config=None, note: str | None = None) -> None:
    """The body undeformed and displaced by the ray (the whole body with a configuration,
    else its contact nodes only), the obstacle walls, the reactions, the node numbers."""
    from matplotlib.collections import LineCollection

    X = mdl.coords
    c = mdl.contact_nodes
    n = mdl.normals
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
    what = "whole body" if config is not None else "contact nodes"
    values = config.element_values if config is not None else {}
    ax.add_collection(LineCollection(_outlines(mdl.cells, X), colors="0.78", linewidths=1.2, zorder=1,
                                     label="undeformed"))
    if values:
        _coloured_body(ax, mdl.cells, Y, values, f"{what} displaced (x{scale:.3g})")
    else:
        ax.add_collection(LineCollection(_outlines(mdl.cells, Y), colors="tab:blue", linewidths=1.4, zorder=2,
                                         label=f"{what} displaced (x{scale:.3g})"))
    if not mdl.cells:                                   # nodes only (a matrix body without a mesh)
        ax.plot(X[:, 0], X[:, 1], ".", color="0.7")
        if config is not None:
            ax.plot(Y[:, 0], Y[:, 1], ".", ms=4, color="tab:blue", zorder=3)
    h = WALL_FRACTION * size / 2
    _walls(ax, X[c], n, t, h)
    ax.plot(Y[c, 0], Y[c, 1], "o", ms=4, color="tab:blue", zorder=4)
    R = _reactions_2d(ax, Y[c], reac, n, size)
    _frame_2d(ax, np.vstack([X, Y, X[c] - 0.6 * h * n, X[c] + h * t, X[c] - h * t]
                            + ([Y[c] + R] if R is not None else [])))
    first = (f"{head}: the whole body (interior from the condensation)" if config is not None else
             f"{head}: only contact nodes displaced ({note or 'body not rebuilt'})")
    ax.set_title(f"{first}\ndisplacement x{scale:.3g} (largest = {DISP_FRACTION:.0%} of body size); "
                 f"arrows: reactions", fontsize=9)


def _outlines(cells: dict, P: np.ndarray) -> list:
    """The segments drawing the cells on the points P: bars, and closed polygon outlines."""
    segs = []
    for kind, q in cells.items():
        if q.size == 0:
            continue
        q = q.reshape(len(q), -1)
        if kind == "line" or q.shape[1] == 2:
            segs.extend(P[q])
        else:                                        # polygons (quad, ...): closed outlines
            for cell in q:
                segs.append(P[np.append(cell, cell[0])])
    return segs


def _walls(ax, P: np.ndarray, n: np.ndarray, t: np.ndarray, h: float) -> None:
    """Obstacle walls: segments of half-length h through each (undeformed) contact node P
    along its tangent t, with short hatches on the obstacle side (-n)."""
    from matplotlib.collections import LineCollection

    walls, hatch = [], []
    for p, ni, ti in zip(P, n, t):
        walls.append([p - h * ti, p + h * ti])
        for s in np.linspace(-0.8, 0.8, 5):
            q = p + s * h * ti
            hatch.append([q, q - 0.35 * h * (ni + ti)])
    ax.add_collection(LineCollection(walls, colors="black", linewidths=2.0, zorder=3, label="obstacle wall"))
    ax.add_collection(LineCollection(hatch, colors="black", linewidths=0.7, zorder=3))


def _reactions_2d(ax, P: np.ndarray, reac: np.ndarray, n: np.ndarray, size: float):
    """The reactions reac at the displaced contact nodes P as arrows (the largest
    ARROW_FRACTION of the body size), and the nodes' numbers; returns the drawn arrows
    (None when there is no reaction)."""
    rmax = float(np.max(np.linalg.norm(reac, axis=1)))
    R = None
    if rmax > 0:
        R = ARROW_FRACTION * size / rmax * reac
        ax.quiver(P[:, 0], P[:, 1], R[:, 0], R[:, 1], angles="xy", scale_units="xy", scale=1.0,
                  color="tab:red", width=0.005, zorder=5, label="reaction r")
    for i, p in enumerate(P):
        ax.annotate(str(i), p, xytext=(-9 * n[i, 0] - 4, -9 * n[i, 1] - 4), textcoords="offset points",
                    fontsize=7, color="0.3")
    return R


def _frame_2d(ax, pts: np.ndarray) -> None:
    """Equal-aspect limits around the points pts, the legend below the axes."""
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.06 * max(float(np.max(hi - lo)), 1e-12)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal", adjustable="box")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=4, fontsize=8, frameon=False)


def _coloured_body(ax, cells: dict, Y: np.ndarray, values: dict, label: str) -> None:
    """The deformed body Y (n, 2): continuum cells filled by von Mises stress, bars coloured
    by axial force (diverging, tension red), each with a colour bar."""
    from matplotlib.collections import LineCollection, PolyCollection

    from hpcwedge.post.recovery import AXIAL_FORCE, VON_MISES
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
        fig.colorbar(axial_colours(lc, values[AXIAL_FORCE]["line"]), ax=ax, shrink=0.8,
                     label=AXIAL_LABEL)




# --------------------------------------------------------------------------- right panel

def _cones_panel(ax, d: dict) -> None:
    """2D: the mu^c of the run's cones, those holding the drawn ray highlighted."""
    cones = d["cones"]
    marked = [d["ray"] is not None and d["ray"] in c.rays for c in cones or []]
    mu_c_panel(ax, d, cones, "cone", marked, f"cone with the drawn ray {d['ray']}",
                lambda c: f"({len(c.rays)} rays)")




# --------------------------------------------------------------------------- helpers


