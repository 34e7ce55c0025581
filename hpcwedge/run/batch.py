"""One batch run of a scene (`hpcwedge run`): its lifecycle around the pipeline, in one place.

run_batch, called by every rank, in order:

1. Which rank serves: a serial process, or rank 0 of an MPI world, is the master (Batch);
   ranks >= 1 print nothing, join the collective start-up (condense_on_ranks), then serve
   tasks (parallel.worker.serve) until the master stops them.
2. The master's signal handlers (Engine.install_signals: SIGUSR1 checkpoints and goes on,
   SIGTERM/SIGINT checkpoint and stop); a stop that came before them is replayed.
3. The scene loaded; the output checked, taken through a symbolic link to its target,
   locked (files.OutputLock); the temp file of a result write a kill -9 cut short removed.
4. Resume: continue from the checkpoint beside the output (--resume), or leave a result
   already complete for this scene as it is (the workers released), or start afresh.
5. The start-up, collective over the ranks under mpirun (condense_on_ranks: the model
   condensed together when run.condense asks), then the pipeline (pipeline.run_scene).
6. The result written atomically, the checkpoint removed. A result that cannot be written
   leaves the state in the checkpoint when it can (Batch.output_lost).
7. A stop (errors.Interrupted): the checkpoint written, one line, EXIT_INTERRUPTED (75).

A failure the user can fix leaves as an errors.UserError (the command line: one line, exit
status 2; under mpirun the job ends by MPI_Abort, as workers may wait in the start-up). On
every way out the engine is closed and the lock released.
"""
from __future__ import annotations

import os
import signal
import sys
import time

from hpcwedge.contact.build import build_model, contact_problem
from hpcwedge.errors import Interrupted, UserError
from hpcwedge.files import OutputLock, check_output, checkpoint_path, error_reason, refuse_not_ours, remove_if_there
from hpcwedge.parallel.engine import EXIT_INTERRUPTED, Engine
from hpcwedge.parallel.mpi import world
from hpcwedge.parallel.worker import serve
from hpcwedge.progress import Progress
from hpcwedge.results.hdf5 import result_state, write_result
from hpcwedge.results.record import Result
from hpcwedge.run.pipeline import noted_condensation, run_scene
from hpcwedge.run.stages import Condensed
from hpcwedge.scene.parse import Scene, changed_settings, load_scene

#: modules a worker imports before its first task (the task handlers' heavy imports),
#: while the master condenses
WORKER_MODULES = ("hpcwedge.patterns.job", "hpcwedge.mu_c.critical", "hpcwedge.rays.faces",
                  "hpcwedge.mu_c.global_search")
#: run.condense = "auto" condenses collectively over all ranks from this many model DOFs on
DISTRIBUTED_MIN_DOFS = 2_000_000


def run_batch(scene_path: str, output: str, resume: bool = False, quiet: bool = False,
              early_stops: list[int] | None = None) -> int:
    """Solve the scene at `scene_path` into the result file `output`, as this process's rank
    (module doc). Returns the exit status: 0 (the result written, or already complete for
    this scene with --resume), EXIT_INTERRUPTED (stopped by a signal; the checkpoint written
    when there was work to save). Raises UserError for a failure the user can fix. resume:
    continue from the checkpoint OUTPUT.ckpt if there is one; quiet: no progress on stderr;
    early_stops: SIGUSR1 and stop signals received before the call, acted on (and taken
    from the list) once the handlers are in (replay_early)."""
    comm = world()
    if comm is not None and comm.rank != 0:
        with open(os.devnull, "w") as null:     # workers print nothing; the master reports
            os.dup2(null.fileno(), 1)
        condense_on_ranks(None, comm)
        serve(comm, WORKER_MODULES)
        return 0
    return Batch(output, resume, quiet, comm).run(scene_path, [] if early_stops is None else early_stops)


def condense_on_ranks(scene: Scene | None, comm, progress: Progress | None = None) -> Condensed | None:
    """The collective start-up of an MPI run, called by every rank before the engine's work:
    the master passes the scene (None: no run, the workers are released), the workers None.
    Every rank builds the model from the scene the master broadcasts and condenses it with
    condense.condense_distributed when run.condense = "distributed", or "auto" and the model
    has >= DISTRIBUTED_MIN_DOFS DOFs. Returns the Condensed on the master if it did, else
    None (then the pipeline condenses on the master alone, as serially, and reports any error
    in the scene or model there). A singular K_ii is found on every rank alike: SceneError on
    the master, None on the workers. Ranks never wait on each other for ever: a model that
    fails to build on any rank sends everyone on. progress (the master's): where the
    condensation of a large model is announced (pipeline.noted_condensation)."""
    if comm.rank == 0 and scene is not None and (not scene.plan().condense or scene.condense == "serial"):
        scene = None
    scene = comm.bcast(scene, root=0)
    if scene is None:
        return None
    t = time.perf_counter()
    try:
        model = build_model(scene)
    except Exception:                            # noqa: BLE001  (the master's own run reports it)
        model = None
    if comm.allreduce(int(model is None)):      # a sum: on any rank
        return None
    if scene.condense == "auto" and model.n_dofs < DISTRIBUTED_MIN_DOFS:
        return None
    try:
        with noted_condensation(model, progress, f", over {comm.size} ranks"):
            problem = contact_problem(scene, model, comm)
    except UserError:
        if comm.rank == 0:
            raise
        return None
    return Condensed(model, problem, time.perf_counter() - t) if comm.rank == 0 else None


def replay_early(engine: Engine, early: list[int]) -> None:
    """Signals received before the handlers were in, acted on now (and taken from `early`):
    a SIGUSR1 asks for a checkpoint; of the stops, the last is acted on (it raises)."""
    if signal.SIGUSR1 in early:
        engine.signals.replay(signal.SIGUSR1)
    stops = [s for s in early if s != signal.SIGUSR1]
    early.clear()
    if stops:
        engine.signals.replay(stops[-1])


class Batch:
    """The master's side of one batch run: its engine (serial when comm is None), progress,
    output file, checkpoint path and lock."""

    def __init__(self, output: str, resume: bool, quiet: bool, comm=None):
        self.output, self.resume, self.quiet = output, resume, quiet
        self.ckpt = checkpoint_path(output)
        self.progress = Progress(quiet=quiet)
        self.engine = Engine(comm, progress=None if quiet else self.progress)
        self.lock = None

    def run(self, scene_path: str, early_stops: list[int]) -> int:
        """Steps 2-7 of the module doc; the exit status (run_batch)."""
        engine = self.engine
        engine.install_signals()
        try:
            try:
                replay_early(engine, early_stops)
                # an error up to the collective start-up ends an mpirun job by MPI_Abort (cli)
                scene = self.load(scene_path)
                if not self.start(scene):
                    return 0
                result = self.solve(scene)
            except Interrupted as e:
                return self.stopped(e)
        finally:
            engine.close(restore_signals=False)
            if self.lock is not None:
                self.lock.release()
        if not self.quiet:
            mu_c = "null" if result.mu_c is None else f"{result.mu_c:.12g}"
            print(f"[hpcwedge] {scene.name}: mu_c = {mu_c}; wrote {self.output} "
                  f"({result.timings['total']:.2f} s)", file=sys.stderr)
        return 0

    def load(self, scene_path: str) -> Scene:
        """The scene loaded; the output checked and locked (through a symbolic link: the
        lock, the checkpoint and the result are the target's)."""
        scene = load_scene(scene_path)
        check_output(self.output, (scene_path, *scene.input_files), replaces_hdf5_only=True)
        if os.path.islink(self.output):
            # a second run on the link went unlocked; the link became a file
            self.output = os.path.realpath(self.output)
            self.ckpt = checkpoint_path(self.output)
        refuse_not_ours(self.ckpt, hdf5_ok=True)     # the checkpoint beside it is written too
        self.lock = OutputLock(self.output)
        # the temp file of a result write that a kill -9 cut short (under the lock: ours)
        remove_if_there(self.output + ".tmp")
        return scene

    def start(self, scene: Scene) -> bool:
        """Resume from the checkpoint (--resume, and there is one), or start afresh (a note when
        a checkpoint there will be replaced). False: nothing to do, as the output is complete
        for this scene and its input files already (--resume of a finished run; the workers
        released)."""
        engine, ckpt = self.engine, self.ckpt
        engine.progress_every_s = self.progress.every = scene.progress_every_s
        if engine.use_checkpoint(ckpt, scene.hash, scene.text, scene.checkpoint_every_s, self.resume,
                                 inputs=scene.input_digests, changed_settings=changed_settings):
            done = engine.checkpoints
            self.progress.note(f"resuming from {ckpt} (session {done.resumes + 1}; "
                               f"{done.elapsed_before:.1f} s of work before it)")
            if done.changed_settings:
                self.progress.note(f"{', '.join(done.changed_settings)} differ from the checkpoint's "
                                   "scene (settings of the run, not of its answers)")
        elif self.resume and result_state(self.output, scene) == "complete":
            # a requeued or chained job whose run has finished: nothing to redo
            print(f"[hpcwedge] {self.output} is already complete for this scene and its input "
                  "files; nothing to do (remove it to recompute)", file=sys.stderr)
            if engine.comm is not None:
                condense_on_ranks(None, engine.comm)
                engine.serving = True
            return False
        elif os.path.exists(ckpt):
            print(f"[hpcwedge] note: {ckpt} exists and will be replaced "
                  f"({'it is missing' if self.resume else 'use --resume to continue from it'})",
                  file=sys.stderr)
        return True

    def solve(self, scene: Scene) -> Result:
        """The start-up (collective under mpirun: after the signal handlers, before anything is
        written), the pipeline, the result written, the checkpoint removed."""
        engine, condensed = self.engine, None
        if engine.comm is not None:
            condensed = condense_on_ranks(scene, engine.comm, self.progress)
            engine.serving = True                # the workers have gone on to serve tasks
        result = run_scene(scene, self.progress, engine=engine, condensed=condensed)
        try:
            write_result(self.output, result, tmp_path=self.output + ".tmp")
        except (OSError, RuntimeError) as e:     # h5py: RuntimeError for some failed writes
            raise UserError(self.output_lost(e)) from None
        engine.remove_checkpoint()
        engine.mark_done()
        return result

    def output_lost(self, err: Exception) -> str:
        """The message for a result that could not be written at the end of a run, after saving
        the engine's state as a checkpoint (if it can) so that --resume does not redo the work."""
        why = error_reason(err)
        try:
            kept = self.engine.write_checkpoint("output failed")
        except Exception as e:                  # noqa: BLE001  (the disk that refused the result)
            return (f"{self.output}: cannot write the result ({why}); the checkpoint could not be "
                    f"written either ({error_reason(e)}): the work is lost")
        if not kept:
            return f"{self.output}: cannot write the result ({why})"
        self.engine.mark_done()
        return f"{self.output}: cannot write the result ({why}); state kept in {self.ckpt}; rerun with --resume"

    def stopped(self, stop: Interrupted) -> int:
        """A stop signal: the checkpoint written when there is work to save, one line saying
        what is kept, the workers stopped; EXIT_INTERRUPTED."""
        engine, ckpt = self.engine, self.ckpt
        written = engine.write_checkpoint(str(stop))
        engine.mark_done()
        if written:
            what = f"checkpoint written to {ckpt}; rerun with --resume to continue"
        elif os.path.isfile(ckpt):
            what = f"no new checkpoint; the previous one, {ckpt}, is kept: rerun with --resume"
        else:
            what = "stopped before any checkpointable work"
        print(f"[hpcwedge] {stop}: {what}", file=sys.stderr, flush=True)
        if not engine.serving:
            # stopped before the collective start-up: the workers wait in it and would
            # never read a stop message (the job hung, the workers spinning in MPI)
            sys.stdout.flush()
            engine.comm.Abort(EXIT_INTERRUPTED)
        # the handlers stay SIG_IGN (mark_done): a second SIGTERM now must not kill a run
        # whose checkpoint is written (exit 143 after 'checkpoint written')
        engine.close(timeout=5.0, restore_signals=False)
        return EXIT_INTERRUPTED
