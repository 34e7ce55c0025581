"""python -m hpcwedge: the command line (same as the console script)."""
import sys

try:
    from .cli import main
except KeyboardInterrupt:                       # Ctrl-C while Python starts: as cli.main does
    sys.stderr.write("hpcwedge: error: interrupted (nothing written)\n")
    sys.exit(130)

sys.exit(main())
