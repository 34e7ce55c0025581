"""K_ii factored once with PETSc (MUMPS or its native LU) and solved for dense right-hand sides
(`factored`): the only module that imports petsc4py (`petsc`). condense.py forms the Schur
complement with it; a serial run's factorisation runs in a forked child (condense's
`CHILD_MIN_DOFS`), as PETSc keeps the interpreter's lock for the whole call.
"""
from __future__ import annotations

import os
from contextlib import contextmanager

import numpy as np
import scipy.sparse as sp


#: a pivot |p| <= NULL_PIVOT_RTOL * ||A|| (MUMPS, after scaling) or <= NULL_PIVOT_RTOL * row sum
#: (PETSc native LU) is taken as zero: K_ii singular. A K_ii that ill-conditioned would leave
#: fewer than ~4 correct digits in K_local anyway.
NULL_PIVOT_RTOL = 1e-12
#: PETSc error codes that mean "zero pivot / empty row" in a factorisation
_ZERO_PIVOT_ERRORS = {71, 73, 81}   # MAT_LU_ZRPVT, ARG_WRONGSTATE (missing diagonal), MAT_CH_ZRPVT


def singular(detail: str) -> ValueError:
    """The error of a singular K_ii (a mechanism apart from the contact nodes); detail: how it showed."""
    return ValueError(f"condense: the stiffness of the non-contact DOFs (K_ii) is singular ({detail}): "
                      "the body is a mechanism apart from its contact nodes (add bars/elements or supports)")


def petsc():
    """petsc4py's PETSc module, initialised for this process on first use (without PETSc's
    signal handlers; under mpirun on this rank alone)."""
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
    return "mumps" if petsc().Sys.hasExternalPackage("mumps") else "petsc"


@contextmanager
def factored(Kii: sp.csr_matrix, solver: str | None, probe: np.ndarray, comm=None,
              symmetrise: bool = False):
    """Factor K_ii once with PETSc (MUMPS or native LU, see condense.condense) and yield
    solve(B (n_loc, q) dense) -> the same rows of K_ii^-1 B. Collective over the mpi4py
    communicator `comm` (None: PETSc.COMM_SELF): Kii (n_loc, n) is this rank's block of
    consecutive rows (all n rows serially; ranks in order), B and the result likewise.
    `probe` (n_loc,): a right-hand side solved once to detect a failed factorisation.
    symmetrise: factor 0.5 (K_ii + K_ii^T) (PETSc transpose and add: exactly symmetric, for
    rows that are symmetric up to rounding only, e.g. condense._distributed_blocks with patches).
    Every PETSc object is destroyed on exit."""
    if solver not in (None, "mumps", "petsc"):
        raise ValueError(f"condense: unknown solver {solver!r} (mumps, petsc)")
    PETSc = petsc()
    comm = PETSc.COMM_SELF if comm is None else comm
    nloc, n = Kii.shape
    A = petsc_matrix(PETSc, Kii, comm, symmetrise)
    ksp = PETSc.KSP().create(comm=comm)
    objs = [A, ksp]
    try:
        pc, use_mumps = _choose_factorisation(PETSc, ksp, A, solver)
        F = _factorise(PETSc, ksp, pc, use_mumps, n)
        _solve_probe(ksp, A, probe, objs)
        yield _dense_solver(PETSc, F, nloc, n, comm)
    finally:
        for o in objs:
            o.destroy()


def petsc_matrix(PETSc, Kii: sp.csr_matrix, comm, symmetrise: bool):
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
    """Set up `ksp` as a direct solve of A (see condense.condense for the choice of solver); returns
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


def _factorise(PETSc, ksp, pc, use_mumps: bool, n: int):
    """Factor K_ii (ksp.setUp) and return the factor; ValueError if K_ii is singular (a zero
    or null pivot), RuntimeError for another PETSc or MUMPS failure."""
    try:
        ksp.setUp()
    except PETSc.Error as e:
        if e.ierr in _ZERO_PIVOT_ERRORS:
            raise singular(f"PETSc error {e.ierr}: zero pivot or empty row in the factorisation") from None
        raise RuntimeError(f"condense: PETSc error {e.ierr} while factoring K_ii ({n} DOFs)") from None
    F = pc.getFactorMatrix()
    if use_mumps:
        info = F.getMumpsInfog(1)
        if info == -10:
            raise singular("MUMPS INFOG(1) = -10")
        if info == -2 and F.getMumpsInfog(2) == 0:
            raise singular("no stiffness at all, MUMPS INFOG(1) = -2")
        if info < 0:
            raise RuntimeError(f"condense: MUMPS failed, INFOG(1) = {info}, INFOG(2) = {F.getMumpsInfog(2)}")
        nnull = F.getMumpsInfog(28)
        if nnull > 0:
            raise singular(f"{nnull} null pivot(s) found by MUMPS")
    return F


def _solve_probe(ksp, A, probe: np.ndarray, objs: list) -> None:
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
        raise singular(f"factorisation failed, KSP reason {reason}")


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
