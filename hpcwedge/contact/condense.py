"""Static condensation (Schur complement) of a Model onto its contact DOFs, in local frames.

The only module that imports petsc4py. `condense` is serial (PETSc.COMM_SELF);
`condense_distributed` is the same condensation collective over an MPI communicator
(K_ii an MPIAIJ matrix, rows split between the ranks, each rank assembling only its own rows
of a continuum model, factored by parallel MUMPS).

    K_local = T (K_cc - K_ci K_ii^-1 K_ic) T^T      (dim*m, dim*m), block ordering (SPEC §1)
    N_local = orth(T R_c)                           (dim*m, k), R_c = rigid modes on contact DOFs

with supports applied (fixed DOFs dropped), c = contact DOFs (node-major), i = the other free
DOFs, T = model.local_map(). A model with contact patches (model.tie, models/patch.py) is
condensed in its reduced DOFs: K = Q^T K Q with Q = model.tie.T, the slave DOFs dropped and
the feet's rotation DOFs (ids n_dofs, n_dofs + 1, ...) added to i. `interior_response` reads the condensation backwards
(u_i = -K_ii^-1 K_ic u_c) with the same factorisation routine (`_factored`).
"""
from __future__ import annotations

import os
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hpcwedge.models.matrix import RIGID_RTOL as RIGID_RTOL_K
from hpcwedge.models.matrix import SYM_RTOL, StiffnessFile
from hpcwedge.models.record import Model, check_contact_free
from hpcwedge.models.rigid import orthonormalise

#: a pivot |p| <= NULL_PIVOT_RTOL * ||A|| (MUMPS, after scaling) or <= NULL_PIVOT_RTOL * row sum
#: (PETSc native LU) is taken as zero: K_ii singular. A K_ii that ill-conditioned would leave
#: fewer than ~4 correct digits in K_local anyway.
NULL_PIVOT_RTOL = 1e-12
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
    PETSc = _petsc()
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
    PETSc = _petsc()
    A = _petsc_matrix(PETSc, B, comm, symmetrise=False)
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


def _singular(model: Model, detail: str) -> ValueError:
    return ValueError(f"condense: the stiffness of the non-contact DOFs (K_ii) is singular ({detail}): "
                      "the body is a mechanism apart from its contact nodes (add bars/elements or supports)")


def schur_dense(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """(K_local, N_local) by dense numpy linear algebra (independent check of condense; small models)."""
    sp_ = split_dofs(model)
    Kcc, Kic, Kii = _blocks(model, sp_)
    if sp_.interior.size == 0:
        return to_local(model, sp_, Kcc)
    A = Kii.toarray()
    lam = np.linalg.eigvalsh(0.5 * (A + A.T))
    if lam[0] <= 1e-14 * lam[-1]:
        raise _singular(model, f"smallest/largest eigenvalue {lam[0] / lam[-1]:.2e}")
    X = np.linalg.solve(A, Kic.toarray())
    return to_local(model, sp_, Kcc - Kic.T.toarray() @ X)


def _petsc():
    import sys

    import petsc4py
    # -no_signal_handler: PETSc's handler would take SIGPIPE (and SIGHUP, SIGSEGV, ...) from
    # Python: a progress reader gone (`hpcwedge run ... 2>&1 | head`) ended the run with
    # PETSc's status 59, no result and the output lock left behind; the signals a run
    # answers (SIGTERM, SIGUSR1, SIGINT) are the engine's. The command line is not PETSc's.
    args = ["-no_signal_handler"]
    if "mpi4py.MPI" in sys.modules:
        # under mpirun only the master condenses: PETSc's world must be this rank
        # alone (PetscInitialize is collective over its world)
        from mpi4py import MPI
        petsc4py.init(args, comm=MPI.COMM_SELF)
    else:
        # a serial run: PETSc starts MPI as a singleton that never talks to another process;
        # Open MPI's default message layer first probes UCX's devices for it (MPI_Init 0.28 s
        # here against 0.08 s with ob1). A user's own choice of the layer stands.
        os.environ.setdefault("OMPI_MCA_pml", "ob1")
        petsc4py.init(args)
    from petsc4py import PETSc
    return PETSc


def solver_name() -> str:
    """'mumps' if this PETSc has MUMPS, else 'petsc' (native sparse LU)."""
    return "mumps" if _petsc().Sys.hasExternalPackage("mumps") else "petsc"


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
    return to_local(model, sp_, Kcc - _kci_kii_inv_kic(Kic, Kii, model, solver, comm, symmetrise))


#: contact columns per MatMatSolve (bounds the two dense n_i x COLUMN_BLOCK work arrays)
COLUMN_BLOCK = 64
#: PETSc error codes that mean "zero pivot / empty row" in a factorisation
_ZERO_PIVOT_ERRORS = {71, 73, 81}   # MAT_LU_ZRPVT, ARG_WRONGSTATE (missing diagonal), MAT_CH_ZRPVT


def _kci_kii_inv_kic(Kic: sp.csr_matrix, Kii: sp.csr_matrix, model: Model, solver: str | None,
                     comm=None, symmetrise: bool = False) -> np.ndarray:
    """K_ci K_ii^-1 K_ic (p, p), global node-major contact DOFs, on every rank of `comm`.
    Kic (n_loc, p), Kii (n_loc, n_i): this rank's rows (all rows serially); symmetrise: factor
    0.5 (K_ii + K_ii^T) (see `_factored`)."""
    p = Kic.shape[1]
    probe = Kic[:, 0].toarray().ravel()
    with _factored(Kii, model, solver, probe=probe, comm=comm, symmetrise=symmetrise) as solve:
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
    if sp_.interior.size == 0:
        X = B
    else:
        with _factored(Kii, model, solver, probe=B[:, 0]) as solve:
            X = np.hstack([solve(B[:, lo:lo + COLUMN_BLOCK]) for lo in range(0, B.shape[1], COLUMN_BLOCK)])
    return X.ravel() if U.ndim == 1 else X


@contextmanager
def _factored(Kii: sp.csr_matrix, model: Model, solver: str | None, probe: np.ndarray, comm=None,
              symmetrise: bool = False):
    """Factor K_ii once with PETSc (MUMPS or native LU, see `condense`) and yield
    solve(B (n_loc, q) dense) -> the same rows of K_ii^-1 B. Collective over the mpi4py
    communicator `comm` (None: PETSc.COMM_SELF): Kii (n_loc, n) is this rank's block of
    consecutive rows (all n rows serially; ranks in order), B and the result likewise.
    `probe` (n_loc,): a right-hand side solved once to detect a failed factorisation.
    symmetrise: factor 0.5 (K_ii + K_ii^T) (PETSc transpose and add: exactly symmetric, for
    rows that are symmetric up to rounding only, e.g. `_distributed_blocks` with patches).
    Every PETSc object is destroyed on exit."""
    if solver not in (None, "mumps", "petsc"):
        raise ValueError(f"condense: unknown solver {solver!r} (mumps, petsc)")
    PETSc = _petsc()
    comm = PETSc.COMM_SELF if comm is None else comm
    nloc, n = Kii.shape
    A = _petsc_matrix(PETSc, Kii, comm, symmetrise)
    ksp = PETSc.KSP().create(comm=comm)
    objs = [A, ksp]
    try:
        pc, use_mumps = _choose_factorisation(PETSc, ksp, A, solver)
        F = _factorise(PETSc, ksp, pc, use_mumps, model, n)
        _solve_probe(ksp, A, probe, model, objs)
        yield _dense_solver(PETSc, F, nloc, n, comm)
    finally:
        for o in objs:
            o.destroy()


def _petsc_matrix(PETSc, Kii: sp.csr_matrix, comm, symmetrise: bool):
    """This rank's rows of K_ii as an assembled PETSc AIJ matrix on `comm`; symmetrise:
    replaced by 0.5 (A + A^T)."""
    Kii = sp.csr_matrix(Kii)
    Kii.sort_indices()
    nloc, n = Kii.shape
    A = PETSc.Mat().createAIJ(size=((nloc, n), (nloc, n)), csr=(Kii.indptr.astype(PETSc.IntType),
                                                Kii.indices.astype(PETSc.IntType), Kii.data), comm=comm)
    A.assemble()
    if symmetrise:
        At = PETSc.Mat()
        A.transpose(At)                      # into a new matrix (A.transpose() is in place)
        A.axpy(1.0, At, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        At.destroy()
        A.scale(0.5)
    return A


def _choose_factorisation(PETSc, ksp, A, solver: str | None):
    """Set up `ksp` as a direct solve of A (see `condense` for the choice of solver); returns
    (its PC, whether MUMPS factors)."""
    ksp.setOperators(A)
    ksp.setType("preonly")
    pc = ksp.getPC()
    use_mumps = solver == "mumps" or (solver is None and PETSc.Sys.hasExternalPackage("mumps"))
    # MUMPS: symmetric LDL^T (SYM = 2, with pivoting) when K_ii is exactly symmetric (as the
    # truss / Q4 assemblies guarantee): half the factor memory and ~35% less time than LU
    # (block2d refine 200, 8e5 DOFs). Otherwise, and natively, LU.
    symmetric = use_mumps and A.isSymmetric(0.0)
    pc.setType("cholesky" if symmetric else "lu")
    if use_mumps:
        pc.setFactorSolverType("mumps")
        pc.setFactorSetUpSolverType()
        F = pc.getFactorMatrix()
        F.setMumpsIcntl(24, 1)                 # detect null pivots ...
        F.setMumpsCntl(3, NULL_PIVOT_RTOL)     # ... |pivot| <= tol * ||A_pre||
    else:
        pc.setFactorSolverType("petsc")
        pc.setFactorOrdering("nd")
        pc.setFactorPivot(zeropivot=NULL_PIVOT_RTOL)
    return pc, use_mumps


def _factorise(PETSc, ksp, pc, use_mumps: bool, model: Model, n: int):
    """Factor K_ii (ksp.setUp) and return the factor; ValueError if K_ii is singular (a zero
    or null pivot), RuntimeError for another PETSc or MUMPS failure."""
    try:
        ksp.setUp()
    except PETSc.Error as e:
        if e.ierr in _ZERO_PIVOT_ERRORS:
            raise _singular(model, f"PETSc error {e.ierr}: zero pivot or empty row in the factorisation") from None
        raise RuntimeError(f"condense: PETSc error {e.ierr} while factoring K_ii ({n} DOFs)") from None
    F = pc.getFactorMatrix()
    if use_mumps:
        info = F.getMumpsInfog(1)
        if info == -10:
            raise _singular(model, "MUMPS INFOG(1) = -10")
        if info == -2 and F.getMumpsInfog(2) == 0:
            raise _singular(model, "no stiffness at all, MUMPS INFOG(1) = -2")
        if info < 0:
            raise RuntimeError(f"condense: MUMPS failed, INFOG(1) = {info}, INFOG(2) = {F.getMumpsInfog(2)}")
        nnull = F.getMumpsInfog(28)
        if nnull > 0:
            raise _singular(model, f"{nnull} null pivot(s) found by MUMPS")
    return F


def _solve_probe(ksp, A, probe: np.ndarray, model: Model, objs: list) -> None:
    """Solve A x = probe once; ValueError (singular K_ii) if the factorisation failed. Its two
    vectors are appended to `objs`, for the caller to destroy."""
    # petsc4py 3.18 has no PCGetFailedReason: a failed factorisation shows as a KSP
    # solve that diverges with DIVERGED_PC_FAILED (native LU flags small pivots this way)
    b, x = A.createVecLeft(), A.createVecRight()
    objs += [b, x]
    b.setArray(np.asarray(probe, dtype=float))
    ksp.solve(b, x)
    reason = ksp.getConvergedReason()
    if reason < 0:
        raise _singular(model, f"factorisation failed, KSP reason {reason}")


def _dense_solver(PETSc, F, nloc: int, n: int, comm):
    """solve(B (n_loc, q) dense) -> this rank's rows of K_ii^-1 B, by MatMatSolve with the factor F."""
    def solve(B: np.ndarray) -> np.ndarray:
        q = B.shape[1]
        Bm = PETSc.Mat().createDense(((nloc, n), (None, q)), array=np.asfortranarray(B, dtype=float),
                                     comm=comm)
        Xm = PETSc.Mat().createDense(((nloc, n), (None, q)), comm=comm)
        try:
            Xm.setUp()
            Bm.assemble()
            Xm.assemble()
            F.matSolve(Bm, Xm)
            return np.array(Xm.getDenseArray())
        finally:
            Bm.destroy()
            Xm.destroy()

    return solve
