"""The program's errors: one base, and what each kind means to the command line.

- `HpcwedgeError`: every error this program raises on purpose.
- `UserError`: a failure the user can fix (a scene key, a file, an index): the command
  line prints one line `hpcwedge: error: ...` and exits 2; under mpirun a worker sends it
  to the master as such. `SceneError`, `FileError`, `CheckpointError`, ... derive from it.
- `Interrupted`: a stop signal (SIGTERM/SIGINT) reached the run; a BaseException, like
  KeyboardInterrupt, so that handlers turning a library's errors into one line do not
  take a stop for one. The command line writes the checkpoint and exits 75.
"""


class HpcwedgeError(Exception):
    """Base of every error hpcwedge raises on purpose."""


class UserError(HpcwedgeError, ValueError):
    """A failure the user can fix: one line naming the key or file, exit status 2."""


class Interrupted(BaseException):
    """SIGTERM/SIGINT reached the master: write the checkpoint and stop (exit status 75)."""


__all__ = ["HpcwedgeError", "UserError", "Interrupted"]
