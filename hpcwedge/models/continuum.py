"""Global stiffness of an isotropic linear-elastic continuum meshed with linear cells."""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import scipy.sparse as sp

from hpcwedge.models.assembly import CHUNK_ENTRIES, assemble_blocks
from hpcwedge.models.elements import (
    CELL_TYPES,
    REFERENCE,
    centroid_stress,
    check_jacobians,
    element_stiffness,
    von_mises,
)
from hpcwedge.models.record import as_float_array


def _per_element(v, ne: int, key: str) -> np.ndarray:
    a = as_float_array(v, key)
    if a.ndim > 1 or (a.ndim == 1 and a.shape[0] != ne):
        raise ValueError(f"{key}: expected a scalar or one value per element ({ne}), got shape {a.shape}")
    return np.broadcast_to(a, (ne,))


def _connectivity(conn, cell: str, nen: int, n_nodes: int, key: str) -> np.ndarray:
    """(ne, nen) int64 node ids of one cell block, in range; ValueError naming key otherwise."""
    Q = np.asarray(conn)
    if Q.ndim != 2 or Q.shape[1] != nen:
        raise ValueError(f"{key}: {cell} cells need {nen} nodes each, got shape {Q.shape}")
    if not np.issubdtype(Q.dtype, np.integer):
        Qf = as_float_array(Q, key)
        if np.any(Qf != np.round(Qf)):
            raise ValueError(f"{key}: non-integer node id in the {cell} cells")
        Q = Qf.astype(np.int64)
    Q = Q.astype(np.int64, copy=False)
    if Q.size and (Q.min() < 0 or Q.max() >= n_nodes):
        e = int(np.flatnonzero((Q.min(axis=1) < 0) | (Q.max(axis=1) >= n_nodes))[0])
        raise ValueError(f"{key}: {cell} element {e} refers to node {Q[e].tolist()}, "
                         f"only {n_nodes} nodes (0-based)")
    return Q


def continuum_material(n_elements: int, E=1.0, nu=0.3, thickness=1.0,
                       material_key: str = "material") -> dict[str, np.ndarray]:
    """Validated per-element constants {"E", "nu", "thickness"}: each (n_elements,) float.

    E > 0, -1 < nu < 0.5, thickness > 0; scalars or one value per element (elements counted
    over the cell blocks in order). ValueError naming <material_key>.E / .nu / .thickness.
    """
    mk = material_key
    Ev = _per_element(E, n_elements, f"{mk}.E")
    nuv = _per_element(nu, n_elements, f"{mk}.nu")
    tv = _per_element(thickness, n_elements, f"{mk}.thickness")
    if np.any(Ev <= 0):
        raise ValueError(f"{mk}.E: must be > 0")
    if np.any((nuv <= -1) | (nuv >= 0.5)):
        raise ValueError(f"{mk}.nu: must lie in (-1, 0.5)")
    if np.any(tv <= 0):
        raise ValueError(f"{mk}.thickness: must be > 0")
    return {"E": np.array(Ev), "nu": np.array(nuv), "thickness": np.array(tv)}


def continuum_von_mises(coords: np.ndarray, cells: Mapping[str, np.ndarray], u: np.ndarray,
                        material: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Von Mises stress at the element centroids: {cell type: (ne,)}, same blocks as `cells`.

    coords: (n_nodes, dim); cells: {cell type: (ne, nen)} (as continuum_stiffness);
    u: (n_nodes, dim) nodal displacements; material: continuum_material(...) of the same
    elements (E, nu per element; in 2D plane stress, sigma_zz = 0). Units of E.
    """
    X = np.asarray(coords, dtype=float)
    out, offset = {}, 0
    for cell, Q in cells.items():
        Q = np.asarray(Q, dtype=np.int64)
        sl = slice(offset, offset + len(Q))
        sig = centroid_stress(cell, X[Q], u[Q], material["E"][sl], material["nu"][sl])
        out[cell] = von_mises(sig)
        offset += len(Q)
    return out


class ContinuumAssembly:
    """The elements of a continuum body, assembling its stiffness whole or by rows
    (model.StiffnessRows; continuum_stiffness is `full()`).

    Arguments as continuum_stiffness, validated here alike (ValueError naming `key` /
    `material_key`); check: also check every element's Jacobian now (chunked, the
    error of element_stiffness), so that a later rows() on a subset cannot be the first to
    meet a bad element. Holds coords, conns {cell type: (ne, nen) int64}, material
    (continuum_material), and counters full_assemblies, row_assemblies, elements_assembled
    (elements in the last rows() call) and row_elements (summed over rows() calls).
    """

    def __init__(self, coords: np.ndarray, cells: Mapping[str, np.ndarray], E=1.0, nu=0.3,
                 thickness=1.0, key: str = "model.cells", material_key: str = "material",
                 check: bool = True):
        X = as_float_array(coords, "model.nodes", ndim=2)
        n, dim = X.shape
        if dim not in CELL_TYPES:
            raise ValueError(f"model.nodes: expected (n_nodes, 2) or (n_nodes, 3) coordinates, got {X.shape}")
        for cell in cells:
            if cell not in CELL_TYPES[dim]:
                raise ValueError(f"{key}: unsupported cell type {cell!r} for a {dim}D body "
                                 f"(supported: {', '.join(CELL_TYPES[dim])})")
        self.coords, self.dim, self.key = X, dim, key
        self.conns = {c: _connectivity(q, c, REFERENCE[c].nen, n, key) for c, q in cells.items()}
        self.material = continuum_material(sum(len(q) for q in self.conns.values()), E, nu, thickness,
                                           material_key)
        self.full_assemblies = self.row_assemblies = self.elements_assembled = self.row_elements = 0
        if check:
            for cell, Q in self.conns.items():
                step = max(1, CHUNK_ENTRIES // (REFERENCE[cell].nen * dim) ** 2)
                for lo in range(0, len(Q), step):
                    check_jacobians(cell, X[Q[lo:lo + step]], lo, key)

    @property
    def n_dofs(self) -> int:
        return self.coords.shape[0] * self.dim

    def _assemble(self, nodes: np.ndarray | None = None) -> sp.csr_matrix:
        """The whole K (nodes None), or the sum of the elements incident to `nodes` only."""
        X, dim, key = self.coords, self.dim, self.key
        n = X.shape[0]
        Ev, nuv, tv = self.material["E"], self.material["nu"], self.material["thickness"]
        mark = None
        if nodes is not None:
            mark = np.zeros(n, dtype=bool)
            mark[nodes] = True
        K = sp.csr_matrix((n * dim, n * dim))
        offset, count = 0, 0
        for cell, Q in self.conns.items():
            o = offset

            def element_matrices(sel, cell=cell, Q=Q, o=o) -> np.ndarray:
                first = sel.start if isinstance(sel, slice) else 0
                idx = np.arange(sel.start, sel.stop) if isinstance(sel, slice) else sel
                return element_stiffness(cell, X[Q[sel]], Ev[o + idx], nuv[o + idx], tv[o + idx],
                                         first=first, key=key)

            elements = None if mark is None else np.flatnonzero(mark[Q].any(axis=1))
            if len(Q) and (elements is None or elements.size):
                Kc = assemble_blocks(Q, n, dim, element_matrices, elements=elements)
                K = Kc if K.nnz == 0 else (K + Kc).tocsr()
            count += len(Q) if elements is None else elements.size
            offset += len(Q)
        K.sort_indices()
        self.elements_assembled = count
        return K

    def full(self) -> sp.csr_matrix:
        """The whole stiffness (n_nodes*dim, n_nodes*dim) CSR (continuum_stiffness)."""
        self.full_assemblies += 1
        return self._assemble()

    def rows(self, dofs: np.ndarray) -> sp.csr_matrix:
        """K[dofs] (len(dofs), n_dofs) CSR, dofs global DOF ids (any order), assembled from the
        elements incident to their nodes only: bit for bit the rows of full() (assemble_blocks)."""
        dofs = np.asarray(dofs, dtype=np.int64)
        self.row_assemblies += 1
        K = self._assemble(np.unique(dofs // self.dim))
        self.row_elements += self.elements_assembled
        out = K[dofs]
        out.sort_indices()
        return out


def continuum_stiffness(coords: np.ndarray, cells: Mapping[str, np.ndarray], E=1.0, nu=0.3,
                        thickness=1.0, key: str = "model.cells",
                        material_key: str = "material") -> sp.csr_matrix:
    """Stiffness (n_nodes*dim, n_nodes*dim) CSR, exactly symmetric, node-major DOFs.

    coords: (n_nodes, dim), dim 2 (plane stress) or 3; cells: {cell type: (ne, nen) node ids}
    with types from elements.CELL_TYPES[dim] in meshio's node order (see elements.py).
    E (Young's modulus, > 0), nu (Poisson ratio, -1 < nu < 0.5) and thickness (> 0, 2D only):
    scalars or one value per element, elements counted over `cells` in its order.
    Every block is assembled on its own (chunked, so 10^6 elements stay within memory) and
    the blocks summed. ValueError("<key>: ...") on an unsupported cell type, a bad node id or
    a non-positive Jacobian (naming the cell type and its element index within the block);
    material errors name <material_key>.E / .nu / .thickness.
    """
    return ContinuumAssembly(coords, cells, E, nu, thickness, key, material_key, check=False).full()


def q4_stiffness(coords: np.ndarray, quads: np.ndarray, E=1.0, nu=0.3, t=1.0,
                 key: str = "model.quads") -> sp.csr_matrix:
    """Plane-stress bilinear quadrilaterals: continuum_stiffness(coords, {"quad": quads}, ...).

    coords: (n_nodes, 2); quads: (ne, 4) counter-clockwise corners; 2x2 Gauss quadrature.
    """
    X = as_float_array(coords, "model.nodes", ndim=2)
    if X.shape[1] != 2:
        raise ValueError(f"model.nodes: plane stress needs (n_nodes, 2) coordinates, got {X.shape}")
    return continuum_stiffness(X, {"quad": quads}, E, nu, t, key=key)
