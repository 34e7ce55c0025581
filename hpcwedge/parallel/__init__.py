"""The parallel engine (SPEC §5): runs jobs serially or over MPI (a master and its workers),
with checkpoints and signals. It knows nothing of wedging: a job hands it tasks and a
handler (a module-level callable, sent to the workers by reference), and merges the
results. Importing this package loads nothing; each module is imported by name:

- cancel.py: what a running task polls (task_stopping, task_tick, task_pausing) and how a long
  task hands back its progress (Continuation); no MPI, no HDF5.
- jobs.py: the job protocol; TaskJob (a fixed list of independent tasks) and TreeJob (a
  budgeted tree search whose open nodes go back to the pool).
- schedule.py: how much work one message to a worker carries (batches, budget scales).
- engine.py: Engine.run(job), in-process or as the master under mpirun; run_tasks.
- signals.py: the master's signals (checkpoint and go on; checkpoint and stop).
- hub.py: hubs, a second level that serves the workers of a tree job at scale.
- worker.py: serve(comm), the loop of ranks >= 1.
- mpi.py: world(), probing without spinning, the wire's tags.
- checkpoint.py: the checkpoint file and the Checkpointer of a run.
"""

__all__ = ["cancel", "jobs", "schedule", "engine", "signals", "hub", "worker", "mpi", "checkpoint"]
