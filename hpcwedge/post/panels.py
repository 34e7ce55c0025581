"""What the 2D and 3D figures share: sizes, reading a run's item with its body, the index
checks, the bars and mu^c panels."""
from __future__ import annotations

import math
import os
from typing import Callable

import numpy as np

from hpcwedge.errors import UserError
from hpcwedge.results.hdf5 import RangeError, index, index_range, read_model, read_run, text
from hpcwedge.results.record import StoredModel

DISP_FRACTION = 0.10     # largest drawn displacement / body size
ARROW_FRACTION = 0.15    # largest drawn reaction arrow / body size (3D: twice that)
WALL_FRACTION = 0.12     # length of a wall segment / body size
MAX_TICKS = 40           # per-item tick labels only up to this many bars
AXIAL_LABEL = "bar axial force (tension > 0)"


class PlotError(UserError):
    """A figure that cannot be drawn (bad run, ray or pattern index, the wrong option for
    the dimension): one line."""


#: the dimension of a figure and the noun of its items, by the kind of item it draws
ITEM_KINDS = {"ray": (2, "wedged ray"), "pattern": (3, "sign pattern")}


def read_figure(f, path: str, run: int, kind: str, j: int, read: Callable[[object, int], tuple]) -> dict:
    """The data every figure has, of item j (Python-style index) of run `run` of the open
    result f, kind "ray" (2D) or "pattern" (3D): name, dim, m, run (its index), n_runs, mu,
    mu_c (global, None when absent), the run's items under kind + "s" (None: not computed),
    the item's index under kind (None when the run has none), the figure's other data read
    by read(run group, m) -> (items, dict), model (the checked /model group, or None) and
    config, config_note (the item's Configuration, or None and why; both None without a model
    or an item). PlotError for a bad run or item index or a /model of the wrong shape."""
    dim, noun = ITEM_KINDS[kind]
    a = f.attrs
    m = int(a["m"])
    k, n_runs, g = run_group(f, run)
    items, more = read(g, m)
    i = item_index(j, 0 if items is None else len(items), kind, noun, k)
    out = {"name": text(a.get("name", os.path.basename(path))), "dim": dim, "m": m, "run": k, "n_runs": n_runs,
           "mu": float(g.attrs["mu"]), "mu_c": mu_c_attr(a), kind + "s": items, kind: i, **more,
           "model": checked_model(f, path, dim, m), "config": None, "config_note": None}
    if out["model"] is not None and i is not None:
        out["config"], out["config_note"] = configuration_of(path, k, **{kind: i})
    return out


def run_group(f, run: int):
    """(index k, number of runs, the HDF5 group) of run `run`; PlotError when out of range."""
    try:
        return read_run(f, run)
    except RangeError as e:
        raise PlotError(f"plot: {e}") from None


def item_index(j: int, n: int, name: str, noun: str, k: int) -> int | None:
    """Index j into a run's n items (None when there are none and j is 0 or -1), else PlotError."""
    i = index(j, n) if n else (0 if j in (0, -1) else None)
    if i is None:
        what = index_range(n) if n else "only 0 when there are none"
        raise PlotError(f"plot: {name} {j} out of range (run {k} has {n} {noun}(s): {what})")
    return i if n else None


def checked_model(f, path: str, dim: int, m: int) -> StoredModel | None:
    """The /model group (results.read_model), or None without one; PlotError unless it has
    the result's dimension and m contact nodes."""
    mdl = read_model(f)
    if mdl is None:
        return None
    if mdl.coords.ndim != 2 or mdl.coords.shape[1] != dim or len(mdl.contact_nodes) != m \
            or mdl.normals.shape != (m, dim):
        raise PlotError(f"plot: {path}: /model does not match dim {dim} and m = {m}")
    return mdl


def configuration_of(path: str, k: int, **item):
    """(Configuration of the item, None) or (None, the one-line reason it cannot be made)."""
    from hpcwedge.post.recovery import ConfigurationError, load_configuration
    try:
        return load_configuration(path, run=k, **item), None
    except ConfigurationError as e:
        return None, str(e)


def mu_c_attr(attrs) -> float | None:
    """The global mu^c of a result's root attributes; None when absent or not finite."""
    v = float(attrs["mu_c"]) if "mu_c" in attrs else math.nan
    return v if math.isfinite(v) else None


def bars_panel(ax, un, rn, head: str, what: str = "ray") -> None:
    """Bars of r_n and u_n per contact node (raw stiffness scenes: no geometry to draw)."""
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


def axial_colours(lc, v: np.ndarray):
    """Colour the bars of `lc` by their axial forces v: diverging about 0, tension red."""
    from matplotlib.colors import TwoSlopeNorm
    lim = max(float(np.abs(v).max()), 1e-300)
    lc.set_array(v)
    lc.set_cmap("coolwarm")
    lc.set_norm(TwoSlopeNorm(0.0, -lim, lim))
    return lc


def mu_c_panel(ax, d: dict, items: list | None, noun: str, marked: list, marked_label: str,
                tick_note) -> None:
    """Bars of the mu^c of a run's items (cones or sign patterns; None: not computed), the
    `marked` ones highlighted, with the run's mu and the global mu^c as lines."""
    from matplotlib.patches import Patch

    title = f"mu^c of the {noun}s at mu = {d['mu']:.6g}"
    glob = "none" if d["mu_c"] is None else f"{d['mu_c']:.6g}"
    if items is None:
        message(ax, f"{noun}s were not computed for this run\n(global mu^c = {glob})", title)
        return
    if not items:
        message(ax, f"the run has no {noun}s\n(global mu^c = {glob})", title)
        return
    vals = [c.mu_c for c in items]
    if all(v is None for v in vals):
        message(ax, f"{len(items)} {noun}(s); mu^c not computed", title)
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


def message(ax, note: str, title: str) -> None:
    """An empty panel saying `note` (why there is nothing to draw) under `title`."""
    ax.text(0.5, 0.5, note, ha="center", va="center", fontsize=11, transform=ax.transAxes)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title, fontsize=10)
