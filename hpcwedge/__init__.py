"""hpcwedge: wedged configurations of elastic bodies in frictional contact (Fujita & Kanno 2010).

The public API is `hpcwedge.api`, re-exported here on first use (so that `import hpcwedge`
loads no numpy). The package, bottom to top (data flow one way; tests/test_layout.py
holds every import to this order):

- errors, version, nodesets, exact, files, environment, progress: leaves.
- parallel/: the engine (serial, or master and workers over MPI), its jobs, cancellation and
  checkpoints; it knows nothing of wedging.
- models/: bodies (trusses, meshes, built-ins, stiffness matrices from other FE codes) as a Model record.
- scene/: the table of scene keys, TOML -> a validated Scene.
- contact/: Scene -> Model -> ContactProblem (condensation with PETSc).
- results/: the Result record (runs, typed cones and patterns) and its HDF5 file.
- solvers/: a pattern's feasibility problem on Clarabel, HiGHS and CLP (one status map
  each), and `decide`.
- rays/: 2D rays and cones; patterns/: 3D sign patterns; mu_c/: mu^c of each, and global.
- post/: configurations, figures, VTU.
- run/: the pipeline and a batch run's lifecycle; api.py, cli.py: the faces.
"""
from hpcwedge.version import __version__

__all__ = ["Scene", "SceneError", "FileError", "Result", "Run", "Cone", "Pattern", "NOT_COMPUTED", "ContactProblem",
           "solve", "contact_problem", "read_result", "write_result", "plot", "export_vtu", "DEFAULT_MU",
           "__version__"]


def __getattr__(name: str):
    if name in __all__:
        from hpcwedge import api
        return getattr(api, name)
    raise AttributeError(f"module 'hpcwedge' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
