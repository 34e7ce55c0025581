"""How the master cuts work into messages (hpcwedge/parallel/schedule.py), a TreeJob's budget
at each pool length (jobs.TreeJob.take), and an idle worker's sleep cap (mpi.worker_poll_max),
against values worked out by hand."""
import time

import pytest

from hpcwedge.parallel import mpi, schedule
from hpcwedge.parallel.jobs import BUDGET_SCALE, TreeJob


def test_cut_batches_tasks_or_grows_them_by_the_pool_and_the_masters_need():
    m = schedule.MESSAGE_S / schedule.MAX_BUSY        # seconds of master time per worker and message
    assert schedule.cut(8, None, 10 ** 6) == (1, 1)                 # nothing measured yet: one task
    assert schedule.cut(8, 8 * m / 5, 10 ** 6) == (5, 1)            # a TaskJob: a batch of 5
    assert schedule.cut(8, 8 * m / 5, 10 ** 6, max_scale=16) == (1, 16)   # a long pool: scale 16
    assert schedule.cut(8, 8 * m / 5, 16 * 3, max_scale=16) == (1, 3)     # 3 nodes per worker pair
    assert schedule.cut(8, 8 * m / 40, 10 ** 6, max_scale=16) == (3, 16)  # 40 units: 3 tasks of 16
    assert schedule.cut(8, 8 * m / 5, 15, max_scale=16) == (1, 1)         # a short pool: short tasks
    assert schedule.cut(8, 8 * m / 5, 16 * 7, schedule.MESSAGE_S / 5, max_scale=16) == (1, 7)  # a cheaper master


def test_the_master_clock_measures_busy_seconds_per_message_once_enough_are_out():
    clock = schedule.MasterClock()
    clock.start()
    clock.messages = schedule.MEASURED_AFTER - 1
    assert clock.message_s() == schedule.MESSAGE_S
    time.sleep(0.05)
    clock.slept_s = 0.05 - 0.0064                            # of which 6.4 ms busy (at least)
    clock.messages = schedule.MEASURED_AFTER
    assert 1e-4 <= clock.message_s() < 1e-4 + 1.0 / schedule.MEASURED_AFTER  # a loaded machine: a late wake-up


class _Node(tuple):
    depth = property(len)


def _job(pool: int) -> TreeJob:
    """A TreeJob whose pool holds `pool` + 1 nodes (budget 4)."""
    return TreeJob("t", None, None, [_Node((k,)) for k in range(pool + 1)], 4, {})


@pytest.mark.parametrize("workers, left, scale, budget", [
    (8, 0, 16, 1), (8, 7, 16, 1),                # fewer open nodes than workers: one node
    (8, 8, 16, 4), (8, 15, 16, 4),               # fewer than two per worker: the budget
    (8, 16, 3, 12), (8, 16, 99, 4 * BUDGET_SCALE),   # a long pool: the engine's scale, capped
    (1, 0, 16, 4), (1, 1, 16, 4), (1, 2, 16, 64),    # serial: never one node; scale when long
])
def test_a_tree_task_explores_one_node_while_the_pool_is_shorter_than_the_workers(workers, left, scale, budget):
    job = _job(left)
    _, (_, _, got, _) = job.take(workers, scale)
    assert job.pending() == left and got == budget


def test_an_idle_worker_sleeps_less_where_each_rank_has_a_core(monkeypatch):
    for key in ("OMPI_COMM_WORLD_LOCAL_SIZE", "MPI_LOCALNRANKS", "SLURM_NTASKS_PER_NODE", "SLURM_CPUS_ON_NODE"):
        monkeypatch.delenv(key, raising=False)
    monkeypatch.setattr(mpi.os, "cpu_count", lambda: 64)
    assert mpi.worker_poll_max() == mpi.POLL_MAX                 # the launcher does not say
    monkeypatch.setenv("OMPI_COMM_WORLD_LOCAL_SIZE", "64")
    assert mpi.worker_poll_max() == mpi.POLL_MAX_OWN_CORE < mpi.POLL_MAX
    monkeypatch.setenv("OMPI_COMM_WORLD_LOCAL_SIZE", "65")
    assert mpi.worker_poll_max() == mpi.POLL_MAX                 # oversubscribed
    monkeypatch.setenv("OMPI_COMM_WORLD_LOCAL_SIZE", "32")
    monkeypatch.setenv("SLURM_CPUS_ON_NODE", "16")
    assert mpi.worker_poll_max() == mpi.POLL_MAX                 # SLURM gave the job 16 of 64
