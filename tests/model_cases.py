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
