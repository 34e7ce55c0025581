"""The Model record: a discretised body before condensation (one per model family)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True)
class Tie:
    """Master-slave elimination of some DOFs (contact patches, models/patch.py): u = T u_red.

    T:           (n_dofs, n_dofs + n_rotations) sparse; identity on every non-slave DOF,
                 zero columns at the slave DOFs; columns n_dofs.. are extra DOFs (the feet's
                 rotations), condensed out with the interior.
    slave_dofs:  (sorted) full DOFs that T expresses through the others.
    n_rotations: number of extra DOFs.
    """

    T: sp.csr_matrix
    slave_dofs: np.ndarray
    n_rotations: int


class StiffnessRows(Protocol):
    """The element data of a body that can assemble its stiffness whole or by rows.

    full():      the whole K (n_dofs, n_dofs) CSR, exactly symmetric, node-major DOFs.
    rows(dofs):  K[dofs] (len(dofs), n_dofs) CSR for global DOFs `dofs` (sorted, unique),
                 assembled from the elements incident to their nodes only, equal entry by
                 entry to the same rows of full().
    full_assemblies, row_assemblies: how many times each was called (for tests and benchmarks).
    """

    full_assemblies: int
    row_assemblies: int

    def full(self) -> sp.csr_matrix: ...

    def rows(self, dofs: np.ndarray) -> sp.csr_matrix: ...


class _LazyK:
    """Model.K as a data descriptor: the stored matrix; a stored None with `model.assembly`
    set is replaced, on first access, by assembly.full() (cached on the instance)."""

    def __get__(self, obj, owner=None):
        if obj is None:
            raise AttributeError("K")           # no class-level default: K stays a required field
        K = obj.__dict__["_K"]
        if K is None and obj.assembly is not None:
            K = obj.assembly.full()
            obj.__dict__["_K"] = K
        return K

    def __set__(self, obj, value) -> None:
        obj.__dict__["_K"] = value


@dataclass(frozen=True)
class Model:
    """A linear-elastic body touching a rigid obstacle at m contact nodes.

    dim:           2 or 3.
    coords:        (n_nodes, dim) node coordinates.
    K:             (n_nodes*dim, n_nodes*dim) sparse symmetric stiffness, node-major
                   DOFs (dof = dim*node + component), supports *not* applied. May be given as
                   None together with `assembly`: then assembled (assembly.full()) on first
                   access and kept.
    fixed_dofs:    global DOFs held at zero by supports (sorted, unique).
    contact_nodes: (m,) node ids, in contact-list order.
    normals:       (m, dim) unit normals of the obstacle pointing into the body.
    tangents:      (m, dim-1, dim) unit tangents: 2D t = (n_y, -n_x); 3D t1, t2 = n x t1.
    rigid_modes:   (n_nodes*dim, k) rigid-body motions the supports leave free
                   (k = 0 for a supported body), from the geometry; with a tie, in the
                   DOFs the tie keeps (models/patch.py: "hat" patches change the contact rows).
    cells:         plotting/export connectivity, e.g. {"line": (nb, 2), "quad": (ne, 4)}.
    material:      per-element constants for stress recovery, element order = the blocks of
                   `cells` in order: {"EA": (nb,)} for bars ("line" cells); {"E": (ne,),
                   "nu": (ne,), "thickness": (ne,)} for continuum cells (thickness 1 in 3D).
                   (Springs added to K by hand, e.g. vgroove_bar's eps, are not elements.)
    tie:           None, or the master-slave map of contact patches (Tie): condensation then
                   works on T^T K T (condense.py), the whole body's displacement is T u_red.
    assembly:      None, or the element data (StiffnessRows) K comes from: continuum models
                   keep it so that condense_distributed can assemble each rank's rows alone
                   (models/continuum.py ContinuumAssembly) instead of the whole K.
    Use model.replace(...) rather than dataclasses.replace: it keeps K unassembled.
    """

    dim: int
    coords: np.ndarray
    K: sp.csr_matrix | None = _LazyK()
    fixed_dofs: np.ndarray
    contact_nodes: np.ndarray
    normals: np.ndarray
    tangents: np.ndarray
    rigid_modes: np.ndarray
    cells: dict = field(default_factory=dict)
    material: dict = field(default_factory=dict)
    tie: Tie | None = None
    assembly: StiffnessRows | None = None

    def replace(self, **changes) -> Model:
        """dataclasses.replace(self, **changes), without assembling a K not yet assembled."""
        changes.setdefault("K", self.__dict__["_K"])
        return dataclasses.replace(self, **changes)

    @property
    def m(self) -> int:
        return len(self.contact_nodes)

    @property
    def n_dofs(self) -> int:
        return self.coords.shape[0] * self.dim

    def contact_dofs(self) -> np.ndarray:
        """Global DOFs of the contact nodes, node-major: (m*dim,)."""
        return (self.dim * self.contact_nodes[:, None] + np.arange(self.dim)).ravel()

    def frames(self) -> np.ndarray:
        """(m, dim, dim) rows = local axes (n, t) or (n, t1, t2) of each contact node."""
        return np.concatenate([self.normals[:, None, :], self.tangents], axis=1)

    def local_map(self) -> np.ndarray:
        """T (dim*m, dim*m): local block-ordered contact DOFs = T @ global contact DOFs.

        Block ordering: row a*m + i is local axis a (0 = n) of contact node i;
        global contact DOFs ordered node-major as in contact_dofs().
        """
        m, d = self.m, self.dim
        T = np.zeros((d * m, d * m))
        F = self.frames()
        for a in range(d):
            for i in range(m):
                T[a * m + i, d * i:d * i + d] = F[i, a]
        return T


# ---------------------------------------------------------------------------
# Input helpers shared by the model families (truss, Q4 mesh, ...).
# Every check raises ValueError("<key>: <reason>") on one line.
# ---------------------------------------------------------------------------

def as_float_array(x, key: str, ndim: int | None = None) -> np.ndarray:
    """np.asarray(x, float) with a one-line ValueError naming `key` on ragged, non-numeric,
    complex (a complex array from a file; numpy would drop its imaginary part) or NaN input."""
    if isinstance(x, np.ndarray) and np.iscomplexobj(x):
        raise ValueError(f"{key}: complex entries (a stiffness is real)")
    try:
        raw = np.asarray(x)                     # converted once; None: ragged
    except (TypeError, ValueError):
        raw = None
    if raw is None or raw.dtype.kind in "USO":
        text = _first_text(x)
        if text is not None:
            # "2" would convert, yet mu = "0.5" is refused: numbers are numbers everywhere
            raise ValueError(f"{key}: numbers expected, got text {text!r}")
    try:
        if raw is None:
            raise ValueError
        a = raw.astype(float, copy=False)
    except (TypeError, ValueError):
        raise ValueError(f"{key}: not a numeric array (ragged or non-numeric entries)") from None
    if ndim is not None and a.ndim != ndim:
        raise ValueError(f"{key}: expected a {ndim}-D array, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        raise ValueError(f"{key}: NaN or infinite entry at index {tuple(int(i) for i in bad)}")
    return a


def _first_text(x):
    """The first str or bytes entry of a (nested) value, or None."""
    if isinstance(x, (str, bytes, np.str_, np.bytes_)):
        return x
    if isinstance(x, (list, tuple, np.ndarray)):
        for v in x:
            t = _first_text(v)
            if t is not None:
                return t
    return None


def as_index_array(x, key: str, n: int, what: str = "node", ndim: int | None = None) -> np.ndarray:
    """Integer array of ids in [0, n) (integral floats accepted); ValueError naming `key` otherwise."""
    a = as_float_array(x, key, ndim)
    if a.size and not np.all(a == np.round(a)):
        bad = np.argwhere(a != np.round(a))[0]
        raise ValueError(f"{key}: non-integer {what} id at index {tuple(int(i) for i in bad)}")
    if a.size:                                   # before the cast (a 1e300 id must not wrap around)
        lo, hi = int(a.min()), int(a.max())
        if lo < 0 or hi >= n:
            v = lo if lo < 0 else hi
            raise ValueError(f"{key}: {what} {v} does not exist, only {n} {what}s (0-based)")
    return a.astype(np.int64)


def check_contact_nodes(contact_nodes, n_nodes: int, key: str = "contact.nodes") -> np.ndarray:
    """(m,) int64 contact node ids: 1-D, non-empty, in range, no duplicates."""
    c = as_index_array(contact_nodes, key, n_nodes, "node", ndim=1)
    if c.size == 0:
        raise ValueError(f"{key}: no contact nodes")
    uniq, counts = np.unique(c, return_counts=True)
    if np.any(counts > 1):
        raise ValueError(f"{key}: duplicate node {int(uniq[counts > 1][0])}")
    return c


def _default_t1(n: np.ndarray) -> np.ndarray:
    """(m, 3) unit vectors perpendicular to the unit normals n (m, 3), deterministic:
    the coordinate axis least aligned with n (first on ties), projected and normalised."""
    axis = np.argmin(np.abs(n), axis=1)
    e = np.zeros_like(n)
    e[np.arange(len(n)), axis] = 1.0
    t = e - (e * n).sum(axis=1, keepdims=True) * n
    return t / np.linalg.norm(t, axis=1, keepdims=True)


def contact_frames(normals, dim: int, m: int, tangents=None,
                   key: str = "contact") -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (m, dim) and tangents (m, dim-1, dim) of the contact frames (SPEC §1).

    normals: (m, dim), any non-zero length (normalised here), pointing into the body.
    2D: t = (n_y, -n_x); given tangents ((m, 2) or (m, 1, 2)) must agree with it in sign.
    3D: default t1 = the coordinate axis least aligned with n, orthogonalised; given
    tangents (m, 3) = t1 or (m, 2, 3) = (t1, t2) are orthonormalised against n; t2 = n x t1
    always (a given t2 must agree with it in sign).
    """
    n = as_float_array(normals, f"{key}.normals", ndim=2)
    if n.shape != (m, dim):
        raise ValueError(f"{key}.normals: expected shape ({m}, {dim}) (one per contact node), got {n.shape}")
    nrm = np.linalg.norm(n, axis=1)
    scale = max(float(nrm.max()), 1e-300)
    zero = np.flatnonzero(nrm <= 1e-12 * scale)
    if zero.size:
        raise ValueError(f"{key}.normals: zero normal at contact node {int(zero[0])}")
    n = n / nrm[:, None]
    tkey = f"{key}.tangents"
    if tangents is not None:
        t = as_float_array(tangents, tkey)
        if t.ndim == 2:
            t = t[:, None, :]
        if t.ndim != 3 or t.shape[0] != m or t.shape[2] != dim or t.shape[1] not in (1, dim - 1):
            raise ValueError(f"{tkey}: expected shape ({m}, {dim}) or ({m}, {dim - 1}, {dim}), got {np.shape(tangents)}")
        t1 = t[:, 0, :] - (t[:, 0, :] * n).sum(axis=1, keepdims=True) * n
        tn = np.linalg.norm(t1, axis=1)
        bad = np.flatnonzero(tn <= 1e-8 * np.linalg.norm(t[:, 0, :], axis=1))
        if bad.size:
            raise ValueError(f"{tkey}: tangent zero or parallel to the normal at contact node {int(bad[0])}")
        t1 = t1 / tn[:, None]
    if dim == 2:
        tt = np.stack([n[:, 1], -n[:, 0]], axis=1)
        if tangents is not None:
            bad = np.flatnonzero((t1 * tt).sum(axis=1) < 0)
            if bad.size:
                raise ValueError(f"{tkey}: 2D tangent must be t = (n_y, -n_x); reversed at contact node {int(bad[0])}")
        return n, tt[:, None, :]
    if dim != 3:
        raise ValueError(f"dim: must be 2 or 3, got {dim}")
    if tangents is None:
        t1 = _default_t1(n)
    t2 = np.cross(n, t1)
    if tangents is not None and t.shape[1] == 2:
        bad = np.flatnonzero((t[:, 1, :] * t2).sum(axis=1) <= 0)
        if bad.size:
            raise ValueError(f"{tkey}: t2 must be n x t1 (right-handed frame); contact node {int(bad[0])} has the opposite t2")
    return n, np.stack([t1, t2], axis=1)


def check_supports(supports, n_nodes: int, dim: int, key: str = "model.supports") -> np.ndarray:
    """Sorted unique fixed global DOFs (dim*node + dof) from [node, dof] pairs."""
    if supports is None:
        return np.zeros(0, dtype=np.int64)
    s = as_float_array(supports, key)
    if s.size == 0:
        return np.zeros(0, dtype=np.int64)
    if s.ndim != 2 or s.shape[1] != 2:
        raise ValueError(f"{key}: expected a list of [node, dof] pairs, got shape {s.shape}")
    nodes = as_index_array(s[:, 0], key, n_nodes, "node")
    dofs = as_index_array(s[:, 1], key + " (dof)", dim, "dof")
    return np.unique(dim * nodes + dofs)


def check_contact_free(fixed_dofs: np.ndarray, contact_nodes: np.ndarray, dim: int,
                       key: str = "model.supports") -> None:
    """ValueError if a contact node has a supported (fixed) DOF: contact DOFs must be free."""
    if len(fixed_dofs) == 0:
        return
    cd = (dim * contact_nodes[:, None] + np.arange(dim)).ravel()
    hit = np.isin(cd, fixed_dofs)
    if hit.any():
        j = int(np.flatnonzero(hit)[0])
        i = j // dim
        raise ValueError(f"{key}: contact node {int(contact_nodes[i])} (contact position {i}) has fixed dof {j % dim}; "
                         "contact DOFs must be free")
