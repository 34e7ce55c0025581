"""Pin-jointed bar (truss) models in 2D and 3D."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from hpcwedge.models.record import (
    Model,
    as_float_array,
    check_contact_free,
    check_contact_nodes,
    check_supports,
    contact_frames,
)
from hpcwedge.models.rigid import rigid_modes


def _bar_geometry(coords: np.ndarray, bars: np.ndarray, key: str = "model.bars"):
    dx = coords[bars[:, 1]] - coords[bars[:, 0]]
    L = np.linalg.norm(dx, axis=1)
    size = float(np.ptp(coords, axis=0).max()) if len(coords) else 0.0
    zero = np.flatnonzero(L <= 1e-12 * max(size, 1e-300))
    if zero.size:
        b = int(zero[0])
        raise ValueError(f"{key}: bar {b} ({int(bars[b, 0])}-{int(bars[b, 1])}) has zero length")
    return dx / L[:, None], L


def truss_stiffness(coords: np.ndarray, bars: np.ndarray, EA: float | np.ndarray) -> sp.csr_matrix:
    """Global stiffness of a 2D/3D truss: (n_nodes*dim, n_nodes*dim) CSR, exactly symmetric.

    coords: (n_nodes, dim); bars: (n_bars, 2) 0-based node pairs; EA: scalar or (n_bars,).
    Node-major DOFs (dof = dim*node + component). Bar stiffness EA/L * [[ee^T, -ee^T], [-ee^T, ee^T]]
    with e the unit bar direction. Vectorised over bars, assembled through COO.
    """
    X = np.asarray(coords, dtype=float)
    B = np.asarray(bars, dtype=np.int64).reshape(-1, 2)
    n, d = X.shape
    e, L = _bar_geometry(X, B)
    k = np.broadcast_to(np.asarray(EA, dtype=float), L.shape) / L
    kee = k[:, None, None] * e[:, :, None] * e[:, None, :]            # (nb, d, d)
    ke = np.concatenate([np.concatenate([kee, -kee], axis=2),
                         np.concatenate([-kee, kee], axis=2)], axis=1)  # (nb, 2d, 2d)
    dofs = (d * B[:, :, None] + np.arange(d)).reshape(len(B), 2 * d)
    rows = np.broadcast_to(dofs[:, :, None], ke.shape).ravel()
    cols = np.broadcast_to(dofs[:, None, :], ke.shape).ravel()
    K = sp.coo_matrix((ke.ravel(), (rows, cols)), shape=(n * d, n * d)).tocsr()
    K = ((K + K.T) * 0.5).tocsr()  # exact symmetry despite the summation order of duplicates
    K.sum_duplicates()
    return K


def bar_forces(coords: np.ndarray, bars: np.ndarray, EA, u: np.ndarray) -> np.ndarray:
    """Axial force of every bar (n_bars,), tension positive: EA/L * e . (u_b - u_a).

    coords, u: (n_nodes, dim) positions and displacements; bars: (n_bars, 2); EA: scalar or
    (n_bars,). Units of EA (force).
    """
    X = np.asarray(coords, dtype=float)
    B = np.asarray(bars, dtype=np.int64).reshape(-1, 2)
    e, L = _bar_geometry(X, B)
    du = u[B[:, 1]] - u[B[:, 0]]
    return np.broadcast_to(np.asarray(EA, dtype=float), L.shape) / L * (e * du).sum(axis=1)


def truss_model(nodes, bars, EA, supports, contact_nodes, normals, tangents=None) -> Model:
    """Validated truss Model (SPEC §3, kind = "truss").

    nodes: (n_nodes, dim), dim 2 or 3; bars: (n_bars, 2) 0-based; EA: scalar or (n_bars,) > 0;
    supports: [[node, dof], ...] or None; contact_nodes: (m,) unique node ids;
    normals: (m, dim) into the body (normalised here); tangents: optional, see
    hpcwedge.models.record.contact_frames. Errors: ValueError("<key>: <reason>") with key among
    model.nodes, model.bars, model.EA, model.supports, contact.nodes, contact.normals, contact.tangents.
    """
    X = as_float_array(nodes, "model.nodes", ndim=2)
    if X.shape[1] not in (2, 3):
        raise ValueError(f"model.nodes: expected (n_nodes, 2) or (n_nodes, 3), got {X.shape}")
    n, dim = X.shape
    if n < 2:
        raise ValueError(f"model.nodes: need at least 2 nodes, got {n}")
    Bf = as_float_array(bars, "model.bars")
    if Bf.ndim != 2 or Bf.shape[1] != 2 or Bf.shape[0] == 0:
        raise ValueError(f"model.bars: expected (n_bars, 2) node pairs, got shape {Bf.shape}")
    bad = np.flatnonzero(np.any(Bf != np.round(Bf), axis=1))
    if bad.size:
        raise ValueError(f"model.bars: bar {int(bad[0])} has a non-integer node id")
    bad = np.flatnonzero((Bf.min(axis=1) < 0) | (Bf.max(axis=1) >= n))    # before the cast: 1e300 too
    if bad.size:
        b = int(bad[0])
        v = int(Bf[b].min()) if Bf[b].min() < 0 else int(Bf[b].max())
        raise ValueError(f"model.bars: bar {b} refers to node {v}, only {n} nodes (0-based)")
    B = Bf.astype(np.int64)
    ea = as_float_array(EA, "model.EA")
    if ea.ndim > 1 or (ea.ndim == 1 and ea.shape[0] != B.shape[0]):
        raise ValueError(f"model.EA: expected a scalar or one value per bar ({B.shape[0]}), got shape {ea.shape}")
    if np.any(ea <= 0):
        raise ValueError("model.EA: must be > 0" + (f" (bar {int(np.flatnonzero(ea <= 0)[0])})" if ea.ndim else ""))
    _bar_geometry(X, B)
    loose = np.setdiff1d(np.arange(n), B.ravel())
    if loose.size:
        raise ValueError(f"model.nodes: node {int(loose[0])} is in no bar (connect it or remove it)")
    fixed = check_supports(supports, n, dim)
    c = check_contact_nodes(contact_nodes, n)
    check_contact_free(fixed, c, dim)
    nrm, tan = contact_frames(normals, dim, len(c), tangents)
    K = truss_stiffness(X, B, ea)
    return Model(dim=dim, coords=X, K=K, fixed_dofs=fixed, contact_nodes=c, normals=nrm, tangents=tan,
                 rigid_modes=rigid_modes(X, dim, fixed), cells={"line": B},
                 material={"EA": np.array(np.broadcast_to(ea, (len(B),)), dtype=float)})
