"""Element stiffness and centroid stress of linear isoparametric cells in isotropic linear
elasticity.

One routine for every cell type (`element_stiffness`; `centroid_stress` for stress recovery),
vectorised over elements with numpy einsum; the cell types differ only in their reference data (`REFERENCE`):

    cell type    dim  nodes  quadrature
    triangle      2     3    1 point (exact: constant strain)
    quad          2     4    2x2 Gauss
    tetra         3     4    1 point (exact: constant strain)
    hexahedron    3     8    2x2x2 Gauss

Names and node orders are meshio's (= VTK's = Gmsh's for these linear cells): triangle and
quad counter-clockwise; tetra with (x1-x0, x2-x0, x3-x0) right-handed; hexahedron bottom face
0-3 then top face 4-7, the bottom face counter-clockwise seen from the top.

2D is plane stress with a thickness t, 3D is the full solid. With the Lamé constants
lam, mu (lam = E nu / (1 - nu^2) in plane stress, E nu / ((1 + nu)(1 - 2 nu)) in 3D;
mu = E / (2 (1 + nu))) the element matrix is

    k[a p, b q] = sum_g w_g t det J_g ( lam dN_a/dx_p dN_b/dx_q + mu dN_a/dx_q dN_b/dx_p
                                       + mu delta_pq grad N_a . grad N_b )

which is B^T D B written without the Voigt matrices. Units: those of E times length^(dim-2)
(times t in 2D); any consistent set.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: det J <= DET_RTOL * (element extent)^dim at a check point: the element is inverted or degenerate
DET_RTOL = 1e-14


@dataclass(frozen=True)
class ReferenceCell:
    """Reference data of one cell type.

    nodes:   (nen, dim) reference node coordinates, in the cell's node order.
    dN:      (ng, nen, dim) shape-function gradients dN_a/dxi_j at the quadrature points.
    weights: (ng,) quadrature weights.
    dN_check: (nc, nen, dim) gradients at the points where det J must be positive: the
             quadrature points, then (tensor-product cells) the nodes. For simplices det J is
             constant and the one quadrature point suffices.
    dN_centroid: (1, nen, dim) gradients at the reference centroid (where stresses are reported).
    """

    name: str
    dim: int
    nodes: np.ndarray
    dN: np.ndarray
    weights: np.ndarray
    dN_check: np.ndarray
    dN_centroid: np.ndarray

    @property
    def nen(self) -> int:
        return self.nodes.shape[0]


def _simplex(name: str, dim: int) -> ReferenceCell:
    """Linear simplex: N_0 = 1 - sum xi, N_k = xi_k; one-point rule at the centroid."""
    nodes = np.vstack([np.zeros(dim), np.eye(dim)])
    grad = np.vstack([-np.ones(dim), np.eye(dim)])[None]                  # (1, dim+1, dim)
    volume = 1.0 / (2.0 if dim == 2 else 6.0)
    return ReferenceCell(name, dim, nodes, grad, np.array([volume]), grad, grad)


def _tensor_gradients(nodes: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """dN_a/dxi_k (np, nen, dim) of N_a = prod_j (1 + xi_j xi_aj) / 2 at the points xi (np, dim)."""
    f = 0.5 * (1.0 + xi[:, None, :] * nodes[None, :, :])                 # (np, nen, dim)
    dim = nodes.shape[1]
    grad = np.empty(f.shape)
    for k in range(dim):                                                   # over axes, not elements
        others = np.prod(np.delete(f, k, axis=2), axis=2)
        grad[:, :, k] = 0.5 * nodes[None, :, k] * others
    return grad


def _tensor(name: str, nodes: np.ndarray) -> ReferenceCell:
    """Bi/trilinear cell on [-1, 1]^dim with the 2^dim-point Gauss rule (weights 1)."""
    gauss = nodes / np.sqrt(3.0)
    dN = _tensor_gradients(nodes, gauss)
    check = np.concatenate([dN, _tensor_gradients(nodes, nodes)])
    centre = _tensor_gradients(nodes, np.zeros((1, nodes.shape[1])))
    return ReferenceCell(name, nodes.shape[1], nodes, dN, np.ones(len(gauss)), check, centre)


_SQUARE = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
_CUBE = np.vstack([np.c_[_SQUARE, -np.ones(4)], np.c_[_SQUARE, np.ones(4)]])

#: reference data by meshio cell type
REFERENCE: dict[str, ReferenceCell] = {
    "triangle": _simplex("triangle", 2),
    "quad": _tensor("quad", _SQUARE),
    "tetra": _simplex("tetra", 3),
    "hexahedron": _tensor("hexahedron", _CUBE),
}
#: supported cell types per body dimension
CELL_TYPES: dict[int, tuple[str, ...]] = {2: ("triangle", "quad"), 3: ("tetra", "hexahedron")}


def lame(E: np.ndarray, nu: np.ndarray, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Lamé constants (lam, mu): plane stress in 2D, the 3D solid in 3D. Needs -1 < nu < 0.5."""
    mu = E / (2.0 * (1.0 + nu))
    lam = E * nu / (1.0 - nu ** 2) if dim == 2 else E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    return lam, mu


def _det_inv(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """det and inverse of a stack of 2x2 or 3x3 matrices (..., d, d), by cofactors."""
    if J.shape[-1] == 2:
        det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
        adj = np.stack([np.stack([J[..., 1, 1], -J[..., 0, 1]], -1),
                        np.stack([-J[..., 1, 0], J[..., 0, 0]], -1)], -2)
    else:
        # adj^T rows are the cross products of the columns: adj[i] = c_{i+1} x c_{i+2}
        c = [J[..., :, k] for k in range(3)]
        adj = np.stack([np.cross(c[1], c[2]), np.cross(c[2], c[0]), np.cross(c[0], c[1])], -2)
        det = np.einsum("...i,...i->...", c[0], adj[..., 0, :])
    with np.errstate(divide="ignore", invalid="ignore"):
        return det, adj / det[..., None, None]


def _checked_jacobian(ref: ReferenceCell, Xe: np.ndarray, first: int, key: str):
    """det J (ne, nc) and J^-1 (ne, nc, dim, dim) at ref.dN_check; ValueError on det J <= 0."""
    dim = Xe.shape[2]
    J = np.einsum("eai,caj->ecij", Xe, ref.dN_check)                       # dx_i/dxi_j
    det, inv = _det_inv(J)
    size = np.ptp(Xe, axis=1).max(axis=1) ** dim
    bad = np.flatnonzero(np.any(det <= DET_RTOL * size[:, None], axis=1))
    if bad.size:
        e = int(bad[0])
        raise ValueError(f"{key}: {ref.name} element {first + e} has a non-positive Jacobian "
                         f"(det J = {det[e].min():.3g}); its nodes must be ordered counter-clockwise "
                         f"(2D) or right-handed (3D) and the element must not be degenerate")
    return det, inv


def check_jacobians(cell: str, Xe: np.ndarray, first: int = 0, key: str = "model.cells") -> None:
    """The Jacobian check of element_stiffness alone (same ValueError), Xe (ne, nen, dim)."""
    _checked_jacobian(REFERENCE[cell], Xe, first, key)


def element_stiffness(cell: str, Xe: np.ndarray, E: np.ndarray, nu: np.ndarray,
                      t: np.ndarray | None = None, first: int = 0, key: str = "model.cells") -> np.ndarray:
    """Element stiffness matrices (ne, nen*dim, nen*dim), exactly symmetric.

    cell: a key of REFERENCE; Xe: (ne, nen, dim) node coordinates in the cell's node order;
    E, nu: (ne,) Young's modulus and Poisson ratio; t: (ne,) thickness (2D; ignored in 3D).
    Local DOFs node-major: (x0, y0[, z0], x1, ...).
    ValueError("<key>: <cell> element <first + i> has a non-positive Jacobian ...") when
    det J <= DET_RTOL * extent^dim at a quadrature point or (quad, hexahedron) at a node.
    """
    ref = REFERENCE[cell]
    ne, nen, dim = Xe.shape
    ng = len(ref.weights)
    det, inv = _checked_jacobian(ref, Xe, first, key)
    G = np.einsum("gaj,egji->egai", ref.dN, inv[:, :ng])                   # dN_a/dx_i at Gauss points
    w = det[:, :ng] * ref.weights
    if dim == 2:
        w = w * t[:, None]
    P = np.einsum("egap,egbq->eapbq", G * w[..., None, None], G)           # sum_g w dN_a/dx_p dN_b/dx_q
    S = np.einsum("eapbp->eab", P)                                         # sum_g w grad N_a . grad N_b
    lam, mu = lame(E, nu, dim)
    ke = lam[:, None, None, None, None] * P + mu[:, None, None, None, None] * P.transpose(0, 1, 4, 3, 2)
    idx = np.arange(dim)
    ke[:, :, idx, :, idx] += mu[None, :, None, None] * S[None]
    ke = ke.reshape(ne, nen * dim, nen * dim)
    return 0.5 * (ke + ke.transpose(0, 2, 1))


def centroid_stress(cell: str, Xe: np.ndarray, Ue: np.ndarray, E: np.ndarray, nu: np.ndarray,
                    first: int = 0, key: str = "model.cells") -> np.ndarray:
    """Cauchy stress (ne, 3, 3) at each element's reference centroid, global axes.

    cell, Xe (ne, nen, dim), E, nu (ne,): as element_stiffness; Ue: (ne, nen, dim) nodal
    displacements. Small strain eps = sym(grad u) at the centroid, sigma = lam tr(eps) I +
    2 mu eps with the Lamé constants of `lame` (plane stress in 2D: the in-plane block, and
    sigma_zz = sigma_xz = sigma_yz = 0). Units of E times strain.
    """
    ref = REFERENCE[cell]
    dim = Xe.shape[2]
    _checked_jacobian(ref, Xe, first, key)
    J = np.einsum("eai,caj->eij", Xe, ref.dN_centroid)
    _, inv = _det_inv(J)
    G = np.einsum("aj,eji->eai", ref.dN_centroid[0], inv)                 # dN_a/dx_i at the centroid
    grad = np.einsum("eap,eaq->epq", Ue, G)                                # du_p/dx_q
    eps = 0.5 * (grad + grad.transpose(0, 2, 1))
    lam, mu = lame(E, nu, dim)
    sig = 2.0 * mu[:, None, None] * eps
    sig[:, np.arange(dim), np.arange(dim)] += (lam * np.trace(eps, axis1=1, axis2=2))[:, None]
    out = np.zeros((len(Xe), 3, 3))
    out[:, :dim, :dim] = sig
    return out


def von_mises(sigma: np.ndarray) -> np.ndarray:
    """Von Mises equivalent stress sqrt(3/2 s:s), s = deviator of sigma (..., 3, 3)."""
    s = sigma - np.trace(sigma, axis1=-2, axis2=-1)[..., None, None] * np.eye(3) / 3.0
    return np.sqrt(1.5 * np.einsum("...ij,...ij->...", s, s))
