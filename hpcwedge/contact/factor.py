"""K_ii factored once with PETSc (MUMPS or its native LU) and solved for dense right-hand sides
(`factored`): the only module that imports petsc4py (`petsc`). condense.py forms the Schur
complement with it.

petsc4py keeps the interpreter's lock for a whole PETSc call, so no signal handler runs until
it returns. A large factorisation on one process runs in a child process (condense's
`CHILD_MIN_DOFS`, `SPAWN_MIN_DOFS`). A collective one (over an MPI communicator) cannot:
there the two long calls, KSPSetUp (the factorisation) and MatMatSolve, are made through
ctypes, which lets go of the lock, in a thread while this one waits in steps
(dense.interruptible: `_released`). A call given up on runs on in the background with its
objects kept alive, and is never destroyed under it; the run that gave it up is ending (an MPI
run's master aborts the job).
"""
from __future__ import annotations

import ctypes
import functools
import os
import sys
from contextlib import contextmanager

import numpy as np
import scipy.sparse as sp

from hpcwedge import dense


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
    import petsc4py
    # -no_signal_handler: PETSc's handler would take SIGPIPE (and SIGHUP, SIGSEGV, ...) from
    # Python: a progress reader gone (`hpcwedge run ... 2>&1 | head`) ended the run with
    # PETSc's status 59, no result and the output lock left behind; the signals a run
    # answers (SIGTERM, SIGUSR1, SIGINT) are the engine's. The command line is not PETSc's.
    args = ["-no_signal_handler"]
    # petsc4py routes PETSc's printing through Python when sys.stdout or sys.stderr is not
    # the original stream at its start (the command line wraps stderr; a worker's stdout is
    # /dev/null), without taking the interpreter's lock: a `_released` call that printed
    # would crash. Started with the original streams, PETSc writes to the file descriptors.
    saved = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = sys.__stdout__, sys.__stderr__
    try:
        return _initialised(petsc4py, args)
    finally:
        sys.stdout, sys.stderr = saved


def _initialised(petsc4py, args: list):
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
    released = comm is not PETSc.COMM_SELF and _library() is not None
    try:
        pc, use_mumps = _choose_factorisation(PETSc, ksp, A, solver)
        F = _factorise(PETSc, ksp, pc, use_mumps, n, released)
        _solve_probe(ksp, A, probe, objs)
        yield _dense_solver(PETSc, F, nloc, n, comm, released)
    finally:
        _destroy(objs)


#: PETSc objects of a `_released` call given up on while it still runs: never destroyed
_IN_USE: list = []


def _destroy(objs: list) -> None:
    """Destroy the PETSc objects, but none that a released call given up on still uses."""
    for o in objs:
        if not any(o is u for u in _IN_USE):
            o.destroy()


@functools.cache
def _library():
    """The PETSc shared library petsc4py loaded (ctypes), or None where it cannot be found
    (not Linux: then every call is made through petsc4py)."""
    try:
        with open("/proc/self/maps") as f:
            paths = {line.split()[-1] for line in f if "/libpetsc" in line}
    except OSError:
        return None
    for path in sorted(paths):
        if ".so" in os.path.basename(path):
            return ctypes.CDLL(path)
    return None


def _released(name: str, *objects) -> int:
    """PETSc's C function `name` on the objects (petsc4py objects, passed by handle), in a thread
    while this one waits in steps serving signals (module doc). Returns PETSc's error code."""
    fn = getattr(_library(), name)
    fn.restype = ctypes.c_int
    fn.argtypes = [ctypes.c_void_p] * len(objects)
    finished = []

    def call() -> int:
        ierr = fn(*(o.handle for o in objects))
        finished.append(True)
        return ierr
    try:
        return dense.interruptible(call)
    finally:
        if not finished:
            _IN_USE.extend(objects)


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


def _factorise(PETSc, ksp, pc, use_mumps: bool, n: int, released: bool = False):
    """Factor K_ii (KSPSetUp; released: through `_released`) and return the factor; ValueError
    if K_ii is singular (a zero or null pivot), RuntimeError for another PETSc or MUMPS failure."""
    if released:
        ierr = _released("KSPSetUp", ksp)
    else:
        try:
            ksp.setUp()
            ierr = 0
        except PETSc.Error as e:
            ierr = e.ierr
    if ierr in _ZERO_PIVOT_ERRORS:
        raise singular(f"PETSc error {ierr}: zero pivot or empty row in the factorisation")
    if ierr:
        raise RuntimeError(f"condense: PETSc error {ierr} while factoring K_ii ({n} DOFs)")
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


def _dense_solver(PETSc, F, nloc: int, n: int, comm, released: bool = False):
    """solve(B (n_loc, q) dense) -> this rank's rows of K_ii^-1 B, by MatMatSolve with the factor
    F (released: through `_released`)."""
    def solve(B: np.ndarray) -> np.ndarray:
        q = B.shape[1]
        Bm = PETSc.Mat().createDense(((nloc, n), (None, q)), array=np.asfortranarray(B, dtype=float),
                                     comm=comm)
        Xm = PETSc.Mat().createDense(((nloc, n), (None, q)), comm=comm)
        try:
            Xm.setUp()
            Bm.assemble()
            Xm.assemble()
            if not released:
                F.matSolve(Bm, Xm)
            elif ierr := _released("MatMatSolve", F, Bm, Xm):
                raise RuntimeError(f"condense: PETSc error {ierr} while solving with the factor of K_ii")
            return np.array(Xm.getDenseArray())
        finally:
            _destroy([Bm, Xm])

    return solve
