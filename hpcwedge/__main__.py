"""python -m hpcwedge: the command line (same as the console script)."""
import signal
import sys

# a checkpoint request (SIGUSR1, which mpirun forwards to every rank) while the modules load
# must not kill the run (status 138, no word): ignored from here, then cli.main's handlers
signal.signal(signal.SIGUSR1, signal.SIG_IGN)

try:
    from hpcwedge.cli import main
except KeyboardInterrupt:                       # Ctrl-C while Python starts: as cli.main does
    sys.stderr.write("hpcwedge: error: interrupted (nothing written)\n")
    sys.exit(130)

sys.exit(main())
