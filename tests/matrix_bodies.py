"""Bodies assembled outside hpcwedge for the kind = "matrix" tests: a plane-stress trapezoid
plug of P1 triangles from scikit-fem (2D) and a truss plug (3D), written as MatrixMarket,
.npz or PETSc binary with their node coordinates, and the scene of the same body condensed
independently (dense numpy Schur complement, rigid modes from the coordinates) as
kind = "stiffness"."""
from __future__ import annotations

import numpy as np
import scipy.io
import scipy.sparse as sp

MU = (0.45, 0.8)


def plug_2d(cols: int = 4, rows: int = 3, E: float = 210e9, nu: float = 0.3):
    """(K CSR node-major, coords (n, 2), contact nodes, normals into the body): a trapezoid
    wider at the top, its two slanted sides against a V-groove (plane stress, unit thickness)."""
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity
    mesh = skfem.MeshTri.init_tensor(np.linspace(0, 1, cols + 1), np.linspace(0, 1, rows + 1))
    x, y = mesh.p
    mesh = skfem.MeshTri(np.array([(x - 0.5) * (1.4 + 0.6 * y), y]), mesh.t)
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTriP1()))
    lam, mu = lame_parameters(E, nu)
    K = skfem.asm(linear_elasticity(2 * lam * mu / (lam + 2 * mu), mu), basis)
    order = basis.nodal_dofs.T.ravel()                # node-major DOFs
    K = sp.csr_matrix(K)[order][:, order]
    left, right = np.flatnonzero(np.isclose(x, 0)), np.flatnonzero(np.isclose(x, 1))
    contact = np.concatenate([left, right])
    side = np.array([1.0, -0.3]) / np.hypot(1.0, 0.3)     # left wall's inward normal
    normals = np.array([side] * len(left) + [[-side[0], side[1]]] * len(right))
    return K, mesh.p.T.copy(), contact, normals


def plug_3d(levels: int = 2, ring: int = 4, EA: float = 3.0):
    """(K, coords (n, 3), contact nodes, normals): a truss of `levels` rings of `ring` nodes
    (radius growing upward) and a centre node per level, braced, in a conical seat."""
    from hpcwedge.models.truss import truss_stiffness
    pts, bars = [], []
    for lv in range(levels):
        r, z = 1.0 + 0.3 * lv, float(lv)
        base = len(pts)
        pts += [[r * np.cos(2 * np.pi * k / ring), r * np.sin(2 * np.pi * k / ring), z] for k in range(ring)]
        pts.append([0.0, 0.0, z])
        bars += [[base + k, base + (k + 1) % ring] for k in range(ring)] + [[base + k, base + ring] for k in range(ring)]
        if lv:
            prev = base - ring - 1
            bars += [[prev + k, base + k] for k in range(ring)] + [[prev + k, base + (k + 1) % ring]
                                                                    for k in range(ring)]
            bars += [[prev + ring, base + ring], [prev + ring, base], [prev, base + ring]]
    X = np.array(pts)
    K = truss_stiffness(X, np.array(bars), EA)
    contact = np.array([lv * (ring + 1) + k for lv in range(levels) for k in range(ring)])
    radial = X[contact, :2] / np.linalg.norm(X[contact, :2], axis=1, keepdims=True)
    normals = np.column_stack([-radial * np.cos(0.3), np.full(len(contact), np.sin(0.3))])
    return K, X, contact, normals


def write_matrix(K: sp.spmatrix, path) -> None:
    """K in the format of path's extension: .mtx (symmetric storage), .npz, .petsc (PETSc binary)."""
    path = str(path)
    if path.endswith(".mtx"):
        scipy.io.mmwrite(path, sp.coo_matrix(K), symmetry="symmetric")
    elif path.endswith(".npz"):
        sp.save_npz(path, sp.csr_matrix(K))
    else:
        write_petsc(K, path)


def write_petsc(K: sp.spmatrix, path: str) -> None:
    """K in PETSc's binary matrix format, written by PETSc (MatView)."""
    from petsc4py import PETSc
    K = sp.csr_matrix(K)
    K.sort_indices()
    A = PETSc.Mat().createAIJ(size=K.shape, csr=(K.indptr.astype(PETSc.IntType), K.indices.astype(PETSc.IntType),
                                                 K.data), comm=PETSc.COMM_SELF)
    A.assemble()
    viewer = PETSc.Viewer().createBinary(path, "w", comm=PETSc.COMM_SELF)
    A.view(viewer)
    viewer.destroy()
    A.destroy()


def condensed_local(K: sp.spmatrix, X: np.ndarray, contact: np.ndarray, normals: np.ndarray):
    """(K_local, N_local) block-ordered [n.., t..] (3D [n.., t1.., t2..]) by dense numpy: the
    Schur complement on the contact DOFs of a free body, and its rigid modes from X."""
    n, dim = X.shape
    c = (dim * contact[:, None] + np.arange(dim)).ravel()
    i = np.setdiff1d(np.arange(n * dim), c)
    A = K.toarray()
    S = A[np.ix_(c, c)] - A[np.ix_(c, i)] @ np.linalg.solve(A[np.ix_(i, i)], A[np.ix_(i, c)])
    d = X - X.mean(axis=0)
    if dim == 2:
        modes = [np.tile([1.0, 0.0], (n, 1)), np.tile([0.0, 1.0], (n, 1)), np.column_stack([-d[:, 1], d[:, 0]])]
    else:
        modes = [np.tile(e, (n, 1)) for e in np.eye(3)] + [np.cross(e, d) for e in np.eye(3)]
    R = np.column_stack([v.ravel() for v in modes])[c]
    nrm = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    if dim == 2:
        frames = [nrm, np.column_stack([nrm[:, 1], -nrm[:, 0]])]
    else:
        axis = np.argmin(np.abs(nrm), axis=1)
        t1 = np.eye(3)[axis] - (np.eye(3)[axis] * nrm).sum(1, keepdims=True) * nrm
        t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
        frames = [nrm, t1, np.cross(nrm, t1)]
    m = len(contact)
    T = np.zeros((dim * m, dim * m))
    for a, F in enumerate(frames):
        for j in range(m):
            T[a * m + j, dim * j:dim * j + dim] = F[j]
    KL = T @ S @ T.T
    return 0.5 * (KL + KL.T), np.linalg.qr(T @ R)[0]


def matrix_scene(tmp_path, body, fmt: str, mu=MU, extra: str = "", name: str = "matrix") -> str:
    """Write body's K as body.<fmt>, its nodes as nodes.csv and a kind = "matrix" scene; its path."""
    K, X, contact, normals = body
    write_matrix(K, tmp_path / f"body.{fmt}")
    np.savetxt(tmp_path / "nodes.csv", X, delimiter=",", header=",".join("xyz"[:X.shape[1]]), comments="")
    text = (f'name = "{name}"\ndim = {X.shape[1]}\n[model]\nkind = "matrix"\nK = "body.{fmt}"\n'
            f'nodes = "nodes.csv"\n[contact]\nnodes = {contact.tolist()}\nnormals = {normals.tolist()}\n'
            f"[friction]\nmu = {list(mu)}\n{extra}")
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return str(path)


def stiffness_scene(tmp_path, body, mu=MU, extra: str = "") -> str:
    """The same body condensed by condensed_local, as a kind = "stiffness" scene (K.npz)."""
    KL, NL = condensed_local(*body)
    np.savez(tmp_path / "K.npz", K=KL, null_space=NL)
    text = (f'name = "stiffness"\ndim = {body[1].shape[1]}\n[model]\nkind = "stiffness"\nfile = "K.npz"\n'
            f"[friction]\nmu = {list(mu)}\n{extra}")
    path = tmp_path / "stiffness.toml"
    path.write_text(text)
    return str(path)
