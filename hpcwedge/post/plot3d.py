"""3D panels of `hpcwedge plot` (`--pattern J`; plot.plot_result draws through here).

Left panel: the body in perspective, undeformed (light grey) and
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
"""
from __future__ import annotations

import math
import os

import numpy as np

from hpcwedge.nodesets import to_mask
from hpcwedge.post.panels import (
    ARROW_FRACTION,
    AXIAL_LABEL,
    DISP_FRACTION,
    WALL_FRACTION,
    axial_colours,
    bars_panel,
    message,
    mu_c_panel,
    read_figure,
)
from hpcwedge.results.hdf5 import read_counts, read_items, stored_scene

VON_MISES_PERCENTILE = 95  # the colour scale ends here (point contacts concentrate the stress)
#: boundary faces of the 3D cells (meshio / VTK node order), for the drawn surface
CELL_FACES = {"tetra": ((0, 2, 1), (0, 1, 3), (1, 2, 3), (0, 3, 2)),
              "hexahedron": ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6),
                             (3, 0, 4, 7))}


# --------------------------------------------------------------------------- reading

def read_3d(f, path: str, run: int, pattern: int) -> dict:
    """The figure data of sign pattern `pattern` of run `run` of the open 3D result f."""
    def patterns_and_counts(g, m: int) -> tuple:
        patterns = read_items(g, "patterns", 0, m)
        return patterns, {"counts": read_counts(f, "n_patterns"), "obstacles": None, "point": None}

    out = read_figure(f, path, run, "pattern", pattern, patterns_and_counts)
    scene = _scene(f, path)
    if scene is not None and scene.obstacles:
        from hpcwedge.models.obstacle import parse_obstacles
        try:
            out["obstacles"] = parse_obstacles(scene.obstacles, 3, scene.obstacle_key)
        except ValueError:
            pass                                           # drawn as wall squares instead
    j = out["pattern"]
    if j is not None and out["model"] is None and scene is not None:   # raw stiffness: the pattern's point only
        from hpcwedge.post.recovery import ConfigurationError, pattern_point
        try:
            out["point"] = pattern_point(scene, None, out["patterns"][j].contact, out["mu"])
        except (ConfigurationError, ValueError) as e:
            out["config_note"] = str(e).splitlines()[0]
    return out


def _scene(f, path: str):
    """The Scene parsed from the result's stored scene text (files relative to the recorded
    scene folder, else the result's), or None when it does not parse any more."""
    import tomllib

    from hpcwedge.scene.parse import parse_scene
    from hpcwedge.scene.values import SceneError
    if "scene_text" not in f:
        return None
    try:
        source, base, _ = stored_scene(f)
        base = base or ""
        if not os.path.isdir(base):
            base = os.path.dirname(os.path.abspath(path))
        return parse_scene(tomllib.loads(source), text=source, base_dir=base)
    except (SceneError, tomllib.TOMLDecodeError, ValueError):
        return None


# --------------------------------------------------------------------------- figure

def figure_3d(fig, d: dict) -> None:
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
        message(ax1, "sign patterns were not enumerated for this run\n(compute.enumerate = false)",
                 "wedged configuration")
    elif j is None:
        message(ax1, f"no feasible sign pattern at mu = {d['mu']:.6g}\n(no wedged configuration)",
                 "wedged configuration")
    elif body:
        _body_3d(ax1, d)
    else:
        head = f"sign pattern {j} of {len(pats)}, contact {pats[j].contact}"
        if d["point"] is None:
            message(ax1, f"no point of the pattern to draw\n({d['config_note']})", head)
        else:
            u, r = d["point"]
            bars_panel(ax1, u[:d["m"]], r[:d["m"]], head, "a feasible point of the pattern")
    marked = [i == j for i in range(len(pats or []))]
    mu_c_panel(fig.add_subplot(gs[0, 1]), d, pats, "sign pattern", marked, f"drawn pattern {j}",
                lambda p: f"(|C| = {len(p.contact)})")
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
    mdl, cfg, m = d["model"], d["config"], d["m"]
    pat, j = d["patterns"][d["pattern"]], d["pattern"]
    X, c = mdl.coords, mdl.contact_nodes
    n = mdl.normals / np.maximum(np.linalg.norm(mdl.normals, axis=1, keepdims=True), 1e-300)
    if cfg is not None:
        D, reac = cfg.displacement, cfg.reaction[c]
    else:                          # no point of the pattern without the body: the body as it is
        D = np.zeros_like(X)
        reac = np.zeros((m, 3))
    size = max(float(np.max(np.ptp(X, axis=0))), 1e-300) if len(X) > 1 else 1.0
    dmax = float(np.max(np.linalg.norm(D, axis=1)))
    scale = DISP_FRACTION * size / dmax if dmax > 0 else 0.0
    Y = X + scale * D
    ax.computed_zorder = False                # layers below, not depth-sorted: the nodes stay on top
    label = f"deformed (displacement x{scale:.3g})" if cfg is not None else "body (not rebuilt: undeformed)"
    _mesh_3d(ax, mdl.cells, X, Y, cfg.element_values if cfg is not None else {}, label)
    ext = [X, Y]
    drawn = _obstacles_3d(ax, d["obstacles"], X[c], n, size)
    if drawn is not None:
        ext.append(drawn)
    ext += _contact_nodes_3d(ax, Y[c], to_mask(pat.contact, m), reac, n, size)
    _box_3d(ax, np.vstack(ext), size)
    ax.figure.legend(*ax.get_legend_handles_labels(), loc="lower left", ncol=3, fontsize=8, frameon=False,
                     bbox_to_anchor=(0.01, 0.0))     # below the 3D box, which draws past its frame
    head = f"sign pattern {j} of {len(d['patterns'])}, contact C = {pat.contact}"
    if cfg is not None:
        title = f"{head}:\nthe whole body at a feasible point; arrows: reactions, pointing at the nodes"
    else:
        import textwrap
        title = "\n".join([f"{head}: body not rebuilt, drawn undeformed"]
                          + textwrap.wrap(d["config_note"] or "no configuration", 100))
    ax.set_title(title, fontsize=9)


def _mesh_3d(ax, cells: dict, X: np.ndarray, Y: np.ndarray, values: dict, label: str) -> None:
    """The edges of the undeformed body X (grey) and the deformed body Y: its boundary faces
    coloured by von Mises stress, its bars by axial force (else plain), with colour bars."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    from hpcwedge.post.recovery import AXIAL_FORCE, VON_MISES
    faces, owner, bars = _boundary(cells)
    edges = [X[b] for b in bars] + [X[np.append(f, f[0])] for f in faces]
    if edges:
        ax.add_collection3d(Line3DCollection(edges, colors="0.72", linewidths=0.6, zorder=1, label="undeformed"))
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
            ax.figure.colorbar(axial_colours(lc, values[AXIAL_FORCE]["line"]), ax=ax, shrink=0.5, pad=0.1,
                               label=AXIAL_LABEL)
        else:
            lc.set_color("tab:blue")
        ax.add_collection3d(lc)
    if not cells:                                       # nodes only (a matrix body without a mesh)
        ax.scatter(*X.T, s=4, color="0.7", depthshade=False, zorder=1, label="undeformed")
        ax.scatter(*Y.T, s=6, color="tab:blue", depthshade=False, zorder=2, label=label)


def _contact_nodes_3d(ax, P: np.ndarray, in_c: np.ndarray, reac: np.ndarray, n: np.ndarray,
                      size: float) -> list:
    """The contact nodes P (m, 3): the contact set C (in_c, filled) and the gap set G (open),
    the reactions reac as arrows pointing at them, their numbers on the body side (-n).
    Returns the arrows' tails (for the axis limits), if any were drawn."""
    ax.scatter(*P[in_c].T, s=40, color="tab:red", edgecolors="black", linewidths=0.6, depthshade=False,
               zorder=6, label=f"contact set C ({int(in_c.sum())}): u_n = 0")
    ax.scatter(*P[~in_c].T, s=40, facecolors="white", edgecolors="tab:blue", linewidths=1.5,
               depthshade=False, zorder=6, label=f"gap set G ({int((~in_c).sum())}): r_n = 0")
    tails = []
    rmax = float(np.max(np.linalg.norm(reac, axis=1))) if len(P) else 0.0
    if rmax > 0:
        R = 2 * ARROW_FRACTION * size / rmax * reac
        ax.quiver(*P.T, *R.T, pivot="tip", color="tab:red", linewidths=1.6, arrow_length_ratio=0.25,
                  zorder=5, label="reaction (obstacle on body)")
        tails.append(P - R)
    for i, p in enumerate(P):
        q = p - 0.06 * size * n[i]
        ax.text(*q, str(i), fontsize=7, color="0.2", ha="center", va="center", zorder=7)
    return tails


def _box_3d(ax, pts: np.ndarray, size: float) -> None:
    """Equal scales on the three axes around the points pts, in perspective from one view."""
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


def _obstacles_3d(ax, obstacles: list | None, P: np.ndarray, n: np.ndarray, size: float):
    """The obstacle near the contact points P (m, 3) with normals n: the scene's cones and
    planes as translucent surfaces, else a wall square in each node's tangent plane.
    Returns the drawn points (for the axis limits) or None."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    from hpcwedge.models.obstacle import Cone
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


def _counts_panel(ax, d: dict) -> None:
    """3D: the number of feasible sign patterns of every run against its mu (steps between
    runs), the drawn run highlighted and the global mu^c marked."""
    from matplotlib.ticker import MaxNLocator
    pts = sorted((mu, n) for mu, n in d["counts"] if n is not None)
    title = "feasible sign patterns against mu"
    if not pts:
        message(ax, "sign patterns were not enumerated\n(compute.enumerate = false)", title)
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
    span = [mus.min(), mus.max()] + ([d["mu_c"]] if d["mu_c"] is not None else [])
    lo, hi = min(span), max(span)          # the global mu^c in view also above every run's mu
    pad = 0.08 * (hi - lo) if hi > lo else 0.1 * max(hi, 1e-12)
    ax.set_xlim(lo - pad, hi + pad)
    ax.set_ylim(0, 1.15 * max(int(ns.max()), 1))
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("mu")
    ax.set_ylabel("feasible patterns")
    ax.legend(loc="upper left", fontsize=8, frameon=False)
    ax.set_title(title, fontsize=10)
