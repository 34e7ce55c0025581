"""hpcwedge: wedged configurations of elastic bodies in frictional contact (Fujita & Kanno 2010).

Importing it sets the thread policy (environment.py): one BLAS/OpenMP thread, whatever the
caller's settings, so that the float bits of a result do not depend on them (SPEC §5).
"""
import sys
import types

from .environment import set_thread_variables

set_thread_variables()
__version__ = "0.1.0"

#: the public API (api.py), imported on first use so that `import hpcwedge` stays light
#: (no numpy: the thread policy above must come before the libraries load)
__all__ = ["Scene", "SceneError", "FileError", "Result", "Run", "solve", "read_result", "write_result",
           "plot", "export_vtu", "DEFAULT_MU", "__version__"]


def __getattr__(name: str):
    if name in __all__:
        from . import api
        return getattr(api, name)
    raise AttributeError(f"module 'hpcwedge' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))



class _Package(types.ModuleType):
    """This package: importing a submodule that shares a public name (hpcwedge.plot) must
    not rebind that name, or `hw.plot` would turn from api.plot into the module once the
    module is imported (api.plot itself imports it)."""

    def __setattr__(self, name: str, value) -> None:
        if name in __all__ and isinstance(value, types.ModuleType):
            return              # the submodule is in sys.modules; hw.<name> stays the API's
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
