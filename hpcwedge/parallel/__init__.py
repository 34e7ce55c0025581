"""The parallel layer (SPEC §5): tasks, jobs, the engine that runs them serially or
over MPI (master / workers), and its checkpoints. One job per module:

- tasks.py: the registry kind -> "module:function" and task cancellation
  (task_stopping, task_tick; no MPI: the engines import it). Kinds: "subtree"
  (patterns.explore_task), "mu_c" (mu_critical.mu_c_task), "face" (faces.face_task),
  "global_bracket" (global_mu_c.bracket_task).
- jobs.py: SubtreeJob (budgeted branch and bound), TaskJob (independent tasks),
  their checkpoint encoding.
- engine.py: Engine.run(job) — in-process, or the master under mpirun — with
  checkpoints and signals; run_tasks.
- worker.py: serve(comm), the loop of ranks >= 1.
- mpi.py: world(), probing without spinning, the wire's tags, ranks_on_host.
- checkpoint.py: the checkpoint file and the Checkpointer of a run.
"""
from .checkpoint import CheckpointError, Checkpointer, checkpoint_path, read_checkpoint, write_checkpoint
from .engine import EXIT_INTERRUPTED, Engine, run_tasks
from .jobs import DEFAULT_BUDGET, Patterns, SubtreeJob, TaskJob, decode_rays, encode_rays
from ..progress import ranks_on_host
from .mpi import ParallelError, world
from .tasks import (Interrupted, TaskCancelled, handler_for, register, registered, task_stopping, task_tick)
from .worker import serve

__all__ = ["CheckpointError", "Checkpointer", "checkpoint_path", "read_checkpoint", "write_checkpoint",
           "EXIT_INTERRUPTED", "Engine", "run_tasks", "DEFAULT_BUDGET", "Patterns", "SubtreeJob", "TaskJob",
           "decode_rays", "encode_rays", "ParallelError", "ranks_on_host", "world",
           "Interrupted", "TaskCancelled", "handler_for", "register", "registered", "task_stopping", "task_tick",
           "serve"]
