"""Continuum models from mesh files (SPEC §3, kind = "mesh"), read with meshio.

Node ids are 0-based rows of the point array as meshio reads the file: for Gmsh, the order
of the $Nodes section (node tag − 1 when the tags are 1..n in file order, as Gmsh writes
them). Named groups are Gmsh physical groups (.msh 2 and 4) and meshio's point and cell
sets (other formats); a group's nodes are the nodes of its cells, in ascending id.

The body is every cell of the scene's dimension (2D: triangle, quad, plane stress with a
thickness; 3D: tetra, hexahedron); lower-dimensional cells (vertex, line, boundary faces)
only define groups. Nodes that belong to no body cell (e.g. geometry points saved by a
mesher) are dropped, so the Model's node numbering may differ from the file's; error
messages always give file ids.
"""
from __future__ import annotations

import contextlib
import io
import os
from dataclasses import dataclass

import numpy as np

from hpcwedge.models.continuum import ContinuumAssembly
from hpcwedge.models.elements import CELL_TYPES
from hpcwedge.models.obstacle import Cone, Plane, obstacle_frames, orient_into_body
from hpcwedge.models.patch import check_patch_size, with_contact_patch
from hpcwedge.models.record import (
    Model,
    as_index_array,
    check_contact_free,
    check_contact_nodes,
    check_supports,
    contact_frames,
)
from hpcwedge.models.rigid import rigid_modes

#: default obstacle tolerance: contact nodes within DEFAULT_TOLERANCE x the median element
#: extent of the nearest obstacle surface
DEFAULT_TOLERANCE = 1e-4


@dataclass(frozen=True)
class MeshData:
    """A mesh as read from a file (file node ids).

    name:   the file name used in messages.
    points: (n, dim) node coordinates.
    cells:  {cell type: (ne, nen) int64 node ids}, the body cells (dimension dim), file order,
            duplicates (same node set) removed.
    groups: {name: (k,) sorted unique node ids}.
    """

    name: str
    points: np.ndarray
    cells: dict
    groups: dict


def read_mesh(path: str, dim: int, name: str | None = None, key: str = "model.file") -> MeshData:
    """Read a mesh file with meshio (format from the extension: Gmsh .msh 2 and 4, .vtu, ...).

    ValueError naming `key` when the file is missing or unreadable, has cells of a higher
    dimension than `dim` or of an unsupported type of dimension `dim`, has no body cells, or
    (2D) is not planar (z must be constant).
    """
    import meshio
    name = name or path
    if not os.path.isfile(path):
        raise ValueError(f"{key}: {name} not found")
    said = io.StringIO()      # meshio prints its parse errors and exits when no reader succeeds
    try:
        with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
            mesh = meshio.read(path)
    except SystemExit:
        formats = meshio.extension_to_filetypes.get(os.path.splitext(path)[1].lower(), ["a known format"])
        raise ValueError(f"{key}: cannot read {name} (not a valid {' or '.join(formats)} file)") from None
    except Exception as e:  # meshio raises many types on malformed or unknown files
        detail = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise ValueError(f"{key}: cannot read {name} ({detail})") from None
    P = np.asarray(mesh.points, dtype=float)
    if P.ndim != 2 or P.shape[1] < dim:
        raise ValueError(f"{key}: {name} has {P.shape[-1]}-D points, the scene has dim = {dim}")
    if not np.all(np.isfinite(P)):
        raise ValueError(f"{key}: {name} has NaN or infinite coordinates")
    if P.shape[1] > dim:
        extra = P[:, dim:]
        span = float(np.ptp(P[:, :dim], axis=0).max()) if len(P) else 0.0
        if len(P) and float(np.ptp(extra, axis=0).max()) > 1e-12 * max(span, 1e-300):
            raise ValueError(f"{key}: {name} is not planar (z varies) but the scene has dim = {dim}")
        P = P[:, :dim]
    body: dict[str, list] = {}
    for blk in mesh.cells:
        if blk.dim > dim:
            raise ValueError(f"{key}: {name} has {blk.dim}D cells ({blk.type}) but the scene has dim = {dim}")
        if blk.dim == dim:
            if blk.type not in CELL_TYPES[dim]:
                raise ValueError(f"{key}: unsupported cell type {blk.type!r} in {name} "
                                 f"(supported in {dim}D: {', '.join(CELL_TYPES[dim])})")
            body.setdefault(blk.type, []).append(np.asarray(blk.data, dtype=np.int64))
    if not body:
        raise ValueError(f"{key}: {name} has no {dim}D cells ({', '.join(CELL_TYPES[dim])}); with Gmsh, "
                         "add a physical group for the body (only physical groups are saved once one exists)")
    cells = {}
    for t, parts in body.items():
        conn = np.concatenate(parts)
        _, first = np.unique(np.sort(conn, axis=1), axis=0, return_index=True)
        cells[t] = conn[np.sort(first)]
    return MeshData(name=name, points=P, cells=cells, groups=_groups(mesh))


def _groups(mesh) -> dict:
    """{name: sorted unique node ids} from point sets, cell sets and Gmsh physical groups."""
    acc: dict[str, list] = {}
    for gname, ids in (mesh.point_sets or {}).items():
        acc.setdefault(gname, []).append(np.asarray(ids, dtype=np.int64).ravel())
    for gname, per_block in (mesh.cell_sets or {}).items():
        if gname.startswith("gmsh:"):
            continue
        for blk, idx in zip(mesh.cells, per_block):
            if idx is not None and len(idx):
                acc.setdefault(gname, []).append(np.asarray(blk.data)[np.asarray(idx, dtype=np.int64)].ravel())
    phys = mesh.cell_data.get("gmsh:physical")
    if phys is not None:
        for gname, fd in (mesh.field_data or {}).items():
            fd = np.asarray(fd).ravel()
            if fd.size != 2:
                continue
            tag, gdim = int(fd[0]), int(fd[1])
            acc.setdefault(gname, [])
            for blk, p in zip(mesh.cells, phys):
                sel = np.asarray(p) == tag
                if blk.dim == gdim and sel.any():
                    acc[gname].append(np.asarray(blk.data)[sel].ravel())
    return {g: np.unique(np.concatenate(v)).astype(np.int64) if v else np.zeros(0, dtype=np.int64)
            for g, v in acc.items()}


def group_nodes(mesh: MeshData, names: str | list[str], key: str) -> np.ndarray:
    """Node ids of the named groups, group by group in the given order, each ascending.
    ValueError naming `key` for an unknown or empty group, or a node in two of the groups."""
    names = [names] if isinstance(names, str) else list(names)
    parts = []
    for g in names:
        if g not in mesh.groups:
            known = ", ".join(repr(k) for k in sorted(mesh.groups)) or "none"
            raise ValueError(f"{key}: unknown group {g!r} in {mesh.name} (groups: {known})")
        if names.count(g) > 1:
            raise ValueError(f"{key}: group {g!r} listed twice")
        if mesh.groups[g].size == 0:
            raise ValueError(f"{key}: group {g!r} in {mesh.name} has no nodes")
        parts.append(mesh.groups[g])
    ids = np.concatenate(parts)
    uniq, counts = np.unique(ids, return_counts=True)
    if np.any(counts > 1):
        node = int(uniq[counts > 1][0])
        g1, g2 = [g for g, p in zip(names, parts) if node in p][:2]
        raise ValueError(f"{key}: node {node} is in both group {g1!r} and group {g2!r}")
    return ids


def element_size(points: np.ndarray, cells: dict) -> float:
    """Median over the body cells of the cell's largest coordinate extent."""
    ext = np.concatenate([np.ptp(points[c], axis=1).max(axis=1) for c in cells.values()])
    return float(np.median(ext))


def inward_vectors(points: np.ndarray, cells: dict) -> np.ndarray:
    """(n, dim): for each node, the sum over its cells of (cell centroid − node): points into
    the body at a boundary node (zero for a node of no cell)."""
    n, dim = points.shape
    acc = np.zeros((n, dim))
    for conn in cells.values():
        Xe = points[conn]
        v = (Xe.mean(axis=1)[:, None, :] - Xe).reshape(-1, dim)
        for k in range(dim):
            acc[:, k] += np.bincount(conn.ravel(), weights=v[:, k], minlength=n)
    return acc


#: each cell type's facets (its edges in 2D, its faces in 3D) by local node index
FACETS = {"triangle": ((0, 1), (1, 2), (2, 0)), "quad": ((0, 1), (1, 2), (2, 3), (3, 0)),
          "tetra": ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)),
          "hexahedron": ((0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7))}


def boundary_nodes(n: int, cells: dict) -> np.ndarray:
    """(n,) bool: the nodes on a facet that only one cell has (the body's boundary)."""
    by_size: dict = {}
    for t, conn in cells.items():
        for f in FACETS[t]:
            by_size.setdefault(len(f), []).append(np.sort(conn[:, f], axis=1))
    out = np.zeros(n, dtype=bool)
    for facets in by_size.values():
        uniq, count = np.unique(np.vstack(facets), axis=0, return_counts=True)
        out[uniq[count == 1].ravel()] = True
    return out


def _require_into_body(nrm: np.ndarray, inward: np.ndarray, c: np.ndarray) -> None:
    """ValueError naming contact.normals when a given normal points out of the body (against
    `inward`, rows of inward_vectors at the contact nodes c): normals point into the body."""
    out = np.flatnonzero((nrm * inward).sum(axis=1) < -1e-6 * np.linalg.norm(inward, axis=1))
    if out.size:
        i = int(out[0])
        raise ValueError(f"contact.normals[{i}]: points out of the body at contact node {int(c[i])} "
                         "(normals point from the obstacle into the body)")


def _require_in_body(ids: np.ndarray, used: np.ndarray, key: str) -> None:
    bad = ids[~used[ids]]
    if bad.size:
        raise ValueError(f"{key}: node {int(bad[0])} belongs to no element of the body")


def mesh_model(mesh: MeshData, *, E=1.0, nu=0.3, thickness=1.0,
               contact_nodes=None, contact_group: str | list[str] | None = None,
               normals=None, tangents=None,
               obstacles: list[Plane | Cone] | None = None, obstacle_key: str = "obstacle",
               tolerance: float = DEFAULT_TOLERANCE,
               supports=None, support_group: str | list[str] | None = None, support_dofs=None,
               contact_patch=0.0, contact_patch_kind: str = "rigid") -> Model:
    """The Model of a meshed body (SPEC §3, kind = "mesh").

    Contact nodes: `contact_nodes` (m,) file ids, or `contact_group` (name or names).
    Normals: `normals` (m, dim) given (into the body; optional `tangents`, see
    model.contact_frames), or those of the nearest of `obstacles` (hpcwedge.models.obstacle),
    which must lie within tolerance x element_size of every contact node, oriented into the
    body (towards the node's cells); in 3D t1 is then circumferential on a cone.
    Supports (optional, else a free body): `supports` [[node, dof], ...] and/or every DOF in
    `support_dofs` (default all) of the nodes of `support_group`.
    Material: E, nu, thickness (2D plane stress; ignored in 3D), errors named model.E, ...
    contact_patch = a > 0: a rigid foot of half-width a under every contact node (the boundary
    nodes within a of it move with it rigidly: models/patch.py); 0 = point contacts;
    contact_patch_kind = "hat": hat-weighted means over the patches instead.
    Every error is ValueError("<key>: <reason>") naming the scene key, with file node ids.
    K is assembled on first access (model.assembly: condense_distributed assembles rows only).
    """
    a = check_patch_size(contact_patch)
    X, dim, n = mesh.points, mesh.points.shape[1], mesh.points.shape[0]
    used = np.zeros(n, dtype=bool)
    for conn in mesh.cells.values():
        used[conn.ravel()] = True
    # contact nodes (file ids)
    if (contact_nodes is None) == (contact_group is None):
        raise ValueError("contact.nodes / contact.group: give exactly one")
    if contact_group is not None:
        c = group_nodes(mesh, contact_group, "contact.group")
        ckey = "contact.group"
    else:
        c = check_contact_nodes(contact_nodes, n, "contact.nodes")
        ckey = "contact.nodes"
    _require_in_body(c, used, ckey)
    inside = c[~boundary_nodes(n, mesh.cells)[c]]
    if inside.size:
        raise ValueError(f"{ckey}: node {int(inside[0])} lies inside the body (on no boundary facet of its "
                         "elements): a contact node is on the body's surface")
    # supports (file ids -> fixed file DOFs)
    fixed = check_supports(supports, n, dim)
    if support_group is not None:
        g = group_nodes(mesh, support_group, "model.support_group")
        comps = (np.arange(dim) if support_dofs is None
                 else np.unique(as_index_array(support_dofs, "model.support_dofs", dim, "dof", ndim=1)))
        fixed = np.union1d(fixed, (dim * g[:, None] + comps).ravel())
    elif support_dofs is not None:
        raise ValueError("model.support_dofs: only with model.support_group")
    skey = "model.supports" if support_group is None else "model.support_group"
    _require_in_body(np.unique(fixed // dim), used, skey)
    check_contact_free(fixed, c, dim, skey)
    # frames
    m = len(c)
    if (normals is None) == (obstacles is None):
        raise ValueError("contact.normals / obstacle: give exactly one (normals per contact node, "
                         "or obstacle surfaces)")
    if normals is not None:
        nrm, tan = contact_frames(normals, dim, m, tangents)
        _require_into_body(nrm, inward_vectors(X, mesh.cells)[c], c)
    else:
        if tangents is not None:
            raise ValueError("contact.tangents: only with contact.normals")
        h = element_size(X, mesh.cells)
        nrm0, t1 = obstacle_frames(X[c], obstacles, tolerance * h, c, obstacle_key,
                                   tol_note=f" (contact.tolerance {tolerance:g} x median element size {h:.3g})")
        nrm0 = orient_into_body(nrm0, inward_vectors(X, mesh.cells)[c], c, obstacle_key)
        nrm, tan = contact_frames(nrm0, dim, m, t1)
    # compact numbering: body nodes only
    new = np.cumsum(used) - 1
    Xb = X[used]
    cells = {t: new[conn] for t, conn in mesh.cells.items()}
    fixed_b = np.sort(dim * new[fixed // dim] + fixed % dim)
    t = thickness if dim == 2 else 1.0
    asm = ContinuumAssembly(Xb, cells, E, nu, t, key="model.file", material_key="model")
    mdl = Model(dim=dim, coords=Xb, K=None, assembly=asm, fixed_dofs=fixed_b, contact_nodes=new[c], normals=nrm,
                tangents=tan, rigid_modes=rigid_modes(Xb, dim, fixed_b), cells=cells, material=asm.material)
    return with_contact_patch(mdl, a, contact_patch_kind)
