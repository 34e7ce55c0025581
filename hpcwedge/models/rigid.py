"""Rigid-body modes of a discretised body, from its geometry."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg as sla

#: relative tolerance of the rank decisions on the (column-normalised) geometric modes
RANK_RTOL = 1e-10


def rigid_motions(coords: np.ndarray, dim: int) -> np.ndarray:
    """All rigid-body motions of the nodes, not orthonormalised: (n_nodes*dim, 3 | 6).

    Columns: translations x, y (, z), then rotations about the centroid (2D: about z;
    3D: about x, y, z), each rotation scaled by 1/R with R the RMS distance of the
    nodes to the centroid, so that all columns have comparable norms.
    DOFs are node-major (dof = dim*node + component).
    """
    X = np.asarray(coords, dtype=float)
    n = X.shape[0]
    if X.ndim != 2 or X.shape[1] != dim or dim not in (2, 3):
        raise ValueError(f"rigid_modes: coords must be (n_nodes, {dim}) with dim 2 or 3, got {X.shape}")
    d = X - X.mean(axis=0)
    R = np.sqrt((d ** 2).sum(axis=1).mean()) if n else 0.0
    scale = 1.0 / R if R > 0 else 1.0
    if dim == 2:
        modes = np.zeros((n, 2, 3))
        modes[:, 0, 0] = 1.0
        modes[:, 1, 1] = 1.0
        modes[:, 0, 2] = -d[:, 1] * scale
        modes[:, 1, 2] = d[:, 0] * scale
    else:
        modes = np.zeros((n, 3, 6))
        for a in range(3):
            modes[:, a, a] = 1.0
            e = np.zeros(3)
            e[a] = 1.0
            modes[:, :, 3 + a] = np.cross(e, d) * scale
    return modes.reshape(n * dim, -1)


def _orthonormal_range(A: np.ndarray, rtol: float = RANK_RTOL) -> np.ndarray:
    """Orthonormal basis (QR, sign-fixed) of range(A), rank decided on singular values."""
    if A.shape[1] == 0 or A.shape[0] == 0:
        return np.zeros((A.shape[0], 0))
    s = np.linalg.svd(A, compute_uv=False)
    rank = int((s > rtol * s[0]).sum()) if s.size and s[0] > 0 else 0
    if rank == 0:
        return np.zeros((A.shape[0], 0))
    if rank < A.shape[1]:
        U = np.linalg.svd(A, full_matrices=False)[0]
        A = U[:, :rank]
    Q, Rf = sla.qr(A, mode="economic")
    sign = np.sign(np.diag(Rf))
    sign[sign == 0] = 1.0
    return Q * sign


def rigid_modes(coords: np.ndarray, dim: int, fixed_dofs: Sequence[int] | np.ndarray = ()) -> np.ndarray:
    """Rigid-body motions that the supports leave free: (n_nodes*dim, k), orthonormal columns.

    coords: (n_nodes, dim); fixed_dofs: global DOFs (node-major, dof = dim*node + c) held at 0.
    Returns the rigid motions (2D: 2 translations + rotation; 3D: 3 + 3, rotations about the
    centroid) that vanish on every fixed DOF, orthonormalised by QR (deterministic signs).
    k = 3 (2D) / 6 (3D) for a free body with non-degenerate geometry, k = 0 when the supports
    hold the body; degenerate geometry (e.g. collinear nodes in 3D) gives fewer columns.
    """
    M = rigid_motions(coords, dim)
    M = _orthonormal_range(M)
    fixed = np.asarray(fixed_dofs, dtype=np.int64).ravel()
    if fixed.size and M.shape[1]:
        A = M[fixed]
        _, s, Vt = np.linalg.svd(A, full_matrices=True)
        rank = int((s > RANK_RTOL).sum())  # M has orthonormal columns: s in [0, 1]
        Z = Vt[rank:].T
        M = _orthonormal_range(M @ Z) if Z.shape[1] else np.zeros((M.shape[0], 0))
    return M


def orthonormalise(N: np.ndarray, expect_rank: int | None = None, what: str = "rigid modes") -> np.ndarray:
    """QR-orthonormalise the columns of N (m, k) -> (m, k); ValueError if rank < expect_rank."""
    if N.shape[1] == 0:
        return np.zeros((N.shape[0], 0))
    Q = _orthonormal_range(N)
    k = N.shape[1] if expect_rank is None else expect_rank
    if Q.shape[1] != k:
        raise ValueError(f"{what}: rank {Q.shape[1]}, expected {k}")
    return Q
