"""Command line (SPEC §4): hpcwedge run | show | plot | export."""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys


def main(argv: list[str] | None = None) -> int:
    # a checkpoint request (SIGUSR1, forwarded by mpirun to every rank) that arrives
    # during start-up must not kill a rank: ignored until the master's handler is in.
    # Called in-process (argv given), every handler is put back on return; as the
    # program (argv None), the handlers stay to the exit: a signal after the result
    # is written must not turn a finished run into a failed one.
    import threading
    main_thread = threading.current_thread() is threading.main_thread()
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGUSR1, signal.SIGTERM, signal.SIGINT)
             } if main_thread and argv is not None else {}
    if main_thread:
        signal.signal(signal.SIGUSR1, signal.SIG_IGN)
    p = argparse.ArgumentParser(prog="hpcwedge", description="Wedged configurations and critical friction "
                                "coefficients of elastic bodies in frictional contact.")
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="solve a scene and write RESULT.h5")
    r.add_argument("scene")
    r.add_argument("-o", "--output", required=True)
    r.add_argument("--resume", action="store_true",
                   help="continue from the checkpoint RESULT.h5.ckpt if it exists (else start afresh)")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    s = sub.add_parser("show", help="print a result")
    s.add_argument("result")
    s.add_argument("--json", action="store_true", help="one JSON object (SPEC §4)")
    s.add_argument("--no-rays", action="store_true", help="leave the ray vectors out of the JSON")
    pl = sub.add_parser("plot", help="draw a wedged configuration and the cones' / patterns' mu^c")
    pl.add_argument("result")
    pl.add_argument("-o", "--output", required=True)
    pl.add_argument("--run", type=int, default=-1, help="run index (default: the last)")
    pl.add_argument("--ray", type=int, help="2D: wedged ray to draw (default 0)")
    pl.add_argument("--pattern", type=int, help="3D: sign pattern to draw (default 0)")
    ex = sub.add_parser("export", help="write one configuration of the whole body as a VTU file (ParaView)",
                        description="Recover every node's displacement, the contact reactions and the "
                        "element stresses (von Mises / bar axial force) of one item of a result, on the "
                        "body rebuilt from the stored scene, and write them as a VTK XML unstructured grid.")
    ex.add_argument("result")
    ex.add_argument("-o", "--output", required=True, help="the .vtu file to write")
    ex.add_argument("--run", type=int, default=-1, help="run index (default: the last)")
    item = ex.add_mutually_exclusive_group(required=True)
    item.add_argument("--ray", type=int, help="2D: wedged ray J")
    item.add_argument("--cone", type=int, help="2D: cone J (the mean of its wedged rays)")
    item.add_argument("--pattern", type=int, help="sign pattern J (a feasible point at the run's mu)")
    try:
        args = p.parse_args(argv)
        return {"run": _run, "show": _show, "plot": _plot, "export": _export}[args.cmd](args)
    except _UserError as e:
        print(f"hpcwedge: error: {e}", file=sys.stderr)
        return 2
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)


class _UserError(Exception):
    pass


#: run.condense = "auto" condenses collectively over all ranks from this many model DOFs on
DISTRIBUTED_MIN_DOFS = 2_000_000


def _condense_together(comm, path: str | None):
    """The distributed condensation of an MPI run (run.condense, SCENE §run): collective over
    `comm`, called by every rank before the task engine starts; the master passes the scene
    path, workers None. Every rank builds the model from the scene the master broadcasts and
    condenses it with condense.condense_distributed when run.condense = "distributed", or
    "auto" and the model has >= DISTRIBUTED_MIN_DOFS DOFs. Returns (model, problem, seconds)
    on the master if it did, else None (then the master condenses alone, as serially, and
    reports any error in the scene or model there). A singular K_ii is found on every rank
    alike: SceneError on the master, None on the workers. Ranks never wait on each other for
    ever: a model that fails to build on any rank sends everyone on."""
    import time

    from mpi4py import MPI

    from .build import build_model, contact_problem
    from .scene import SceneError, load_scene
    scene = None
    if comm.rank == 0:
        try:
            scene = load_scene(path)
        except SceneError:
            scene = None                         # reported by the master's own run
        if scene is not None and (not scene.plan().condense or scene.condense == "serial"):
            scene = None
    scene = comm.bcast(scene, root=0)
    if scene is None:
        return None
    t = time.perf_counter()
    try:
        model = build_model(scene)
    except Exception:                            # noqa: BLE001  (the master's own run reports it)
        model = None
    if not comm.allreduce(model is not None, op=MPI.LAND):
        return None
    if scene.condense == "auto" and model.n_dofs < DISTRIBUTED_MIN_DOFS:
        return None
    try:
        problem = contact_problem(scene, model, comm)
    except SceneError:
        if comm.rank == 0:
            raise
        return None
    return (model, problem, time.perf_counter() - t) if comm.rank == 0 else None


def _run(args) -> int:
    from .parallel import EXIT_INTERRUPTED, Engine, Interrupted, ParallelError, world
    try:
        comm = world()
    except ParallelError as e:
        raise _UserError(str(e)) from None
    if comm is not None and comm.rank != 0:
        sys.stdout = open(os.devnull, "w")      # workers print nothing; the master reports
        _condense_together(comm, None)
        Engine(comm).serve()
        return 0
    from .checkpoint import CheckpointError, checkpoint_path
    from .pipeline import run_scene
    from .progress import Progress
    from .results import write_result
    from .scene import SceneError, load_scene
    progress = Progress(quiet=args.quiet)
    engine = Engine(comm, progress=None if args.quiet else progress)
    engine.install_signals()
    ckpt = checkpoint_path(args.output)
    try:
        try:
            # collective (under mpirun): after the signal handlers, before anything is written
            condensed = _condense_together(comm, args.scene) if comm is not None else None
            scene = load_scene(args.scene)
            if engine.use_checkpoint(ckpt, scene.hash, scene.text, scene.checkpoint_every_s, args.resume,
                                     inputs=scene.input_digests):
                progress.note(f"resuming from {ckpt}")
            elif os.path.exists(ckpt):
                print(f"[hpcwedge] note: {ckpt} exists and will be replaced "
                      f"({'it is missing' if args.resume else 'use --resume to continue from it'})",
                      file=sys.stderr)
            result = run_scene(scene, progress, engine=engine, condensed=condensed)
            write_result(args.output, result)
            engine.remove_checkpoint()
            engine.mark_done()
        except (SceneError, CheckpointError) as e:
            raise _UserError(str(e)) from None
        except Interrupted as e:
            written = engine.write_checkpoint(str(e))
            engine.mark_done()
            print(f"[hpcwedge] {e}: " + (f"checkpoint written to {ckpt}; rerun with --resume to continue"
                                         if written else "stopped before any checkpointable work"),
                  file=sys.stderr)
            engine.close(timeout=5.0)
            return EXIT_INTERRUPTED
    finally:
        engine.close(restore_signals=False)
    if not args.quiet:
        mu_c = "null" if result.mu_c is None else f"{result.mu_c:.12g}"
        print(f"[hpcwedge] {scene.name}: mu_c = {mu_c}; wrote {args.output} "
              f"({result.timings['total']:.2f} s)", file=sys.stderr)
    return 0


def _read(path: str, with_rays: bool = True) -> dict:
    from .results import FileError, read_result
    try:
        return read_result(path, with_rays=with_rays)
    except FileError as e:
        raise _UserError(str(e)) from None


def _show(args) -> int:
    if args.json:
        from .results import FileError, dump_result_json
        _read(args.result, with_rays=False)
        try:
            dump_result_json(args.result, sys.stdout, with_rays=not args.no_rays)
        except FileError as e:
            raise _UserError(str(e)) from None
        return 0
    res = _read(args.result, with_rays=False)
    mu_c = "null" if res["mu_c"] is None else f"{res['mu_c']:.12g}"
    print(f"{res['name']}: dim {res['dim']}, m {res['m']}, mu_c = {mu_c}"
          + (f" ({res['mu_c_status']})" if res["mu_c_status"] else ""))
    print(f"{'mu':>8} {'wedged':>8} {'trivial':>8} {'cones':>6} {'patterns':>9}")
    for run in res["runs"]:
        cells = [run[k] for k in ("n_wedged_rays", "n_trivial_rays", "n_cones", "n_patterns")]
        print(f"{run['mu']:8.4g} " + " ".join(f"{'-' if v is None else v:>{w}}"
                                               for v, w in zip(cells, (8, 8, 6, 9))))
        for j, cone in enumerate(run["cones"] or []):
            mc = "-" if cone["mu_c"] is None else f"{cone['mu_c']:.12g}"
            print(f"         cone {j}: {len(cone['rays'])} rays, zero_u {cone['zero_u']}, "
                  f"zero_r {cone['zero_r']}, mu_c {mc}")
        for j, pat in enumerate(run["patterns"] or []):
            mc = "-" if pat["mu_c"] is None else f"{pat['mu_c']:.12g}"
            flag = " (undecided)" if pat.get("undecided") else ""
            print(f"         pattern {j}: contact {pat['contact']}, mu_c {mc}{flag}")
    t = res["timings"]
    print("timings: " + ", ".join(f"{k} {v:.3f} s" for k, v in t.items()))
    return 0


def _plot(args) -> int:
    from .plot import plot_result
    _read(args.result, with_rays=False)
    try:
        plot_result(args.result, args.output, run=args.run, ray=args.ray, pattern=args.pattern)
    except ValueError as e:
        raise _UserError(str(e)) from None
    return 0


def _export(args) -> int:
    from .configuration import ConfigurationError, load_configuration, write_vtu
    try:
        config = load_configuration(args.result, run=args.run, ray=args.ray, cone=args.cone,
                                    pattern=args.pattern)
    except ConfigurationError as e:
        raise _UserError(f"export: {e}") from None
    write_vtu(config, args.output)
    print(f"[hpcwedge] {config.label}: wrote {args.output}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
