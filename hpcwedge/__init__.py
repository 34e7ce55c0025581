"""hpcwedge: wedged configurations of elastic bodies in frictional contact (Fujita & Kanno 2010).

Importing it sets the thread policy (environment.py): one BLAS/OpenMP thread, whatever the
caller's settings, so that the float bits of a result do not depend on them (SPEC §5).
"""
from .environment import set_thread_variables

set_thread_variables()
__version__ = "0.1.0"
