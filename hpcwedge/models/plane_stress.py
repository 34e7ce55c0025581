"""Plane-stress bilinear quadrilaterals (Q4, 2x2 Gauss), vectorised over elements."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..model import as_float_array

_G = 1.0 / np.sqrt(3.0)
#: reference corners (counter-clockwise) and Gauss points (weights 1)
_CORNERS = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
_GAUSS = _CORNERS * _G
#: dN[g, a, j] = dN_a / dxi_j at Gauss point g
_DN = 0.25 * np.stack([_CORNERS[None, :, 0] * (1 + _GAUSS[:, None, 1] * _CORNERS[None, :, 1]),
                       _CORNERS[None, :, 1] * (1 + _GAUSS[:, None, 0] * _CORNERS[None, :, 0])], axis=2)

#: elements per assembly chunk (bounds the temporaries to ~100 MB)
CHUNK = 65536


def _per_element(v, ne: int, key: str) -> np.ndarray:
    a = as_float_array(v, key)
    if a.ndim > 1 or (a.ndim == 1 and a.shape[0] != ne):
        raise ValueError(f"{key}: expected a scalar or one value per element ({ne}), got shape {a.shape}")
    return np.broadcast_to(a, (ne,))


def q4_element_stiffness(Xe: np.ndarray, E, nu, t, first: int = 0, key: str = "model.quads") -> np.ndarray:
    """Element stiffness matrices (ne, 8, 8), exactly symmetric, local DOFs (x0, y0, x1, y1, ...).

    Xe: (ne, 4, 2) corner coordinates, counter-clockwise; E, nu, t: (ne,) arrays.
    ValueError if det J <= 0 at a Gauss point (element index reported as first + local index).
    """
    J = Xe.transpose(0, 2, 1)[:, None] @ _DN[None]                      # (ne, 4, 2, 2) dx_i/dxi_j
    det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]      # (ne, 4)
    size = np.ptp(Xe, axis=1).max(axis=1) ** 2                           # element scale^2
    bad = np.flatnonzero(np.any(det <= 1e-14 * size[:, None], axis=1))
    if bad.size:
        e = int(bad[0])
        raise ValueError(f"{key}: element {first + e} has a non-positive Jacobian (det J = {det[e].min():.3g}); "
                         "corners must be counter-clockwise and the element convex")
    # dN_a/dx = (J11 dN_a/dxi - J10 dN_a/deta) / det,  dN_a/dy = (-J01 dN_a/dxi + J00 dN_a/deta) / det
    d0, d1 = _DN[None, :, :, 0], _DN[None, :, :, 1]                     # (1, 4g, 4a)
    inv = 1.0 / det[..., None]
    Nx = (J[..., 1, 1, None] * d0 - J[..., 1, 0, None] * d1) * inv      # (ne, 4g, 4a)
    Ny = (J[..., 0, 0, None] * d1 - J[..., 0, 1, None] * d0) * inv
    w = det * t[:, None]                                                 # Gauss weights are 1
    NxT, NyT = (Nx * w[..., None]).transpose(0, 2, 1), (Ny * w[..., None]).transpose(0, 2, 1)
    Pxx, Pyy, Pxy = NxT @ Nx, NyT @ Ny, NxT @ Ny                         # (ne, 4, 4): sum_g w N?_a N?_b
    Pyx = Pxy.transpose(0, 2, 1)
    c = (E / (1.0 - nu ** 2))[:, None, None]
    g = ((1.0 - nu) / 2.0)[:, None, None]
    nu_ = nu[:, None, None]
    ne = Xe.shape[0]
    ke = np.empty((ne, 4, 2, 4, 2))
    ke[:, :, 0, :, 0] = c * (Pxx + g * Pyy)
    ke[:, :, 1, :, 1] = c * (Pyy + g * Pxx)
    ke[:, :, 0, :, 1] = c * (nu_ * Pxy + g * Pyx)
    ke[:, :, 1, :, 0] = c * (nu_ * Pyx + g * Pxy)
    ke = ke.reshape(ne, 8, 8)
    return 0.5 * (ke + ke.transpose(0, 2, 1))


def _node_pattern(conn: np.ndarray, n_nodes: int):
    """Node-level CSR pattern (indptr, indices) of the element graph and sorted keys i*n + j."""
    nen = conn.shape[1]
    idx = np.int32 if n_nodes < 2 ** 31 - 1 else np.int64
    I = np.repeat(conn.astype(idx), nen, axis=1).ravel()
    Jc = np.tile(conn.astype(idx), (1, nen)).ravel()
    P = sp.coo_matrix((np.ones(I.size, dtype=np.int8), (I, Jc)), shape=(n_nodes, n_nodes)).tocsr()
    del I, Jc
    P.sum_duplicates()
    P.sort_indices()
    rows = np.repeat(np.arange(n_nodes, dtype=np.int64), np.diff(P.indptr))
    keys = rows * n_nodes + P.indices
    return P.indptr, P.indices, keys


def assemble_blocks(conn: np.ndarray, n_nodes: int, dim: int, element_matrices, chunk: int = CHUNK) -> sp.csr_matrix:
    """Assemble (n_nodes*dim)^2 CSR from element matrices without a global COO array.

    conn: (ne, nen) node ids; element_matrices(lo, hi) -> (hi-lo, nen*dim, nen*dim) exactly
    symmetric matrices with node-major local DOFs. The node-level pattern is built once; each
    chunk's blocks are added into it with bincount, in element order, so the result is exactly
    symmetric. Memory ~ nnz of K plus one chunk of temporaries.
    """
    ne, nen = conn.shape
    indptr, indices, keys = _node_pattern(conn, n_nodes)
    nnzb = keys.size
    data = np.zeros((dim, dim, nnzb))
    for lo in range(0, ne, chunk):
        hi = min(ne, lo + chunk)
        c = conn[lo:hi].astype(np.int64)
        pos = np.searchsorted(keys, (c[:, :, None] * n_nodes + c[:, None, :]).ravel())
        ke = element_matrices(lo, hi).reshape(hi - lo, nen, dim, nen, dim)
        for p in range(dim):
            for q in range(dim):
                data[p, q] += np.bincount(pos, weights=ke[:, :, p, :, q].ravel(), minlength=nnzb)
    blocks = np.ascontiguousarray(data.transpose(2, 0, 1))
    del data
    K = sp.bsr_matrix((blocks, indices, indptr), shape=(n_nodes * dim, n_nodes * dim)).tocsr()
    K.sort_indices()
    return K


def q4_stiffness(coords: np.ndarray, quads: np.ndarray, E=1.0, nu=0.3, t=1.0,
                 key: str = "model.quads") -> sp.csr_matrix:
    """Plane-stress Q4 stiffness: (n_nodes*2, n_nodes*2) CSR, exactly symmetric, node-major DOFs.

    coords: (n_nodes, 2); quads: (ne, 4) counter-clockwise corners; E (Young's modulus),
    nu (Poisson ratio, -1 < nu < 0.5), t (thickness): scalars or (ne,) arrays. 2x2 Gauss
    quadrature, vectorised over elements (chunked, so 10^6 elements stay within memory).
    ValueError("<key>: ...") on bad input or a non-positive Jacobian.
    """
    X = as_float_array(coords, "model.nodes", ndim=2)
    if X.shape[1] != 2:
        raise ValueError(f"model.nodes: plane stress needs (n_nodes, 2) coordinates, got {X.shape}")
    Q = np.asarray(quads)
    if Q.ndim != 2 or Q.shape[1] != 4:
        raise ValueError(f"{key}: expected (n_elements, 4), got shape {Q.shape}")
    if not np.issubdtype(Q.dtype, np.integer):
        Qf = as_float_array(Q, key)
        if np.any(Qf != np.round(Qf)):
            raise ValueError(f"{key}: non-integer node id")
        Q = Qf.astype(np.int64)
    n, ne = X.shape[0], Q.shape[0]
    if ne and (Q.min() < 0 or Q.max() >= n):
        e = int(np.flatnonzero((Q.min(axis=1) < 0) | (Q.max(axis=1) >= n))[0])
        raise ValueError(f"{key}: element {e} refers to node {Q[e].tolist()}, only {n} nodes (0-based)")
    Ev, nuv, tv = _per_element(E, ne, "material.E"), _per_element(nu, ne, "material.nu"), _per_element(t, ne, "material.thickness")
    if np.any(Ev <= 0):
        raise ValueError("material.E: must be > 0")
    if np.any((nuv <= -1) | (nuv >= 0.5)):
        raise ValueError("material.nu: must lie in (-1, 0.5)")
    if np.any(tv <= 0):
        raise ValueError("material.thickness: must be > 0")

    def element_matrices(lo: int, hi: int) -> np.ndarray:
        return q4_element_stiffness(X[Q[lo:hi]], Ev[lo:hi], nuv[lo:hi], tv[lo:hi], first=lo, key=key)

    return assemble_blocks(Q, n, 2, element_matrices)
