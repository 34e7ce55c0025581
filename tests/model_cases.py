"""Models shared by the tests and the mpirun drivers: a small hexahedral block (3D continuum)
and a by-name constructor (library models or "hexblock")."""
import numpy as np

from hpcwedge import models
from hpcwedge.models.mesh import MeshData, mesh_model


def hex_block(nx, ny, nz):
    """Unit-spaced hexahedral block, nodes (i, j, k) -> i + (nx+1)(j + (ny+1) k)."""
    g = np.stack(np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1), indexing="ij"), -1)
    X = g.transpose(2, 1, 0, 3).reshape(-1, 3).astype(float)
    X[:, 0] *= 1.0 + 0.1 * X[:, 2]                       # a slight taper: not a plain grid
    nid = lambda i, j, k: i + (nx + 1) * (j + (ny + 1) * k)  # noqa: E731
    H = [[nid(i, j, k), nid(i + 1, j, k), nid(i + 1, j + 1, k), nid(i, j + 1, k),
          nid(i, j, k + 1), nid(i + 1, j, k + 1), nid(i + 1, j + 1, k + 1), nid(i, j + 1, k + 1)]
         for k in range(nz) for j in range(ny) for i in range(nx)]
    return X, np.array(H), nid


def hex_model(**kw):
    """hex_block(4, 4, 4) as a free mesh body with 6 contact nodes on 5 faces (normals into
    the body); kw: mesh_model's keywords (contact_patch, contact_patch_kind, ...)."""
    X, H, nid = hex_block(4, 4, 4)
    contact = np.array([nid(0, 1, 1), nid(0, 3, 3), nid(4, 2, 2), nid(2, 0, 2), nid(2, 4, 2), nid(2, 2, 0)])
    normals = [[1, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]]
    mesh = MeshData(name="block", points=X, cells={"hexahedron": H}, groups={})
    return mesh_model(mesh, contact_nodes=contact, normals=normals, **kw)


def make_model(kind: str, kwargs: dict):
    """hpcwedge.models.<kind>(**kwargs), or hex_model(**kwargs) for kind "hexblock"."""
    return hex_model(**kwargs) if kind == "hexblock" else getattr(models, kind)(**kwargs)


def distorted_patch(cell):
    """A distorted patch: coords, (ne, nen) cells, interior node ids, exact volume (area)."""
    if cell in ("quad", "triangle"):
        X = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1.2, 0.9], [2, 1], [0, 2], [1, 2], [2, 2]], float)
        Q = np.array([[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 7, 6], [4, 5, 8, 7]])
        C = Q if cell == "quad" else np.concatenate([Q[:, [0, 1, 2]], Q[:, [0, 2, 3]]])
        return X, C, [4], 4.0
    g = np.arange(3) / 2.0
    X = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)   # node = 9i + 3j + k
    X[13] = [0.55, 0.45, 0.6]                                              # the interior node
    node = np.arange(27).reshape(3, 3, 3)
    H = np.stack([node[:-1, :-1, :-1], node[1:, :-1, :-1], node[1:, 1:, :-1], node[:-1, 1:, :-1],
                  node[:-1, :-1, 1:], node[1:, :-1, 1:], node[1:, 1:, 1:], node[:-1, 1:, 1:]], -1).reshape(-1, 8)
    return X, (H if cell == "hexahedron" else kuhn_tets(X, H)), [13], 1.0


def kuhn_tets(X, H):
    """Six tetrahedra per hexahedron around its 0-6 diagonal, reordered to positive volume."""
    T4 = H[:, [[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]]].reshape(-1, 4)
    d = X[T4[:, 1:]] - X[T4[:, :1]]
    neg = np.linalg.det(d) < 0
    T4[neg] = T4[neg][:, [0, 2, 1, 3]]
    return T4
