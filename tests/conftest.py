"""The suite's process set-up, shared by every test folder (which mirror the package's).

pytest puts this folder on sys.path (the helpers: instances, mpi_helpers, ...). A suite
started with SIGINT ignored (`nohup make test &`, a CI runner) must test as one started
from a terminal: an ignored disposition survives exec, so every child the tests start
would ignore the SIGINT a test sends it. A handled one is reset to the default at exec.
"""
import signal

signal.signal(signal.SIGINT, signal.default_int_handler)
