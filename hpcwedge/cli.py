"""Command line (SPEC §4): hpcwedge run | show | plot | export.

This module reads the arguments and turns every error into one line and an exit status;
`run` is one batch run (run/batch.py: the lock, resume, signals, which rank serves).

Exit status: 0 done; 2 a failure the user can fix (one line `hpcwedge: error: ...` naming the
key or file); 75 stopped by a signal with a checkpoint; 1 an internal error (a bug: one line
naming the exception, HPCWEDGE_DEBUG=1 prints the traceback); 141 stdout closed by its reader.
A closed stderr (a progress reader gone, `hpcwedge run ... 2>&1 | head`) stops no command:
the lines meant for it are dropped and the run writes its result (`_Stderr`).
Under mpirun an error on any rank ends the whole job (MPI_Abort) with that status.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys

from hpcwedge.errors import Interrupted, UserError

#: stop signals received before the run's handlers were in (main -> run_batch)
#: SIGUSR1/SIGTERM received before the run's own handlers are in, replayed by run_batch
EARLY_SIGNALS: list = []


def main(argv: list[str] | None = None) -> int:
    """The program: `argv` (None: sys.argv) parsed and its command run; the exit status
    (module doc). Called with `argv`, every signal handler and sys.stderr are put back on
    return; as the program, the handlers stay to the exit (a signal after the result is
    written must not turn a finished run into a failed one)."""
    from hpcwedge.environment import set_thread_variables
    set_thread_variables()          # the thread policy (environment.py), before numpy loads
    # a checkpoint request (SIGUSR1, forwarded by mpirun to every rank) that arrives
    # during start-up must not kill a rank: kept for the master's handler (run_batch)
    import threading
    main_thread = threading.current_thread() is threading.main_thread()
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGUSR1, signal.SIGTERM, signal.SIGINT)
             } if main_thread and argv is not None else {}
    if main_thread:
        signal.signal(signal.SIGUSR1, lambda signum, frame: EARLY_SIGNALS.append(signum))
    stderr = sys.stderr
    sys.stderr = _Stderr(stderr)
    parser = _parser()
    try:
        code = _command(parser, argv, main_thread)
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)
        EARLY_SIGNALS.clear()
        if argv is not None:
            sys.stderr = stderr
    if code == 75 and argv is None and "mpi4py.MPI" not in sys.modules:
        _exit_now(code)
    return code


def _exit_now(code: int) -> None:
    """Exit at once after a stop of a serial run (the checkpoint is on disk): the exit
    handlers run, the interpreter's own teardown (1-2 s with numpy, scipy, h5py and the
    solvers loaded) is skipped, so that SIGTERM ends the process within SLURM's grace."""
    import atexit
    sys.stdout.flush()
    sys.stderr.flush()
    if "hpcwedge.solvers.lp" in sys.modules:    # a MILP left running ends with the process
        sys.modules["hpcwedge.solvers.lp"].release_left_running()
    atexit._run_exitfuncs()
    os._exit(code)


def _parser() -> argparse.ArgumentParser:
    """The command line's arguments: run, show, plot, export."""
    from hpcwedge.version import __version__
    p = _Parser(prog="hpcwedge", description="Wedged configurations and critical friction "
                "coefficients of elastic bodies in frictional contact.",
                epilog="Exit status: 0 done; 2 a failure you can fix (one line naming the key or "
                "file); 75 stopped by a signal, a checkpoint written (rerun with --resume); 1 an "
                "internal error (HPCWEDGE_DEBUG=1 prints the traceback).")
    p.add_argument("--version", action="version", version=f"hpcwedge {__version__}")
    sub = p.add_subparsers(dest="cmd", required=True, metavar="command")
    r = sub.add_parser("run", help="solve a scene and write RESULT.h5")
    r.add_argument("scene", help="the scene (TOML)")
    r.add_argument("-o", "--output", required=True, metavar="RESULT.h5", help="the result file to write (HDF5; an existing file is replaced only if it is empty or HDF5)")
    r.add_argument("--resume", action="store_true",
                   help="continue from the checkpoint RESULT.h5.ckpt if it exists (else start afresh)")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    s = sub.add_parser("show", help="print a result, or how far a checkpoint's run got")
    s.add_argument("result", help="a result file (HDF5) that `hpcwedge run` wrote, or its checkpoint "
                   "(RESULT.h5.ckpt)")
    s.add_argument("--json", action="store_true", help="one JSON object (SPEC §4)")
    s.add_argument("--no-rays", action="store_true", help="with --json: leave the ray vectors out")
    s.add_argument("--all", action="store_true", help="list every cone and pattern (default: a run with "
                   "more than 8 gives the first, the least mu^c and their spread)")
    pl = sub.add_parser("plot", help="draw a wedged configuration and the cones' / patterns' mu^c")
    pl.add_argument("result", help="a result file (HDF5) that `hpcwedge run` wrote")
    pl.add_argument("-o", "--output", required=True, help="the figure to write (its format from the suffix: .png, .pdf, .svg)")
    pl.add_argument("--run", type=int, default=-1, help="run J, numbered from 0 as `show` lists them "
                    "(default: the last, the largest mu)")
    pl.add_argument("--ray", type=int, help="2D: wedged ray to draw (default 0)")
    pl.add_argument("--pattern", type=int, help="3D: sign pattern to draw (default 0)")
    _export_arguments(sub)
    return p


def _export_arguments(sub) -> None:
    """The export command's arguments."""
    ex = sub.add_parser("export", help="write one configuration of the whole body as a VTU file (ParaView)",
                        description="Recover every node's displacement, the contact reactions and the "
                        "element stresses (von Mises / bar axial force) of one item of a result, on the "
                        "body rebuilt from the stored scene, and write them as a VTK XML unstructured grid.")
    ex.add_argument("result", help="a result file (HDF5) that `hpcwedge run` wrote")
    ex.add_argument("-o", "--output", required=True, help="the file to write (its name ends in .vtu)")
    ex.add_argument("--run", type=int, default=-1, help="run J, numbered from 0 as `show` lists them "
                    "(default: the last, the largest mu)")
    item = ex.add_mutually_exclusive_group(required=True)
    item.add_argument("--ray", type=int, help="2D: wedged ray J")
    item.add_argument("--cone", type=int, help="2D: cone J (the mean of its wedged rays)")
    item.add_argument("--pattern", type=int, help="sign pattern J (a feasible point at the run's mu)")


def _command(parser: argparse.ArgumentParser, argv: list[str] | None, main_thread: bool) -> int:
    """Parse `argv` and run its command; every error as one line and its exit status
    (SystemExit, argparse's --help and --version, goes through)."""
    try:
        args = parser.parse_args(argv)
        if main_thread and args.cmd == "run":
            # a stop signal before the run's own handlers are in (imports: ~0.4 s) is kept
            # for them (run_batch), not the default death with status 143 and no word
            signal.signal(signal.SIGTERM, lambda signum, frame: EARLY_SIGNALS.append(signum))
        return {"run": _run, "show": _show, "plot": _plot, "export": _export}[args.cmd](args)
    except UserError as e:                      # a scene key, a file, an index, a launch
        return _error(str(e), 2)
    except BrokenPipeError:
        return _broken_pipe()
    except KeyboardInterrupt:
        # Ctrl-C where no handler of ours is in (start-up, show, plot, export): nothing was
        # written (outputs are atomic); one line and the status of a process ended by SIGINT
        return _error("interrupted (nothing written)", 128 + signal.SIGINT)
    except Interrupted as e:                    # a stop outside run_batch's own handling of it
        return _error(f"{e}: stopped before any checkpointable work", 75)
    except Exception as e:                      # noqa: BLE001  (a bug: one line, the traceback on request)
        if os.environ.get("HPCWEDGE_DEBUG"):
            import traceback
            traceback.print_exc()
        what = (str(e).strip().splitlines() or [""])[0]
        return _error(f"internal error: {type(e).__name__}{': ' + what if what else ''} "
                      "(set HPCWEDGE_DEBUG=1 for the traceback)", 1)


class _Stderr:
    """sys.stderr that outlives its reader: once a write finds the pipe closed (EPIPE), the
    file descriptor is pointed at /dev/null and every later line is dropped, so that
    progress and notes never end a run (nor the interpreter's final flush complain)."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._silence()
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._silence()

    def _silence(self) -> None:
        _to_devnull(self._stream)
        self._stream = open(os.devnull, "w")

    def __getattr__(self, name):
        return getattr(self._stream, name)


class _UserError(UserError):
    """A failure the user can fix that the command line finds itself: `hpcwedge: error:
    <message>` on stderr, exit status 2."""


class _Parser(argparse.ArgumentParser):
    """argparse, with its usage errors as one line and exit status 2 (the usage is in --help)."""

    def error(self, message: str):
        # the command's name when a command's own arguments are wrong ("hpcwedge run: ...")
        where = "" if self.prog == "hpcwedge" else f"{self.prog}: "
        raise _UserError(f"{where}{message} (see {self.prog} --help)")


def _error(message: str, code: int) -> int:
    """Print `hpcwedge: error: message` (one line) and return `code`; under mpirun, end the
    whole job with it (MPI_Abort): the other ranks may be waiting in a collective call that
    this rank will never reach, and an error on any rank must not leave the job hanging."""
    print(f"hpcwedge: error: {' '.join(message.split())}", file=sys.stderr, flush=True)
    mpi = sys.modules.get("mpi4py.MPI")
    if mpi is not None and mpi.Is_initialized() and not mpi.Is_finalized() and mpi.COMM_WORLD.size > 1:
        sys.stdout.flush()
        mpi.COMM_WORLD.Abort(code)
    return code


def _broken_pipe() -> int:
    """stdout was closed by its reader (`hpcwedge show R.h5 | head`): stop quietly, as Unix
    tools do, with the status of a process ended by SIGPIPE (128 + 13); stdout is pointed at
    /dev/null so that the interpreter's final flush does not complain either."""
    _to_devnull(sys.stdout)
    return 128 + signal.SIGPIPE


def _to_devnull(stream) -> None:
    """Point the file descriptor of `stream` at /dev/null (a stream without one: nothing)."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, stream.fileno())
    except (OSError, ValueError):
        pass
    finally:
        os.close(devnull)


def _run(args) -> int:
    """hpcwedge run: one batch run (run/batch.py)."""
    from hpcwedge.run.batch import run_batch
    return run_batch(args.scene, args.output, resume=args.resume, quiet=args.quiet, early_stops=EARLY_SIGNALS)


def _read(path: str, with_rays: bool = True):
    from hpcwedge.files import FileError
    from hpcwedge.results.hdf5 import read_result
    try:
        return read_result(path, with_rays=with_rays)
    except FileError as e:
        raise _UserError(str(e)) from None


def _show(args) -> int:
    from hpcwedge.files import CheckpointGiven, FileError
    from hpcwedge.results.hdf5 import dump_result_json, read_result
    from hpcwedge.results.summary import show_lines
    if args.no_rays and not args.json:
        raise _UserError("show: --no-rays only applies with --json (the text summary has no rays)")
    try:
        if args.json:
            dump_result_json(args.result, sys.stdout, with_rays=not args.no_rays)
            return 0
        res = read_result(args.result, with_rays=False)
    except CheckpointGiven:
        return _show_checkpoint(args)
    except FileError as e:
        raise _UserError(str(e)) from None
    print("\n".join(show_lines(res, args.result, every_item=args.all)))
    return 0


def _show_checkpoint(args) -> int:
    """`show` of a checkpoint: how far its run got (parallel.checkpoint.checkpoint_summary)."""
    import json
    import time

    from hpcwedge.files import resume_hint
    from hpcwedge.parallel.checkpoint import CheckpointError, checkpoint_summary
    from hpcwedge.mu_c import saved
    from hpcwedge.patterns import job as patterns_job

    try:
        ck = checkpoint_summary(args.result,
                                lambda a, d: patterns_job.describe_saved(a, d) or saved.describe_saved(a, d))
    except CheckpointError as e:
        raise _UserError(str(e)) from None
    bounds = [j["mu_c_at_most"] for j in ck["jobs"] if j.get("mu_c_at_most") is not None]
    ck["mu_c_at_most"] = min(bounds) if bounds else None
    if args.json:
        print(json.dumps(ck))
        return 0
    when = (time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(ck["written_unix"]))
            if ck["written_unix"] == ck["written_unix"] else "?")
    sessions = ck["resumes"] + 1
    print(f"{args.result}: checkpoint of an unfinished run of {ck['name'] or '(unnamed scene)'}, "
          f"written {when} ({ck['reason'] or '?'})")
    print(f"work so far: {ck['elapsed_s']:.1f} s in {sessions} session{'s' * (sessions > 1)}, "
          f"last on {ck['ranks']} rank{'s' * (ck['ranks'] > 1)} (hpcwedge {ck['version']})")
    if ck["mu_c_at_most"] is not None:
        print(f"global mu^c so far: at most {ck['mu_c_at_most']:.12g} (the least certified mu^c of a "
              f"pattern found; the run goes on to look for a lower one)")
    for job in ck["jobs"]:
        state = "done" if job["finished"] else "in progress"
        if "found" in job:
            nodes = job["counters"].get("nodes", 0)
            mus = ", ".join(f"{v:g}" for v in job["mu"])
            what = (f"{job['found']} pattern(s) found, {job['open']} open subtree(s), "
                    f"{nodes:,} tree nodes, {100 * job['decided']:.3g} % of the tree decided (mu {mus})")
        else:
            what = f"{job['done']} of {job['tasks']} {job['kind']} task(s) done"
        print(f"  {job['name']}: {what}; {state}")
    print(f"to finish it: {resume_hint(args.result)}")
    return 0


def _plot(args) -> int:
    from hpcwedge.files import check_output
    from hpcwedge.post.plot import figure_format, plot_result
    check_output(args.output, (args.result,), figure_format)
    _read(args.result, with_rays=False)
    try:
        label = plot_result(args.result, args.output, run=args.run, ray=args.ray, pattern=args.pattern)
    except ValueError as e:
        raise _UserError(str(e)) from None
    except OSError as e:
        raise _cannot_write(args.output, e) from None
    print(f"[hpcwedge] {label}: wrote {args.output}", file=sys.stderr)
    return 0


def _cannot_write(output: str, e: OSError) -> _UserError:
    """The one line of an output that failed while written (a folder that refuses files
    although os.access allowed it, as /sys for root; a full disk): nothing is left, as
    files.replace_atomic removed its temp file."""
    from hpcwedge.files import error_reason
    return _UserError(f"{output}: cannot write ({error_reason(e)})")


def _export(args) -> int:
    from hpcwedge.files import check_output
    from hpcwedge.post.export import check_vtu_name, write_vtu
    from hpcwedge.post.recovery import ConfigurationError, load_configuration
    check_output(args.output, (args.result,), check_vtu_name)
    try:
        config = load_configuration(args.result, run=args.run, ray=args.ray, cone=args.cone,
                                    pattern=args.pattern)
    except ConfigurationError as e:
        raise _UserError(f"export: {e}") from None
    try:
        write_vtu(config, args.output)
    except OSError as e:
        raise _cannot_write(args.output, e) from None
    print(f"[hpcwedge] {config.label}: wrote {args.output}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
