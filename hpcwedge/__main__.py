"""python -m hpcwedge: the command line (same as the console script)."""
import signal
import sys

# a checkpoint request (SIGUSR1, which mpirun forwards to every rank) while the modules load
# must not kill the run (status 138, no word): kept from here and handed to cli.main's handlers
_early: list = []
signal.signal(signal.SIGUSR1, lambda signum, frame: _early.append(signum))

try:
    from hpcwedge.cli import main
except KeyboardInterrupt:                       # Ctrl-C while Python starts: as cli.main does
    sys.stderr.write("hpcwedge: error: interrupted (nothing written)\n")
    sys.exit(130)

from hpcwedge import cli  # noqa: E402  (loaded above)

cli.EARLY_SIGNALS.extend(_early)
sys.exit(main())
