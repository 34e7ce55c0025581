"""The numerical environment: hpcwedge's thread policy, and the record of what a run ran on.

Thread policy (SPEC §5: the same float bits for any rank count, budget or resume on one
machine, whatever the caller's BLAS thread settings). Every BLAS, LAPACK and OpenMP kernel
runs on **one thread**; parallelism comes from MPI ranks only. OpenBLAS's rounding
depends on its thread count (plug2d m = 12, the ray vectors `X @ U.T`: 127 entries differ
by up to 5.6e-17 between a serial run and mpirun on an EPYC without AVX-512, issue 11;
156 between 1 and 2 threads with OpenBLAS's Haswell kernels on ours), and that count
differs between a serial run (every core), a rank Open MPI binds to one core, and
oversubscribed unbound ranks. So:

- the command line (`cli.main`, first in every process of a run and of mpirun, before numpy
  loads) sets THREAD_VARIABLES to "1" in os.environ, *overriding* the caller's
  values; the libraries read them when they load (numpy's and scipy's OpenBLAS, PETSc's
  OpenMP), and child processes inherit them;
- Clarabel's settings ask for one thread (`solvers/conic.settings`: its faer LDL, chosen
  for larger KKT systems, otherwise starts a thread per core, and Rust's rayon pools read
  RAYON_NUM_THREADS, set here too);
- `single_threaded()` limits the libraries that are loaded already (a notebook that
  imported numpy before hpcwedge) with threadpoolctl, for the duration of a block;
  pipeline.run_scene runs inside it.

The policy covers the command line (every rank) and run_scene. A caller who wants more
BLAS threads for their own numpy work after importing hpcwedge sets them with
threadpoolctl; run_scene still runs on one. (Engine functions called directly, outside
run_scene, in a process that loaded numpy first run at the caller's setting.)

Within one machine the bits then depend on nothing the caller sets except what changes
the kernels themselves (OPENBLAS_CORETYPE, NPY_DISABLE_CPU_FEATURES): those select other
SIMD code, like another CPU, and give the same answers with floats equal to rounding
(tests/test_environment.py runs the determinism and numerics tests under them).

`environment()` is the record stored as a result's stats["environment"] and in every
benchmark JSON: package versions, the BLAS libraries (threadpoolctl: library, version,
core type, threads), numpy's SIMD extensions and the CPU. It holds nothing that differs
between the ranks of one job or between a serial run and mpirun on one machine.
"""
from __future__ import annotations

import contextlib
import functools
import os
import platform
from collections.abc import Iterator

#: thread-count variables of the BLAS / OpenMP runtimes, all set to "1" (see module doc)
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                    "BLIS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "RAYON_NUM_THREADS")

#: the distributions whose versions the record lists (besides hpcwedge and python)
PACKAGES = ("numpy", "scipy", "clarabel", "h5py", "mpi4py", "petsc4py", "threadpoolctl")


def set_thread_variables() -> None:
    """Set every THREAD_VARIABLES entry to "1" in os.environ (the thread policy for
    libraries loaded from now on, and for child processes)."""
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"


@contextlib.contextmanager
def single_threaded() -> Iterator[None]:
    """Run the block with every BLAS / OpenMP library loaded in this process limited to
    one thread (threadpoolctl); the previous limits are restored afterwards."""
    from threadpoolctl import threadpool_limits
    with threadpool_limits(limits=1):
        yield


def environment() -> dict:
    """What the run ran on (JSON-ready): {"hpcwedge", "python", "packages" {name: version
    or None}, "blas" [{"library", "api", "version", "architecture", "threading", "threads"}
    per loaded BLAS, by library name], "numpy_simd" (the SIMD extensions numpy dispatches
    to here), "cpu" {"model", "logical_cpus"}, "platform"}. The same in every rank of a job
    on one machine (no pid, host name, affinity or time)."""
    import scipy.linalg  # noqa: F401  (loads the BLAS of numpy and scipy, the ones to record)
    from threadpoolctl import threadpool_info
    blas = sorted(({"library": os.path.basename(lib.get("filepath") or ""),
                    "api": lib.get("internal_api"), "version": lib.get("version"),
                    "architecture": lib.get("architecture"),
                    "threading": lib.get("threading_layer"), "threads": lib.get("num_threads")}
                   for lib in threadpool_info() if lib.get("user_api") == "blas"),
                  key=lambda b: b["library"])
    return {**_static(), "blas": blas, "numpy_simd": _numpy_simd()}


@functools.cache
def _static() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    from hpcwedge.version import __version__

    def ver(name: str) -> str | None:
        try:
            return version(name)
        except PackageNotFoundError:
            return None
    return {"hpcwedge": __version__, "python": platform.python_version(),
            "packages": {name: ver(name) for name in PACKAGES},
            "cpu": {"model": _cpu_model(), "logical_cpus": os.cpu_count()},
            "platform": platform.platform()}


def _cpu_model() -> str:
    """The first "model name" of /proc/cpuinfo (Linux); elsewhere platform.processor()."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                key, _, value = line.partition(":")
                if key.strip() == "model name":
                    return value.strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _numpy_simd() -> list[str]:
    """The SIMD targets numpy dispatches to in this process: its baseline and the
    dispatched extensions this CPU has and NPY_DISABLE_CPU_FEATURES leaves on."""
    from numpy._core import _multiarray_umath as umath
    features = umath.__cpu_features__
    return list(umath.__cpu_baseline__) + [t for t in umath.__cpu_dispatch__ if features.get(t)]
