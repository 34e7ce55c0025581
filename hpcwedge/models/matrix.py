"""Bodies assembled by another FE code (kind = "matrix"): a sparse stiffness read from a file
(MatrixMarket .mtx, scipy.sparse .npz, PETSc binary .petsc), node coordinates, supports and
contact frames. DOFs are node-major: node i owns DOFs dim*i .. dim*i + dim - 1.

A PETSc binary file is not read here: the Model carries a StiffnessFile (K assembled on
first access by the loader it is given, PETSc's MatLoad in contact/condense.py) so that a
distributed condensation reads each rank's rows of it in parallel, never the whole matrix.
"""
from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from typing import Callable

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

#: the stiffness formats, by file extension
FORMATS = (".mtx", ".npz", ".petsc")
#: max |K - K^T| <= SYM_RTOL max |K|: symmetric (the stored K is then made exactly symmetric)
SYM_RTOL = 1e-10
#: max |K R| <= RIGID_RTOL max |K| (R orthonormal rigid modes of the nodes and supports)
RIGID_RTOL = 1e-8
#: the first int32 of a PETSc binary matrix (MAT_FILE_CLASSID)
PETSC_MAT_CLASSID = 1211216


@dataclass
class StiffnessFile:
    """A stiffness in a PETSc binary file, loaded when needed (models.record.StiffnessRows).

    path: the file; n: its size (from the header); exponent: the loaded values are multiplied
    by 2**-exponent (build.stiffness_exponent); load(path) -> the whole matrix (CSR)."""

    path: str
    n: int
    exponent: int
    load: Callable[[str], sp.csr_matrix]
    full_assemblies: int = 0
    row_assemblies: int = 0

    def full(self) -> sp.csr_matrix:
        """The whole K, checked (check_stiffness), exactly symmetric, scaled."""
        self.full_assemblies += 1
        K = check_stiffness(self.load(self.path), self.n, "model.K")
        return _scaled(K, self.exponent)

    def rows(self, dofs: np.ndarray) -> sp.csr_matrix:
        """K[dofs], from the whole K (the distributed route loads rows itself: condense.py)."""
        self.row_assemblies += 1
        return self.full()[np.asarray(dofs, dtype=np.int64)]


def _scaled(K: sp.csr_matrix, e: int) -> sp.csr_matrix:
    """K times 2**-e (exact)."""
    if e:
        K = K.copy()
        K.data = np.ldexp(K.data, -e)
    return K


def petsc_header(path: str, name: str, key: str = "model.K") -> tuple[int, int, int]:
    """(rows, columns, stored entries) from a PETSc binary matrix file's header (big-endian
    int32: class id, M, N, nz); ValueError naming `key` if it is not one."""
    try:
        head = np.fromfile(path, dtype=">i4", count=4)
    except OSError as e:
        raise ValueError(f"{key}: cannot read {name} ({e.strerror or type(e).__name__})") from None
    if head.size < 4 or head[0] != PETSC_MAT_CLASSID:
        raise ValueError(f"{key}: {name} is not a PETSc binary matrix (no MAT_FILE_CLASSID header)")
    return int(head[1]), int(head[2]), int(head[3])


@functools.lru_cache(maxsize=8)
def _largest(path: str, stamp: tuple) -> float:
    if not path.lower().endswith(".petsc"):
        K = read_stiffness(path, path)
        return float(np.abs(K.data).max()) if K.nnz else 0.0
    M, _, nz = petsc_header(path, path)
    values = np.memmap(path, dtype=">f8", mode="r", offset=16 + 4 * (M + nz), shape=(nz,))
    step = 1 << 22
    return max((float(np.abs(values[i:i + step]).max()) for i in range(0, nz, step)), default=0.0)


def largest_entry(path: str) -> float:
    """max |K_ij| of a stiffness file (a PETSc binary file streamed, no copy of the matrix),
    cached per file version; NaN if a value is NaN. OSError or ValueError if unreadable."""
    st = os.stat(path)
    return _largest(path, (st.st_mtime_ns, st.st_size))


def read_stiffness(path: str, name: str, key: str = "model.K") -> sp.csr_matrix:
    """The matrix of a .mtx (symmetric or general storage) or .npz (scipy.sparse.save_npz)
    file as CSR, unchecked; ValueError naming `key` if missing, unreadable or of another type."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in (".mtx", ".npz"):
        raise ValueError(f"{key}: {name}: unsupported file type (use {', '.join(FORMATS)})")
    if not os.path.isfile(path):
        raise ValueError(f"{key}: {name} not found")
    try:
        if ext == ".mtx":
            import scipy.io
            K = scipy.io.mmread(path)
        else:
            K = sp.load_npz(path)
    except Exception as e:  # noqa: BLE001  (scipy raises many types on malformed files)
        why = (str(e).strip().splitlines() or [type(e).__name__])[0]
        raise ValueError(f"{key}: cannot read {name} ({why})") from None
    if not sp.issparse(K):
        K = sp.csr_matrix(np.asarray(K))
    if np.iscomplexobj(K.data) or K.dtype.kind not in "fiu":
        raise ValueError(f"{key}: {name} is not a real matrix (dtype {K.dtype})")
    return sp.csr_matrix(K, dtype=float)


def check_stiffness(K: sp.csr_matrix, n: int, key: str = "model.K") -> sp.csr_matrix:
    """K (n, n) with finite values, symmetric to SYM_RTOL: returned as 0.5 (K + K^T) (exactly
    symmetric), duplicates summed, indices sorted; ValueError naming `key` otherwise."""
    K = sp.csr_matrix(K, dtype=float)
    K.sum_duplicates()
    if K.shape[0] != K.shape[1]:
        raise ValueError(f"{key}: must be square, got shape {K.shape}")
    if K.shape[0] != n:
        raise ValueError(f"{key}: size {K.shape[0]}, expected dim x nodes = {n}")
    if not np.all(np.isfinite(K.data)):
        i = int(np.flatnonzero(~np.isfinite(K.data))[0])
        row = int(np.searchsorted(K.indptr, i, side="right") - 1)
        raise ValueError(f"{key}: NaN or infinite entry at ({row}, {int(K.indices[i])})")
    scale = float(np.abs(K.data).max()) if K.nnz else 0.0
    if scale == 0:
        raise ValueError(f"{key}: all zero")
    D = (K - K.T).tocsr()
    asym = float(np.abs(D.data).max()) if D.nnz else 0.0
    if asym > SYM_RTOL * scale:
        raise ValueError(f"{key}: not symmetric (max |K - K^T| = {asym:.3g}, max |K| = {scale:.3g})")
    K = (0.5 * (K + K.T)).tocsr()
    K.sort_indices()
    return K


def check_rigid(K: sp.csr_matrix, R: np.ndarray, key: str = "model.K") -> None:
    """ValueError naming `key` unless K annihilates the rigid modes R (orthonormal columns)."""
    if R.shape[1] == 0:
        return
    res = float(np.abs(K @ R).max()) / max(float(np.abs(K.data).max()), 1e-300)
    if res > RIGID_RTOL:
        raise ValueError(f"{key}: does not annihilate the {R.shape[1]} rigid mode(s) of model.nodes and "
                         f"model.supports (relative residual {res:.1e}): a support or a spring to ground "
                         "that model.supports does not list, or nodes that are not K's")


def read_nodes(value, base_dir: str, dim: int, key: str = "model.nodes") -> np.ndarray:
    """(n_nodes, dim) coordinates: inline, or a .csv (x,y[,z] per line, one header line
    allowed) or .npy file relative to base_dir; ValueError naming `key` otherwise."""
    if isinstance(value, str):
        path = os.path.join(base_dir, value)
        ext = os.path.splitext(value)[1].lower()
        if ext not in (".csv", ".npy"):
            raise ValueError(f"{key}: {value}: unsupported file type (use .csv or .npy)")
        if not os.path.isfile(path):
            raise ValueError(f"{key}: {value} not found")
        try:
            value = np.load(path, allow_pickle=False) if ext == ".npy" else _read_csv(path)
        except Exception as e:  # noqa: BLE001
            why = (str(e).strip().splitlines() or [type(e).__name__])[0]
            raise ValueError(f"{key}: cannot read {value} ({why})") from None
    X = as_float_array(value, key, ndim=2)
    if X.shape[1] != dim or X.shape[0] == 0:
        raise ValueError(f"{key}: expected (n_nodes, {dim}) coordinates, got shape {X.shape}")
    return X


def _read_csv(path: str) -> np.ndarray:
    with open(path) as f:
        first = f.readline()
    try:
        [float(v) for v in first.split(",")]
        skip = 0
    except ValueError:
        skip = 1                                  # a header line
    return np.loadtxt(path, delimiter=",", skiprows=skip, ndmin=2)


def matrix_model(K: sp.csr_matrix | StiffnessFile, coords: np.ndarray, supports, contact_nodes, normals,
                 tangents=None, cells: dict | None = None, exponent: int = 0) -> Model:
    """The Model of a stiffness assembled elsewhere: K (n_nodes*dim)^2, checked by
    check_stiffness and stored times 2**-exponent (or a StiffnessFile, checked when loaded),
    coords (n_nodes, dim), supports [[node, dof], ...] or None, contact nodes and frames as for
    a truss; rigid modes from the coordinates and supports (K must annihilate them:
    check_rigid). ValueError("<key>: ...")."""
    X = np.asarray(coords, dtype=float)
    n, dim = X.shape
    fixed = check_supports(supports, n, dim)
    c = check_contact_nodes(contact_nodes, n)
    check_contact_free(fixed, c, dim)
    nrm, tan = contact_frames(normals, dim, len(c), tangents)
    R = rigid_modes(X, dim, fixed)
    if isinstance(K, StiffnessFile):
        if K.n != n * dim:
            raise ValueError(f"model.K: size {K.n}, expected dim x nodes = {n * dim}")
        return Model(dim=dim, coords=X, K=None, fixed_dofs=fixed, contact_nodes=c, normals=nrm, tangents=tan,
                     rigid_modes=R, cells=cells or {}, assembly=K)
    K = check_stiffness(K, n * dim)
    check_rigid(K, R)
    return Model(dim=dim, coords=X, K=_scaled(K, exponent), fixed_dofs=fixed, contact_nodes=c, normals=nrm, tangents=tan,
                 rigid_modes=R, cells=cells or {})
