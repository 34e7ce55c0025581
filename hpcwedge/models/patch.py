"""Contact patches: a rigid foot of half-width a under every contact node of a continuum body.

A point contact on a 2D (3D) continuum has a compliance that grows like log(1/h) (1/h) as the
mesh is refined, so the condensed stiffness never settles. With model.contact_patch = a > 0
each contact node carries a rigid foot: the boundary nodes of the body (reference
configuration) within Euclidean distance a of the contact node (its *patch*; the contact
node is its *master*) move with it rigidly,

    u_s = u_c + B_p q_p          for every slave node s of the patch p of contact node c,

where q_p are the foot's rotation DOFs (1 in 2D, up to 3 in 3D: as many as the patch's
lever arms x_s - x_c determine) and B_p an orthonormal basis of the rotations' motions of
the slaves relative to the master. The foot rotations are extra interior DOFs, condensed out
with the body's own. This is master-slave elimination, u = T u_red: T is the identity on every
DOF of a non-slave node, zero on the slave columns, and maps each slave DOF to its master and
its foot's rotations. A rigid motion of the body is T of a reduced vector (the same translation
and rotation at the masters, the body's rotation as the feet's), so free bodies keep their
rigid modes exactly. Reduced numbering: the full DOF ids (slave DOFs unused), then the foot
rotations at n_dofs, n_dofs + 1, ...

model.contact_patch_kind = "hat" is the other patch model: the contact node's DOFs stand for
the hat-weighted mean displacement u_c = sum_i w_i u_i of its patch (the contact node and
its slaves, w_i proportional to max(0, 1 - d_i/a), summing to 1), so the contact force acts
on the body as nodal forces w_i F, a triangular pressure of half-width a; the patch itself
stays elastic. Elimination u = T u_red again: T keeps every DOF but the contact node's own,
u_c(node) = (u_c - sum_s w_s u_s) / w_c. A rigid motion's u_c is the motion of the weighted
contact point sum_i w_i x_i (the contact node itself on a straight, evenly meshed side; inside
the corner at a corner), which is what the model's rigid modes hold at the contact DOFs. The
hat's weights vary continuously with the node positions, so the patch's effective width does
not jump as nodes enter it under refinement (the rigid foot's does, by up to one element).
"""
from __future__ import annotations

import math
import numbers

import numpy as np
import scipy.sparse as sp

from hpcwedge.models.record import Model, Tie
from hpcwedge.models.rigid import orthonormalise

#: a boundary node at distance d <= a (1 + DIST_RTOL) of a contact node is in its patch
#: (mirror-image nodes land on the same side of the cut despite rounding in their coordinates)
DIST_RTOL = 1e-9
#: rank of the lever matrix of a patch, relative to its largest singular value
LEVER_RTOL = 1e-10

#: faces of each cell type (meshio node order): edges in 2D, faces in 3D
FACES = {"triangle": ((0, 1), (1, 2), (2, 0)),
         "quad": ((0, 1), (1, 2), (2, 3), (3, 0)),
         "tetra": ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)),
         "hexahedron": ((0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7))}

KEY = "model.contact_patch"


def _at(x: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in x) + ")"


def check_patch_size(a, key: str = KEY) -> float:
    """a as a float >= 0 (finite); ValueError naming `key` otherwise."""
    if isinstance(a, bool) or not isinstance(a, numbers.Real) or not math.isfinite(float(a)) or a < 0:
        raise ValueError(f"{key}: must be a finite length >= 0 (half-width of the rigid foot), got {a!r}")
    return float(a)


def boundary_nodes(cells: dict, n_nodes: int) -> np.ndarray:
    """Sorted ids of the nodes on the body's boundary: nodes of the faces (edges in 2D) that
    belong to exactly one cell. cells: {cell type in FACES: (ne, nen) node ids}."""
    by_size: dict[int, list] = {}
    for cell, Q in cells.items():
        if cell not in FACES:
            raise ValueError(f"{KEY}: contact patches need continuum cells, not {cell!r}")
        Q = np.asarray(Q, dtype=np.int64)
        for f in FACES[cell]:
            by_size.setdefault(len(f), []).append(Q[:, list(f)])
    out = [np.zeros(0, dtype=np.int64)]
    for faces in by_size.values():
        F = np.sort(np.concatenate(faces), axis=1)
        uniq, counts = np.unique(F, axis=0, return_counts=True)
        out.append(uniq[counts == 1].ravel())
    return np.unique(np.concatenate(out)).astype(np.int64) if n_nodes else np.zeros(0, dtype=np.int64)


def patch_slaves(coords: np.ndarray, boundary: np.ndarray, contact_nodes: np.ndarray,
                 a: float) -> list[np.ndarray]:
    """Per contact node (contact order): the boundary nodes other than itself within a of it,
    ascending. ValueError naming model.contact_patch if two patches share a node or a contact
    node lies in another's patch."""
    from scipy.spatial import cKDTree
    X = np.asarray(coords, dtype=float)
    c = np.asarray(contact_nodes, dtype=np.int64)
    if a == 0 or boundary.size == 0:
        return [np.zeros(0, dtype=np.int64) for _ in c]
    tree = cKDTree(X[boundary])
    hits = tree.query_ball_point(X[c], a * (1 + DIST_RTOL))
    slaves = [np.setdiff1d(boundary[np.asarray(h, dtype=np.int64)], [ci]) for h, ci in zip(hits, c)]
    owner = np.full(len(X), -1, dtype=np.int64)
    owner[c] = np.arange(len(c))
    for i, s in enumerate(slaves):
        taken = owner[s]
        if np.any(taken >= 0):
            j = int(taken[taken >= 0][0])
            node = int(s[taken >= 0][0])
            d = float(np.linalg.norm(X[c[i]] - X[c[j]]))
            raise ValueError(f"{KEY}: the patches of contact nodes {min(i, j)} and {max(i, j)} (contact positions) overlap: "
                             f"the node at {_at(X[node])} is within a = {a:g} of both (contact nodes "
                             f"{d:.4g} apart): take a smaller a")
        owner[s] = i
    return slaves


def tie_map(coords: np.ndarray, contact_nodes: np.ndarray, slaves: list[np.ndarray]) -> Tie:
    """The master-slave map of the given patches (see the module doc): T (n_dofs, n_dofs + q)."""
    X = np.asarray(coords, dtype=float)
    n, d = X.shape
    nd = n * d
    slave_nodes = np.concatenate([np.zeros(0, dtype=np.int64)] + list(slaves))
    is_slave = np.zeros(nd, dtype=bool)
    is_slave[(d * slave_nodes[:, None] + np.arange(d)).ravel()] = True
    keep = np.flatnonzero(~is_slave)
    rows, cols, vals = [keep], [keep], [np.ones(keep.size)]
    q = 0
    for ci, s in zip(contact_nodes, slaves):
        if s.size == 0:
            continue
        D = X[s] - X[ci]                                  # (k, d) lever arms
        if d == 2:
            L = np.stack([-D[:, 1], D[:, 0]], axis=1).reshape(-1, 1)
        else:
            L = np.stack([np.cross(np.eye(3)[e], D) for e in range(3)], axis=2).reshape(-1, 3)
        U, sv, _ = np.linalg.svd(L, full_matrices=False)
        rank = int((sv > LEVER_RTOL * sv[0]).sum()) if sv.size and sv[0] > 0 else 0
        B = U[:, :rank]                                   # (k*d, rank) orthonormal
        sd = (d * s[:, None] + np.arange(d)).ravel()      # slave DOFs, node-major
        md = np.tile(d * ci + np.arange(d), s.size)       # their masters' DOFs
        rows += [sd, np.repeat(sd, rank)]
        cols += [md, np.tile(nd + q + np.arange(rank), sd.size)]
        vals += [np.ones(sd.size), B.ravel()]
        q += rank
    T = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(nd, nd + q))
    T.sum_duplicates()
    T.sort_indices()
    return Tie(T=T, slave_dofs=np.flatnonzero(is_slave), n_rotations=q)


def hat_weights(coords: np.ndarray, contact_nodes: np.ndarray, slaves: list[np.ndarray],
                a: float) -> list[np.ndarray]:
    """Per patch: weights of (contact node, *slaves) proportional to max(0, 1 - d/a), d the
    distance to the contact node, summing to 1."""
    X = np.asarray(coords, dtype=float)
    out = []
    for ci, s in zip(contact_nodes, slaves):
        h = np.maximum(0.0, 1.0 - np.linalg.norm(X[s] - X[ci], axis=1) / a)
        w = np.concatenate([[1.0], h])
        out.append(w / w.sum())
    return out


def hat_map(coords: np.ndarray, contact_nodes: np.ndarray, slaves: list[np.ndarray], a: float) -> Tie:
    """The hat-weighted patch map (module doc, kind "hat"). The contact DOFs become
    u_c = sum_i w_i u_i over the patch; the contact node's own displacement is
    (u_c - sum_s w_s u_s) / w_c, every other DOF is kept."""
    X = np.asarray(coords, dtype=float)
    n, d = X.shape
    nd = n * d
    W = hat_weights(X, contact_nodes, slaves, a)
    is_master = np.zeros(nd, dtype=bool)
    is_master[(d * np.asarray(contact_nodes, dtype=np.int64)[:, None] + np.arange(d)).ravel()] = True
    keep = np.flatnonzero(~is_master)
    rows, cols, vals = [keep], [keep], [np.ones(keep.size)]
    for ci, s, w in zip(contact_nodes, slaves, W):
        nodes = np.concatenate([[ci], s]).astype(np.int64)
        coef = np.concatenate([[1.0], -w[1:]]) / w[0]        # u_ci = coef @ (u_c, u_s...)
        for k in range(d):
            rows.append(np.full(nodes.size, d * ci + k))
            cols.append(d * nodes + k)
            vals.append(coef)
    T = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(nd, nd))
    T.sum_duplicates()
    T.sort_indices()
    return Tie(T=T, slave_dofs=np.zeros(0, dtype=np.int64), n_rotations=0)


#: patch kinds (scene key model.contact_patch_kind)
KINDS = ("rigid", "hat")


def with_contact_patch(model: Model, a, kind: str = "rigid") -> Model:
    """`model` with a contact patch of half-width a under every contact node (module doc).

    kind "rigid": a rigid foot (the patch's boundary nodes move with the contact node
    rigidly); "hat": the contact DOFs are the hat-weighted means of the patch's displacements
    (weights max(0, 1 - d/a), normalised), the contact force spread as a hat pressure; the
    rigid modes then take the contact DOFs at the weighted contact points.
    a = 0, or patches that hold no node besides their contact node: `model` itself, unchanged.
    ValueError("model.contact_patch: ...") if a < 0, the patches overlap, a patch holds a
    supported node, or the model has no continuum cells.
    """
    a = check_patch_size(a)
    if kind not in KINDS:
        raise ValueError(f"model.contact_patch_kind: one of {', '.join(KINDS)}, got {kind!r}")
    if a == 0:
        return model
    n, d = model.coords.shape
    slaves = patch_slaves(model.coords, boundary_nodes(model.cells, n), model.contact_nodes, a)
    if not any(s.size for s in slaves):
        return model
    fixed_nodes = np.unique(np.asarray(model.fixed_dofs, dtype=np.int64) // d)
    for i, s in enumerate(slaves):
        hit = np.intersect1d(s, fixed_nodes)
        if hit.size:
            raise ValueError(f"{KEY}: the node at {_at(model.coords[int(hit[0])])} in the patch of contact "
                             f"node {i} (contact position) is supported "
                             "(a patch node moves with its contact node): take a smaller a")
    if kind == "rigid":
        return model.replace(tie=tie_map(model.coords, model.contact_nodes, slaves))
    tie = hat_map(model.coords, model.contact_nodes, slaves, a)
    R = model.rigid_modes
    if R.shape[1]:
        R = R.copy()       # reduced DOFs: a contact DOF is the weighted mean over its patch
        for ci, s, w in zip(model.contact_nodes, slaves, hat_weights(model.coords, model.contact_nodes,
                                                                       slaves, a)):
            nodes = np.concatenate([[ci], s]).astype(np.int64)
            for k in range(d):
                R[d * ci + k] = w @ model.rigid_modes[d * nodes + k]
        R = orthonormalise(R, expect_rank=R.shape[1], what="contact patch rigid modes")
    return model.replace(tie=tie, rigid_modes=R)
