"""Static condensation (Schur complement) of a Model onto its contact DOFs, in local frames.

K_ii is factored by contact/factor.py (PETSc). `condense` is serial (PETSc.COMM_SELF; from
CHILD_MIN_DOFS interior DOFs on in a child process, so that a signal is served while PETSc
factors);
`condense_distributed` is the same condensation collective over an MPI communicator
(K_ii an MPIAIJ matrix, rows split between the ranks, each rank assembling only its own rows
of a continuum model, factored by parallel MUMPS).

    K_local = T (K_cc - K_ci K_ii^-1 K_ic) T^T      (dim*m, dim*m), block ordering (SPEC §1)
    N_local = orth(T R_c)                           (dim*m, k), R_c = rigid modes on contact DOFs

with supports applied (fixed DOFs dropped), c = contact DOFs (node-major), i = the other free
DOFs, T = model.local_map(). A model with contact patches (model.tie, models/patch.py) is
condensed in its reduced DOFs: K = Q^T K Q with Q = model.tie.T, the slave DOFs dropped and
the feet's rotation DOFs (ids n_dofs, n_dofs + 1, ...) added to i. `interior_response` reads the condensation backwards
(u_i = -K_ii^-1 K_ic u_c) with the same factorisation routine (factor.factored).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hpcwedge import forked
from hpcwedge.contact.factor import factored, petsc, petsc_matrix, singular, solver_name  # noqa: F401
from hpcwedge.models.matrix import RIGID_RTOL as RIGID_RTOL_K
from hpcwedge.models.matrix import SYM_RTOL, StiffnessFile
from hpcwedge.models.record import Model, check_contact_free
from hpcwedge.models.rigid import orthonormalise

#: ||K_local N_local|| <= RIGID_RTOL ||K_local|| is required of the result (free bodies)
RIGID_RTOL = 1e-7


@dataclass(frozen=True)
class DofSplit:
    """Which DOFs are condensed out and how the contact DOFs are rotated.

    contact:  (dim*m,) global contact DOFs, node-major (model.contact_dofs()).
    interior: (n_i,) free (unsupported) non-contact global DOFs, ascending (with contact
              patches: no slave DOF, then the rotation DOFs n_dofs, n_dofs + 1, ...).
    T:        (dim*m, dim*m) global node-major contact DOFs -> local block ordering.
    Rc:       (dim*m, k) the model's rigid modes restricted to the contact DOFs.
    """

    contact: np.ndarray
    interior: np.ndarray
    T: np.ndarray
    Rc: np.ndarray


def split_dofs(model: Model) -> DofSplit:
    """Partition the DOFs of `model` (shared by the PETSc and the dense route)."""
    check_contact_free(np.asarray(model.fixed_dofs), np.asarray(model.contact_nodes), model.dim)
    c = model.contact_dofs()
    keep = np.ones(model.n_dofs, dtype=bool)
    keep[np.asarray(model.fixed_dofs, dtype=np.int64)] = False
    keep[c] = False
    interior = np.flatnonzero(keep)
    if model.tie is not None:
        keep[model.tie.slave_dofs] = False
        interior = np.concatenate([np.flatnonzero(keep),
                                   model.n_dofs + np.arange(model.tie.n_rotations, dtype=np.int64)])
    return DofSplit(contact=c, interior=interior, T=model.local_map(), Rc=model.rigid_modes[c])


def reduced_stiffness(model: Model) -> sp.csr_matrix:
    """model.K, or Q^T K Q (Q = model.tie.T) for a model with contact patches: the stiffness
    in the DOFs that split_dofs numbers."""
    K = sp.csr_matrix(model.K)
    if model.tie is None:
        return K
    Q = model.tie.T
    Kr = (Q.T @ K @ Q).tocsr()
    Kr = (0.5 * (Kr + Kr.T)).tocsr()          # exactly symmetric (MUMPS LDL^T needs it)
    Kr.sort_indices()
    return Kr


def _blocks(model: Model, sp_: DofSplit, lo: int = 0, hi: int | None = None):
    """Kcc (p, p) dense, Kic (hi-lo, p) CSR, Kii (hi-lo, n_i) CSR, p = dim*m (node-major contact
    DOFs): the interior rows [lo, hi) (default all) of K_ic and K_ii."""
    K = reduced_stiffness(model)
    Kcc = K[sp_.contact][:, sp_.contact].toarray()
    Ki = K[sp_.interior[lo:hi]]
    return Kcc, Ki[:, sp_.contact].tocsr(), Ki[:, sp_.interior].tocsr()


def _distributed_blocks(model: Model, sp_: DofSplit, lo: int, hi: int):
    """`_blocks(model, sp_, lo, hi)` for one rank of condense_distributed, plus a flag: whether
    K_ii still needs symmetrising (0.5 (K_ii + K_ii^T), done on the assembled parallel matrix).

    A model with element data (model.assembly) never assembles the whole K here: the contact
    rows and this rank's interior rows come from the elements incident to their nodes
    (assembly.rows: bit for bit the rows of the whole K, so K_ii is exactly symmetric across
    the ranks). With contact patches (Q = model.tie.T), rows D of Q^T K Q are
    Q[R, D]^T K[R] Q, R the full DOFs of Q's columns D (the DOFs themselves, their patches'
    slaves, or a hat's master): only K[R] is assembled. Those rows are symmetric up to
    rounding only, so K_cc and K_ic are symmetrised here from the contact rows (every rank
    has them) and K_ii by the caller. Models without element data (trusses, hand-made K):
    `_blocks`, from the whole K.
    """
    if model.assembly is None:
        return (*_blocks(model, sp_, lo, hi), False)
    c, mine = sp_.contact, sp_.interior[lo:hi]
    p = c.size
    D = np.concatenate([c, mine])
    if model.tie is None:
        B = model.assembly.rows(D)
        Bi = B[p:]
        return B[:p][:, c].toarray(), Bi[:, c].tocsr(), Bi[:, sp_.interior].tocsr(), False
    Q = model.tie.T
    QD = Q.T.tocsr()[D]                                     # (|D|, n_dofs): columns D of Q
    R = np.unique(QD.indices)
    B = ((QD[:, R] @ model.assembly.rows(R)) @ Q).tocsr()    # rows D of Q^T K Q
    Bc, Bi = B[:p], B[p:]
    Kcc = Bc[:, c].toarray()
    Kic = (0.5 * (Bi[:, c] + Bc[:, mine].T)).tocsr()
    return 0.5 * (Kcc + Kcc.T), Kic, Bi[:, sp_.interior].tocsr(), True


def load_petsc(path: str, comm=None, rows: tuple[int, int] | None = None) -> sp.csr_matrix:
    """A PETSc binary matrix read by PETSc's MatLoad, collective over the mpi4py communicator
    `comm` (None: this process alone): this rank's rows [rows[0], rows[1]) (default all) as CSR
    (rows[1] - rows[0], N), global columns. The ranks' row ranges must be consecutive."""
    PETSc = petsc()
    viewer = PETSc.Viewer().createBinary(path, "r", comm=PETSc.COMM_SELF if comm is None else comm)
    A = PETSc.Mat().create(comm=viewer.getComm())
    try:
        if rows is not None:
            A.setSizes(((rows[1] - rows[0], None), (rows[1] - rows[0], None)))
        A.setType(PETSc.Mat.Type.AIJ)
        A.load(viewer)
        lo, hi = A.getOwnershipRange()
        indptr, indices, data = A.getValuesCSR()
        return sp.csr_matrix((data, indices, indptr), shape=(hi - lo, A.getSize()[1]))
    finally:
        A.destroy()
        viewer.destroy()


def _loaded_blocks(model: Model, sp_: DofSplit, comm):
    """`_distributed_blocks` of a stiffness in a PETSc binary file (models.matrix.StiffnessFile):
    rank r loads the rows [r N / P, (r+1) N / P) of K with MatLoad (never the whole K), checks
    them (`_check_loaded`), and keeps its interior rows; the contact rows are gathered on every
    rank. K_cc and K_ic are symmetrised from the contact rows, K_ii by the caller (flag True)."""
    src, N, P, r = model.assembly, model.n_dofs, comm.size, comm.rank
    g0, g1 = N * r // P, N * (r + 1) // P
    B = load_petsc(src.path, comm, (g0, g1))
    B.data = np.ldexp(B.data, -src.exponent)
    _check_loaded(B, model, comm)
    c, interior = sp_.contact, sp_.interior
    mine = interior[np.searchsorted(interior, g0):np.searchsorted(interior, g1)]
    here = c[(c >= g0) & (c < g1)]
    pieces = comm.allgather((here, B[here - g0]))
    ids = np.concatenate([h for h, _ in pieces])
    Bc = sp.vstack([b for _, b in pieces]).tocsr()[np.argsort(ids)[np.searchsorted(np.sort(ids), c)]]
    Bi = B[mine - g0]
    Kcc = Bc[:, c].toarray()
    Kic = (0.5 * (Bi[:, c] + Bc[:, mine].T)).tocsr()
    return 0.5 * (Kcc + Kcc.T), Kic, Bi[:, interior].tocsr(), True


def _check_loaded(B: sp.csr_matrix, model: Model, comm) -> None:
    """The checks of models.matrix (check_stiffness, check_rigid) on the ranks' rows B of K,
    collectively: ValueError naming model.K on every rank alike when K holds a NaN, is all zero,
    is not symmetric to SYM_RTOL (PETSc's MatIsSymmetric on the parallel matrix), or does not
    annihilate the model's rigid modes to RIGID_RTOL."""
    bad_ranks = comm.allreduce(int(not np.all(np.isfinite(B.data))))
    if bad_ranks:
        raise ValueError("model.K: NaN or infinite entries")
    scale = comm.allreduce(float(np.abs(B.data).max()) if B.nnz else 0.0, op=_mpi_max())
    if scale == 0:
        raise ValueError("model.K: all zero")
    PETSc = petsc()
    A = petsc_matrix(PETSc, B, comm, symmetrise=False)
    try:
        symmetric = A.isSymmetric(SYM_RTOL * scale)
    finally:
        A.destroy()
    if not symmetric:
        raise ValueError(f"model.K: not symmetric (|K - K^T| above {SYM_RTOL:g} max |K| = {SYM_RTOL * scale:.3g})")
    R = model.rigid_modes
    if R.shape[1]:
        res = comm.allreduce(float(np.abs(B @ R).max()) if B.shape[0] else 0.0, op=_mpi_max()) / scale
        if res > RIGID_RTOL_K:
            raise ValueError(f"model.K: does not annihilate the {R.shape[1]} rigid mode(s) of model.nodes and "
                             f"model.supports (relative residual {res:.1e}): a support or a spring to ground "
                             "that model.supports does not list, or nodes that are not K's")


def _mpi_max():
    from mpi4py import MPI
    return MPI.MAX


def to_local(model: Model, sp_: DofSplit, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotate the condensed (global, node-major) S into K_local, symmetrise, and build N_local."""
    T = sp_.T
    KL = T @ S @ T.T
    KL = 0.5 * (KL + KL.T)
    k = sp_.Rc.shape[1]
    if k:
        N = orthonormalise(T @ sp_.Rc, expect_rank=k,
                           what="condense: rigid modes restricted to the contact DOFs")
        scale = max(np.abs(KL).max(), 1e-300)
        res = np.abs(KL @ N).max() / scale
        if res > RIGID_RTOL:
            raise ValueError(f"condense: the condensed stiffness does not annihilate the rigid modes "
                             f"(relative residual {res:.2e}): K_ii is (nearly) singular or the model's "
                             "rigid modes do not match K")
    else:
        N = np.zeros((KL.shape[0], 0))
    return KL, N


def schur_dense(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """(K_local, N_local) by dense numpy linear algebra (independent check of condense; small models)."""
    sp_ = split_dofs(model)
    Kcc, Kic, Kii = _blocks(model, sp_)
    if sp_.interior.size == 0:
        return to_local(model, sp_, Kcc)
    A = Kii.toarray()
    lam = np.linalg.eigvalsh(0.5 * (A + A.T))
    if lam[0] <= 1e-14 * lam[-1]:
        raise singular(f"smallest/largest eigenvalue {lam[0] / lam[-1]:.2e}")
    X = np.linalg.solve(A, Kic.toarray())
    return to_local(model, sp_, Kcc - Kic.T.toarray() @ X)


def condense(model: Model, solver: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(K_local (dim*m, dim*m) symmetric PSD, N_local (dim*m, k) orthonormal) via PETSc.

    K_ii is factored once by a sparse direct solver: solver None = MUMPS if this PETSc has it,
    else "petsc" (PETSc's native LU, nested-dissection ordering); or force "mumps" / "petsc".
    MUMPS uses its symmetric LDL^T factorisation when K_ii is exactly symmetric, else LU.
    The dim*m contact columns are solved for with MatMatSolve, COLUMN_BLOCK at a time.
    ValueError if K_ii is singular (null pivot) or the result does not annihilate the model's
    rigid modes.
    """
    return condense_distributed(model, None, solver)


def condense_distributed(model: Model, comm=None, solver: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """`condense`, collective over the mpi4py communicator `comm` (None: this process alone).

    Every rank of `comm` calls it with the same `model`. Rank r assembles the rows
    [r n_i / P, (r+1) n_i / P) of K_ii (and of K_ic) into a parallel PETSc MPIAIJ matrix on
    `comm`: with a comm, a model with element data (model.assembly: continuum meshes, with or
    without contact patches) assembles only these rows and the contact rows, from the elements
    incident to their nodes, never the whole K (`_distributed_blocks`); a stiffness in a PETSc
    binary file (models.matrix.StiffnessFile) is read by MatLoad, rank r its rows
    [r N / P, (r+1) N / P) only (`_loaded_blocks`); other models (trusses,
    hand-made K) and comm None slice them from the whole model.K (comm None: exactly as
    before, bit for bit). K_ii is factored once by parallel MUMPS ("petsc" native LU is serial
    only: ValueError with more than one rank); each rank multiplies its rows of X = K_ii^-1 K_ic by
    its rows of K_ic, and the (dim*m)^2 partial sums are allreduced. Every rank returns the
    same (K_local, N_local), equal to `condense`'s up to rounding. Errors (singular K_ii, rigid
    modes) are raised on every rank alike.
    """
    sp_ = split_dofs(model)
    n = sp_.interior.size
    size, rank = (1, 0) if comm is None else (comm.size, comm.rank)
    if size > 1 and solver == "petsc":
        raise ValueError("condense: the native PETSc LU is serial; use MUMPS with more than one rank")
    lo, hi = n * rank // size, n * (rank + 1) // size
    if comm is None:
        (Kcc, Kic, Kii), symmetrise = _blocks(model, sp_, lo, hi), False
    elif isinstance(model.assembly, StiffnessFile):
        Kcc, Kic, Kii, symmetrise = _loaded_blocks(model, sp_, comm)
    else:
        Kcc, Kic, Kii, symmetrise = _distributed_blocks(model, sp_, lo, hi)
    if n == 0:
        return to_local(model, sp_, Kcc)
    return to_local(model, sp_, Kcc - _kci_kii_inv_kic(Kic, Kii, solver, comm, symmetrise))


#: contact columns per MatMatSolve (bounds the two dense n_i x COLUMN_BLOCK work arrays)
COLUMN_BLOCK = 64
#: from this many interior DOFs on, a condensation on one process factors K_ii in a child
#: process (`_here_or_forked`; block2d refine 40, 33,000 DOFs: ~0.5 s to factor, ~0.05 s to
#: fork, ~1 s to start an interpreter)
CHILD_MIN_DOFS = 20_000
#: where a fork is not safe (an MPI run's master), from this many interior DOFs on in a spawned
#: interpreter instead: it costs ~0.6-1.2 s to start (numpy, scipy, PETSc), about what
#: factoring ~30,000 DOFs takes; from here on the factorisation alone takes ~2 s or more
SPAWN_MIN_DOFS = 80_000
def _kci_kii_inv_kic(Kic: sp.csr_matrix, Kii: sp.csr_matrix, solver: str | None,
                     comm=None, symmetrise: bool = False) -> np.ndarray:
    """K_ci K_ii^-1 K_ic (p, p), global node-major contact DOFs, on every rank of `comm`.
    Kic (n_loc, p), Kii (n_loc, n_i): this rank's rows (all rows serially); symmetrise: factor
    0.5 (K_ii + K_ii^T) (see factor.factored). Serially from CHILD_MIN_DOFS interior DOFs on, in a
    child process (`_here_or_forked`)."""
    if comm is None:
        return _here_or_forked(_kci_kii_inv_kic_here, Kic, Kii, solver, None, symmetrise)
    return _kci_kii_inv_kic_here(Kic, Kii, solver, comm, symmetrise)


def _here_or_forked(fn, a, Kii, *args):
    """fn(a, Kii, *args) in this process, or for a large K_ii in a child process (PETSc's
    factorisation keeps the interpreter's lock, so a signal waited for it; there it is served
    within a step): forked from CHILD_MIN_DOFS rows on where that is safe (forked.in_child: no
    MPI or PETSc started here, as in a serial run, which condenses before anything else), else
    a fresh interpreter from SPAWN_MIN_DOFS rows on (forked.in_spawned: the master of an MPI
    run). The same bits either way."""
    if Kii.shape[0] >= CHILD_MIN_DOFS and forked.can_fork():
        return forked.in_child(fn, a, Kii, *args, what="condense")
    if Kii.shape[0] >= SPAWN_MIN_DOFS and forked.can_spawn():
        return forked.in_spawned(fn, a, Kii, *args, what="condense")
    return fn(a, Kii, *args)


def _kci_kii_inv_kic_here(Kic: sp.csr_matrix, Kii: sp.csr_matrix, solver: str | None,
                          comm=None, symmetrise: bool = False) -> np.ndarray:
    """`_kci_kii_inv_kic` in this process."""
    p = Kic.shape[1]
    probe = Kic[:, 0].toarray().ravel()
    with factored(Kii, solver, probe=probe, comm=comm, symmetrise=symmetrise) as solve:
        P = np.zeros((p, p))
        KicT = Kic.T.tocsr()
        for lo in range(0, p, COLUMN_BLOCK):
            hi = min(p, lo + COLUMN_BLOCK)
            P[:, lo:hi] = KicT @ solve(Kic[:, lo:hi].toarray())
    if comm is not None and comm.size > 1:
        P = comm.allreduce(P)
    return P


def interior_response(model: Model, uc: np.ndarray, solver: str | None = None) -> np.ndarray:
    """Interior DOFs u_i = -K_ii^-1 K_ic u_c of a body whose contact DOFs are displaced by u_c.

    uc: (dim*m,) or (dim*m, q) global contact DOFs, node-major (model.contact_dofs()).
    Returns (n_i,) or (n_i, q) on split_dofs(model).interior (supported DOFs are zero and not
    included; with contact patches, reduced DOFs: expand with model.tie.T). This is the
    static condensation read backwards: with these u_i, K u = f has
    f = 0 at every free non-contact DOF. K_ii is factored exactly as by `condense` (same
    solver choice and null-pivot checks; ValueError if singular).
    """
    sp_ = split_dofs(model)
    _, Kic, Kii = _blocks(model, sp_)
    U = np.asarray(uc, dtype=float)
    B = -(Kic @ U.reshape(len(sp_.contact), -1))
    X = B if sp_.interior.size == 0 else _here_or_forked(_kii_inv, B, Kii, solver)
    return X.ravel() if U.ndim == 1 else X


def _kii_inv(B: np.ndarray, Kii: sp.csr_matrix, solver: str | None) -> np.ndarray:
    """K_ii^-1 B (n_i, q), B (n_i, q) dense, serially."""
    with factored(Kii, solver, probe=B[:, 0]) as solve:
        return np.hstack([solve(B[:, lo:lo + COLUMN_BLOCK]) for lo in range(0, B.shape[1], COLUMN_BLOCK)])

