"""Jobs and their checkpoint state (hpcwedge/parallel/jobs.py; tests/test_jobs.py is about the
batch scripts in jobs/): a job saved with tasks in flight and loaded afresh finishes with
the answers of one pass."""
import json
import os
import signal
import time

import numpy as np
import pytest
from instances import tree_factory

from hpcwedge.errors import Interrupted
from hpcwedge.parallel import cancel
from hpcwedge.parallel.checkpoint import read_checkpoint
from hpcwedge.parallel.engine import Engine, run_tasks
from hpcwedge.parallel.jobs import TaskJob, TreeJob
from hpcwedge.patterns.job import SubtreeJob, run_patterns


def _task(ctx, payload):
    return {}


def test_subtree_job_checkpoint_state_round_trip():
    """Stop a job half-way with tasks 'in flight', save, load into a fresh job,
    finish: the same patterns and node count as one pass."""
    make, _ = tree_factory(31, m=6)
    mus = [1.0, 4.0]
    ref = run_patterns(make, mus, budget=2)
    job = SubtreeJob("p", make, mus, budget=2)
    handler = job.handler
    in_flight = []
    for _ in range(7):
        token, payload = job.take(1)
        job.merge(token, handler(job.context, payload))
    for _ in range(2):                                    # taken, never merged
        token, _ = job.take(1)
        in_flight.append(token)
    state = job.save(in_flight)
    again = SubtreeJob("p", make, mus, budget=2)
    again.load(state)
    again.counters.update({k: v for k, v in job.counters.items()})
    out = Engine().run(again).output()
    assert out.found == ref.found
    assert out.counters["nodes"] == ref.counters["nodes"]


def test_task_job_state_round_trip_with_arrays():
    job = TaskJob("t", _task, None, list(range(5)))
    for k, res in [(0, {"a": 1.5, "v": np.arange(3.0)}), (3, {"a": -2.0, "v": np.zeros((0,))}),
                   (4, {"a": 7.0, "v": np.ones(2)})]:
        job.merge(k, res)
    again = TaskJob("t", _task, None, list(range(5)))
    again.load({"attrs": job.save([])["attrs"], "data": job.save([])["data"]})
    assert again.pending() == 2 and [again.take(1)[0], again.take(1)[0]] == [1, 2]
    assert again.results[0]["a"] == 1.5 and again.results[0]["v"].tolist() == [0, 1, 2]
    assert again.results[3]["v"].tolist() == [] and again.results[4]["v"].tolist() == [1, 1]


def test_task_job_resumed_from_results_with_fewer_keys_saves_the_common_ones():
    """A task job resumed from an older version's checkpoint (its mu_c results lack
    "pyramid_lps") whose first done task is a new one: the next save keeps the keys every
    result has, where it raised KeyError on the old result."""
    old = TaskJob("t", _task, None, list(range(3)))
    old.merge(2, {"mu_c": 0.5, "lps": 3})
    resumed = TaskJob("t", _task, None, list(range(3)))
    resumed.load(old.save([]))
    resumed.merge(0, {"mu_c": 0.25, "lps": 4, "pyramid_lps": 2})
    again = TaskJob("t", _task, None, list(range(3)))
    again.load(resumed.save([]))
    assert again.results[0] == {"mu_c": 0.25, "lps": 4} and again.results[2] == {"mu_c": 0.5, "lps": 3}


# ---------------------------------------------------------------- the generic tree job

class _Node(tuple):
    """A node of the full binary tree of depth DEPTH: its path of 0/1 choices."""

    @property
    def depth(self) -> int:
        return len(self)


DEPTH = 5


def _explore(ctx, payload):
    """Visit at most `budget` nodes below the given one, depth first; leaves with an odd path
    sum are flagged; the rest is handed back open, each with its parent's path as witness.
    ctx: None, or a path sum at which a node is closed unvisited (an infeasible subtree)."""
    group, node, budget, witness = payload
    assert witness is None or witness == node[:-1]
    stack, found, flagged, visited = [node], [], [], 0
    while stack and visited < budget:
        n = stack.pop()
        visited += 1
        if ctx is not None and sum(n) >= ctx:
            continue
        if n.depth == DEPTH:
            found.append(n)
            if sum(n) % 2:
                flagged.append(n)
        else:
            stack += [_Node(n + (1,)), _Node(n + (0,))]
    return found, stack, {"nodes": visited}, flagged, [s[:-1] for s in stack]


def test_tree_job_finds_every_leaf_for_any_budget_and_resumes_mid_way():
    """The engine's generic tree job, without any domain: every leaf of two trees found once,
    the odd ones flagged, the node count the same for every budget; saved with tasks in flight
    and restored into a fresh job, it finishes with the answers of one pass."""
    leaves = sorted(_Node(tuple((k >> i) & 1 for i in reversed(range(DEPTH)))) for k in range(2 ** DEPTH))
    for budget in (1, 3, 64):
        job = TreeJob("t", _explore, None, [_Node(()), _Node(())], budget, {"nodes": 0})
        out = Engine().run(job)
        assert [sorted(f) for f in out.found] == [leaves, leaves]
        assert all(sorted(f) == [x for x in leaves if sum(x) % 2] for f in out.flagged)
        assert out.counters["nodes"] == 2 * (2 ** (DEPTH + 1) - 1)
    job = TreeJob("t", _explore, None, [_Node(()), _Node(())], 2, {"nodes": 0})
    for _ in range(9):
        token, payload = job.take(1)
        job.merge(token, _explore(None, payload))
    in_flight = [job.take(1)[0] for _ in range(2)]            # taken, never merged
    again = TreeJob("t", _explore, None, [_Node(()), _Node(())], 2, {"nodes": 0})
    again.restore(*job.saved_nodes(in_flight))
    out = Engine().run(again)
    assert [sorted(f) for f in out.found] == [leaves, leaves]
    assert all(sorted(f) == [x for x in leaves if sum(x) % 2] for f in out.flagged)


def _decided_by_count(opens: list, groups: int) -> float:
    """The share of the groups' 2^DEPTH leaves below no open node (brute force over leaves)."""
    leaves = [tuple((k >> i) & 1 for i in reversed(range(DEPTH))) for k in range(2 ** DEPTH)]
    below = sum(any(leaf[:len(n)] == n for gg, n, _ in opens if gg == g) for g in range(groups) for leaf in leaves)
    return 1.0 - below / (groups * 2 ** DEPTH)


@pytest.mark.parametrize("prune", [None, 3])
def test_tree_job_decided_share_is_the_share_of_leaves_below_no_open_node(prune):
    """decided_share, with two tasks in flight, equals the share of leaves that no open node
    (pool or in flight) covers, counted leaf by leaf; it never falls and ends at 1 (pruned
    subtrees count as decided)."""
    job = TreeJob("t", _explore, prune, [_Node(()), _Node(())], 3, {"nodes": 0})
    assert job.decided_share([]) == 0.0
    shares = []
    while job.pending():
        held = [job.take(1) for _ in range(min(2, job.pending()))]
        tokens = [t for t, _ in held]
        shares.append(job.decided_share(tokens))
        assert shares[-1] == pytest.approx(_decided_by_count(job.open_nodes(tokens), 2), abs=1e-15)
        for token, payload in held:
            job.merge(token, _explore(prune, payload))
    assert shares == sorted(shares) and shares[0] == 0.0
    assert job.decided_share([]) == 1.0


def test_progress_lines_of_a_tree_job_say_the_share_decided_and_short_tasks_leave_no_running_line():
    """Serial engine, a line after every merge: each line of the tree job carries its decided
    share, the last one 100 %; tasks shorter than the period write no "a task running" line
    (before, the in-task poll took every line once a period had passed since the last one)."""
    import io

    from hpcwedge.progress import Progress
    buf = io.StringIO()
    eng = Engine(progress=Progress(stream=buf), progress_every_s=0.0, tick_every_s=0.0)
    eng.run(TreeJob("t", _explore, None, [_Node(())], 3, {"nodes": 0}))
    lines = buf.getvalue().splitlines()
    assert lines and all("% of the tree decided" in line for line in lines)
    assert "100 % of the tree decided" in lines[-1]
    buf2 = io.StringIO()
    eng = Engine(progress=Progress(stream=buf2), progress_every_s=0.05, tick_every_s=0.0)
    run_tasks(_short_sum, None, list(range(60)), engine=eng, kind="short")
    lines = buf2.getvalue().splitlines()
    assert lines and not any("a task running" in line for line in lines)
    assert all("tasks done" in line for line in lines)


def _slow_explore(ctx, payload):
    """_explore after ~0.1 s of ticking (cancel.task_tick): a long tree task."""
    for _ in range(20):
        cancel.task_tick()
        time.sleep(0.005)
    return _explore(ctx, payload)


def test_a_long_tree_task_prints_the_jobs_line_with_its_share_while_it_runs():
    """Serial engine, one tree task of ~0.1 s, a period of 0.02 s: the lines written inside
    the task are the job's own (its share decided), ending with how long the task has run."""
    import io

    from hpcwedge.progress import Progress
    buf = io.StringIO()
    eng = Engine(progress=Progress(stream=buf), progress_every_s=0.02, tick_every_s=0.0)
    out = eng.run(TreeJob("t", _slow_explore, None, [_Node(())], 64, {"nodes": 0}))
    assert len(out.found[0]) == 2 ** DEPTH
    inside = [line for line in buf.getvalue().splitlines() if "; a task running for " in line]
    assert len(inside) >= 2 and all("t: 0 tasks done, 0 pending, 1 running, 0 % of the tree decided" in line
                                    for line in inside)


def _short_sum(ctx, payload):
    """A short task (~4 ms) that ticks (cancel.task_tick) as it runs."""
    for _ in range(4):
        cancel.task_tick()
        time.sleep(0.001)
    return {"sum": payload}


# ---------------------------------------------------------------- continuations

STEPS = 30


def _long_sum(ctx, payload):
    """A long task: sum of (k + 1)^2 over k < STEPS, one step at a time (each a few ms); when
    task_pausing() says so it hands back its state as a Continuation. ctx["starts"] records
    the step each run of the task started from (the context is shared in-process)."""
    state = payload if isinstance(payload, dict) else {"k": 0, "acc": 0}
    ctx["starts"].append((state["k"], os.getpid()))
    k, acc = state["k"], state["acc"]
    while k < STEPS:
        if k > state["k"] and cancel.task_pausing():
            return cancel.Continuation({"k": k, "acc": acc})
        time.sleep(0.004)
        if ctx.get("kill_at") == k and len(ctx["starts"]) > 2:
            os.kill(os.getpid(), signal.SIGTERM)
        acc += (k + 1) ** 2
        k += 1
    return {"sum": acc}


def _sums(n: int) -> list:
    """The answers of _long_sum for n tasks, from the closed form (not the loop)."""
    return [STEPS * (STEPS + 1) * (2 * STEPS + 1) // 6] * n


def test_task_job_keeps_a_continuation_in_its_checkpoint_state():
    """A continued task stays open with the new payload, is handed out next, is saved (JSON)
    and loaded by a fresh job; results and the task count are those of one pass."""
    job = TaskJob("t", _task, None, [None, None, None])
    k, _ = job.take(1)
    job.merge(k, cancel.Continuation({"k": 4, "acc": 30}))
    assert job.pending() == 3 and job.take(1) == (k, {"k": 4, "acc": 30})
    again = TaskJob("t", _task, None, [None, None, None])
    again.load(job.save([k]))
    assert again.pending() == 3 and again.payloads[k] == {"k": 4, "acc": 30}
    assert [again.take(1)[0] for _ in range(3)] == [0, 1, 2]
    again.merge(k, {"sum": 1})
    assert again.counters["tasks"] == 1 and json.loads(again.save([])["attrs"]["continued"]) == {}


@pytest.mark.parametrize("every", [0.02, 0.0])
def test_a_long_task_prints_progress_lines_while_it_runs(every):
    """In-process engine: a task of ~0.12 s, progress every 0.02 s, writes lines while it
    runs (before: only after each merge, so a single bracket task of minutes said nothing);
    progress_every_s = 0 (a line after every merge) writes none from inside. The answers stand."""
    import io

    from hpcwedge.progress import Progress
    buf = io.StringIO()
    eng = Engine(progress=Progress(stream=buf), progress_every_s=every, tick_every_s=0.0)
    got = [r["sum"] for r in run_tasks(_long_sum, {"starts": []}, [None, None], engine=eng, kind="sums")]
    inside = [line for line in buf.getvalue().splitlines() if "sums: a task running (1 rank, " in line]
    assert got == _sums(2)
    assert len(inside) >= 2 if every else inside == []


def test_long_tasks_pause_for_the_timer_checkpoint_and_resume_after_a_sigterm(tmp_path):
    """In-process engine, checkpoint every 0.03 s: each long task pauses several times (the
    timer checkpoint holds its state, a continued payload), the answers are the closed
    form's. A SIGTERM in the middle of a task continued before: Interrupted, the stop
    checkpoint holds the continuation, and a resumed engine starts that task from it and
    ends with the same answers."""
    ctx = {"starts": []}
    eng = Engine()
    eng.use_checkpoint(str(tmp_path / "a.ckpt"), "hash", "scene", 0.03, resume=False)
    try:
        got = [r["sum"] for r in run_tasks(_long_sum, ctx, [None, None], engine=eng, kind="sums")]
    finally:
        eng.close()
    assert got == _sums(2)
    assert eng.checkpoints_written >= 2 and eng.summary()["jobs"]["sums"]["tasks"] == 2
    assert 0 < eng.summary()["jobs"]["sums"]["continued"] == len(ctx["starts"]) - 2

    ckpt = str(tmp_path / "b.ckpt")
    ctx = {"starts": [], "kill_at": STEPS - 5}
    eng = Engine(tick_every_s=0.0)            # the stop seen at the next look
    eng.use_checkpoint(ckpt, "hash", "scene", 0.03, resume=False)
    eng.install_signals()
    try:
        with pytest.raises(Interrupted):
            run_tasks(_long_sum, ctx, [None, None], engine=eng, kind="sums")
        assert eng.write_checkpoint("SIGTERM")
    finally:
        eng.close()
    continued = json.loads(read_checkpoint(ckpt)["jobs"]["sums"]["attrs"]["continued"])
    (state,) = continued.values()                            # the task that ran at the stop
    stopped_at = state["k"]
    assert STEPS - 4 <= stopped_at < STEPS                  # paused within a tick of the stop
    ctx = {"starts": []}
    eng = Engine()
    assert eng.use_checkpoint(ckpt, "hash", "scene", 0.03, resume=True)
    try:
        got = [r["sum"] for r in run_tasks(_long_sum, ctx, [None, None], engine=eng, kind="sums")]
    finally:
        eng.close()
    assert got == _sums(2) and ctx["starts"][0][0] == stopped_at
