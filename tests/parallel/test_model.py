"""The discrete-event model of the engine's master (hpcwedge/parallel/model.py) against
schedules worked out by hand: one worker is the serial sum, equal tasks on w workers take
ceil(n / w) rounds, zero-length tasks are the master's costs alone, the master's wake-ups
are mpi.wait_any's."""
import math

import pytest

from hpcwedge.parallel import mpi, schedule
from hpcwedge.parallel.jobs import TaskJob, TreeJob
from hpcwedge.parallel.model import FREE, MasterCosts, noticed_at, simulate, simulate_hubs, waited


def _seconds_task(ctx, payload):
    return {"seconds": payload}


class _Node(tuple):
    @property
    def depth(self) -> int:
        return len(self)


def _explore(ctx, payload):
    """The full binary tree of depth 6, `budget` nodes per task, each costing 1 + depth s."""
    _, node, budget, _ = payload
    stack, found, seconds, visited = [node], [], 0.0, 0
    while stack and visited < budget:
        n = stack.pop()
        visited += 1
        seconds += 1 + n.depth
        if n.depth == 6:
            found.append(n)
        else:
            stack += [_Node(n + (1,)), _Node(n + (0,))]
    return found, stack, {"seconds": seconds}, [], [None] * len(stack)


def _result_seconds(r):
    return r["seconds"] if isinstance(r, dict) else r[2]["seconds"]


def test_one_worker_is_the_serial_sum_and_equal_tasks_take_rounds():
    durations = [0.3, 1.7, 0.25, 2.0, 0.5, 0.125]
    sim = simulate(TaskJob("t", _seconds_task, None, durations), 1, FREE, _result_seconds)
    assert sim.wall_s == pytest.approx(sum(durations)) and sim.tasks == len(durations)
    assert sim.efficiency == pytest.approx(1.0)
    for n, w in [(10, 3), (12, 4), (7, 8)]:
        sim = simulate(TaskJob("t", _seconds_task, None, [2.0] * n), w, FREE, _result_seconds)
        assert sim.wall_s == pytest.approx(2.0 * math.ceil(n / w))
        assert sim.efficiency == pytest.approx(n / (w * math.ceil(n / w)))


def test_zero_length_tasks_cost_the_master_alone():
    costs = MasterCosts(send_s=0.001, merge_s=0.003, poll_max_s=0.0, worker_poll_max_s=0.0)
    sim = simulate(TaskJob("t", _seconds_task, None, [0.0] * 50), 16, costs, _result_seconds)
    assert sim.wall_s == pytest.approx(50 * 0.004)
    assert sim.master_busy == pytest.approx(1.0)


def test_a_tree_job_costs_its_tree_for_any_worker_count():
    """The tree is the same for any split: its task seconds are the sum over its 127 nodes;
    one worker's wall time is that sum, more workers' is less, down to the longest path."""
    total = sum((1 + d) * 2 ** d for d in range(7))
    walls = []
    for w in (1, 2, 8):
        job = TreeJob("t", _explore, None, [_Node(())], 3, {"seconds": 0.0})
        sim = simulate(job, w, FREE, _result_seconds)
        assert sim.task_s == pytest.approx(total) and len(job.found[0]) == 64
        walls.append(sim.wall_s)
    assert walls[0] == pytest.approx(total)
    assert walls[0] > walls[1] > walls[2] >= sum(1 + d for d in range(7))


def test_batch_size_lasts_the_masters_target_and_shares_out_a_short_pool():
    target = math.ceil(100 * schedule.MESSAGE_S / schedule.MAX_BUSY / 0.01)         # 67 tasks of 10 ms
    assert schedule.batch_size(100, 0.01, 10 ** 6) == target == 67
    assert schedule.batch_size(100, 0.01, 1000) == 5                               # 1000 / (2 x 100)
    assert schedule.batch_size(100, 0.01, 150) == schedule.batch_size(100, None, 10 ** 6) == 1


def test_the_master_notices_a_result_at_its_next_wake_up():
    """noticed_at against the wake-ups listed one by one, as mpi.wait_any sleeps."""
    cap = mpi.POLL_MAX_MASTER
    wakes, t = [0.0], 0.0
    while t < 0.5:
        t += mpi.backoff(t, cap)
        wakes.append(t)
    for arrival in (0.0, 5e-5, 0.0031, 0.0457, 0.1, 0.2345, 0.49):
        expect = next(w for w in wakes if w >= arrival)
        assert noticed_at(0.0, arrival, cap) == pytest.approx(expect, abs=1e-12)
        t, probes = waited(0.0, arrival, cap)
        assert probes == wakes.index(expect) + 1        # the wake-ups up to it, each probing once
    assert noticed_at(1.0, 0.5, cap) == 1.0


def test_a_task_job_travels_in_batches_of_the_masters_target_length():
    """4,000 tasks of 0.3 ms on 8 workers, a master whose messages cost it MESSAGE_S: a first
    round of single tasks, then batches that last 8 x MESSAGE_S / MAX_BUSY (53 ms: 178 tasks)
    while the pool holds 16 x 178 tasks, then pending / 16 down to 1 (guided self-scheduling);
    every task merged once, in its slot. A master whose messages cost it nothing (as measured
    after schedule.MEASURED_AFTER messages) sends single tasks from then on."""
    durations = [0.0003 + 1e-9 * k for k in range(4000)]
    half = schedule.MESSAGE_S / 2
    job = TaskJob("t", _seconds_task, None, durations)
    sim = simulate(job, 8, MasterCosts(half, half, poll_max_s=0.0, worker_poll_max_s=0.0), _result_seconds)
    assert [r["seconds"] for r in job.results] == durations and sim.tasks == 4000
    k = math.ceil(8 * schedule.MESSAGE_S / schedule.MAX_BUSY / 0.0003)
    sizes, pending = [], 4000 - 8
    while pending:                        # one worker free at a time: one batch per answer
        sizes.append(max(1, min(k, pending // 16)))
        pending -= sizes[-1]
    assert k == 178 and sizes[:3] == [178] * 3 and sizes[-3:] == [1, 1, 1]
    assert sim.messages == 8 + len(sizes)
    assert sim.task_s == pytest.approx(sum(durations))
    free = simulate(TaskJob("t", _seconds_task, None, durations), 8, FREE, _result_seconds)
    sent, pending = 8, 4000 - 8
    while pending:
        pending -= max(1, min(k if sent < schedule.MEASURED_AFTER else 1, pending // 16))
        sent += 1
    assert free.tasks == 4000 and free.messages == sent > sim.messages


def test_a_worker_left_idle_starts_at_its_own_capped_wake_up():
    """One task of 1 s reaching its worker after a 1 s latency: the worker, asleep since 0 with
    sleeps capped at mpi.POLL_MAX, starts it at its first wake-up at or after 1 s (within one
    capped sleep); a worker that never sleeps starts it at once. The longest task is reported."""
    job = lambda: TaskJob("t", _seconds_task, None, [1.0])  # noqa: E731
    costs = MasterCosts(send_s=0.0, merge_s=0.0, latency_s=1.0, poll_max_s=0.0, worker_poll_max_s=mpi.POLL_MAX)
    sim = simulate(job(), 1, costs, _result_seconds)
    assert 2.0 < sim.wall_s <= 2.0 + mpi.POLL_MAX
    assert sim.wall_s == pytest.approx(noticed_at(0.0, 1.0, mpi.POLL_MAX) + 1.0)
    assert simulate(job(), 1, MasterCosts(0.0, 0.0, 1.0, 0.0, worker_poll_max_s=0.0), _result_seconds).wall_s == 2.0
    assert sim.longest_s == 1.0


def test_a_send_waits_for_the_idle_workers_probes():
    """idle_probe_s x idle workers x workers: four 1 s tasks sent at 0 to four idle workers
    start after 3, 2, 1 and 0 other idle workers' delays (0.01 x k x 4 s), so the wall is 1.12 s."""
    costs = MasterCosts(send_s=0.0, merge_s=0.0, poll_max_s=0.0, worker_poll_max_s=0.0, idle_probe_s=0.01)
    sim = simulate(TaskJob("t", _seconds_task, None, [1.0] * 4), 4, costs, _result_seconds)
    assert sim.wall_s == pytest.approx(1.12)
    assert sim.efficiency == pytest.approx(4 / (4 * 1.12))


# ---------------------------------------------------------------- hubs (simulate_hubs)

#: the binary tree of depth 6: every node's 1 + depth seconds, and its 64 leaves
TREE_SECONDS, TREE_LEAVES = sum(2 ** d * (1 + d) for d in range(7)), 64


def _tree_job(budget: int = 4) -> TreeJob:
    return TreeJob("t", _explore, None, [_Node(())], budget, {"seconds": 0.0})


@pytest.mark.parametrize("groups", [[1], [2, 3], [4, 4, 4], [1, 7]])
def test_hubs_explore_every_node_once(groups):
    """Every node once between the pools: the tree's seconds and leaves, whatever the layout (a
    node lost or run twice changes them)."""
    costs = MasterCosts(send_s=1e-3, merge_s=2e-3, latency_s=1e-3)
    r = simulate_hubs(_tree_job(), groups, costs, _result_seconds)
    assert r["task_s"] == TREE_SECONDS and r["found"] == TREE_LEAVES
    assert 0 < r["efficiency"] <= 1 and r["wall_s"] >= TREE_SECONDS / sum(groups)
    assert 0 < r["master_busy"] <= 1 and 0 < r["hub_busy"] <= 1 and r["moved"] >= 1


def test_one_free_hub_of_one_worker_is_the_serial_sum():
    r = simulate_hubs(_tree_job(), [1], FREE, _result_seconds)
    assert r["wall_s"] == pytest.approx(TREE_SECONDS) and r["efficiency"] == pytest.approx(1.0)


def test_more_hubs_are_faster_on_a_wide_tree():
    one, four = (simulate_hubs(_tree_job(1), g, FREE, _result_seconds) for g in ([4], [4] * 4))
    assert four["wall_s"] < one["wall_s"] / 2


def test_a_hub_schedule_without_an_end_is_an_error():
    with pytest.raises(RuntimeError, match="max_events"):
        simulate_hubs(_tree_job(), [2, 2], FREE, _result_seconds, max_events=5)
