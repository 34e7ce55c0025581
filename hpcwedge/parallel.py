"""Master/worker engine over mpi4py, and the checkpoints of its state (SPEC §5).

Vocabulary
- *task* = (kind, payload). A kind names a handler ``handler(context, payload)
  -> result``; ``context`` is the job's shared read-only data (a picklable
  object: the parametrisation, the mu list, ...), sent once to each worker.
  The engines (patterns.py, mu_critical.py, dd.py) know nothing of MPI. Kinds:
  "subtree" (sign patterns), "mu_c", "face" (the 2D double description of one
  face of a few branching nodes, SPEC §5; run_faces). A long task calls
  ``task_tick()`` now and then, where a stopping engine may cancel it.
- *job*: a pool of tasks and the merge of their results. ``SubtreeJob``
  (branch and bound: a task explores a subtree with a node budget and gives
  back the subtrees it left open, which return to the pool) and ``TaskJob``
  (a fixed list of independent tasks: mu^c, faces; a face split depends on the
  rank count, so its job saves the split and a resumed run keeps it).
- ``Engine`` runs jobs. One process (no MPI launcher, or size 1): the same
  task loop in-process. Under mpirun: rank 0 is the master — it holds the
  pool, hands a task to each worker that is free, merges results and alone
  writes files; ranks >= 1 call ``Engine.serve()`` and only run tasks.

Budgets (after mplrs): a subtree task gets ``budget`` tree nodes while the
pool is short (fewer than 2 tasks per worker), so work is split and handed
back as open subtrees; ``budget * BUDGET_SCALE`` when the pool is long. Tasks
are always bounded, so a checkpoint never waits long and loses little.

Idle ranks sleep: Open MPI's blocking receive busy-polls a core, so every
wait here is a burst of ``Iprobe`` calls + ``time.sleep`` with a back-off
(10% of the time waited so far, at most POLL_MAX seconds) (an idle worker costs well under 1% of a core;
see tests). The burst matters: Open MPI's Iprobe sees a message that is
already there only after ~10 progress calls, so one probe per sleep made
every round trip cost ~140 ms instead of ~0.2 ms.

Checkpoints (checkpoint.py has the file layout): every ``checkpoint_every_s``
seconds, at SIGUSR1 (then the run goes on) and at SIGTERM/SIGINT (then the
master stops the workers — a task in progress is dropped at its next
task_tick() — and the command exits with EXIT_INTERRUPTED). Signal
handlers only set a flag inside the task loop, which acts on it between two
merges (a task is done only once its result is merged into the master's
state; tasks in flight are saved as open). Outside the loop, SIGTERM raises
``Interrupted`` at once: the state is then the finished jobs.

Resume: a job whose name is in the checkpoint starts from the saved state
(a finished job returns its saved results at once). The pipeline is
deterministic, so it asks for the same jobs in the same order.

Adding a task kind is one line in KINDS (a ``"module:function"`` string is
imported on first use, on every rank), or ``register(kind, handler)`` in a
module that every rank imports.
"""
from __future__ import annotations

import heapq
import importlib
import json
import math
import os
import signal
import socket
import sys
import time
import traceback
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from .checkpoint import CheckpointError, read_checkpoint, write_checkpoint
from .results import error_reason

if TYPE_CHECKING:
    from .dd import DDResult

#: exit status of `hpcwedge run` after SIGTERM/SIGINT: the checkpoint is written, rerun with --resume
EXIT_INTERRUPTED = 75
#: longest sleep between two probes of an idle worker / of the master (seconds);
#: a rank that has waited t seconds sleeps min(cap, POLL_FRACTION * t), so a
#: result is noticed within ~10% of the task's duration
POLL_MAX = 0.05
POLL_MAX_MASTER = 0.01
POLL_FRACTION = 0.1
#: probes per wake-up: Open MPI's Iprobe reports a message that has arrived only
#: after several progress calls (~10 measured here), so each wake-up probes in a burst
PROBE_BURST = 32
#: budget multiplier when the pool holds enough tasks for every worker
BUDGET_SCALE = 16
#: default node budget of a subtree task (scene key run.task_budget)
DEFAULT_BUDGET = 64
#: the master checks the memory guard (Engine.guard) at most this often (seconds)
GUARD_EVERY_S = 1.0

_TASK, _RESULT, _ERROR, _STOP, _HELLO, _CANCELLED = 1, 2, 3, 4, 5, 6
#: how often an idle worker checks that its master (same host) is still alive
MASTER_CHECK_S = 0.2


class ParallelError(RuntimeError):
    """A launch problem the user must fix (one line; exit status 2)."""


class Interrupted(Exception):
    """SIGTERM/SIGINT reached the master: write the checkpoint and stop."""


class TaskCancelled(Exception):
    """Raised by task_tick() inside a task the engine is stopping."""


#: set by the engine while it runs a task: returns True when the task should stop
_cancel_check = None
_TICK_EVERY_S = 0.05
_last_tick = 0.0
_stopping = False


def task_stopping() -> bool:
    """Long loops of a task call this now and then: True when the engine is stopping —
    a worker whose master sent stop (after SIGTERM: the master checkpoints, then stops
    the workers; mpirun would otherwise wait for the task, or kill it), or the
    in-process engine after SIGTERM/SIGINT. A loop that can hand back what is left
    (PatternTree.explore: its open subtrees) returns then; others call task_tick().
    In-process, the call also serves SIGUSR1 and the checkpoint timer (the running
    task is saved as open). Cheap: looks at most every 50 ms; once True, stays True
    to the end of the task; False outside a task."""
    global _last_tick, _stopping
    if _cancel_check is None:
        return False
    if not _stopping:
        now = time.monotonic()
        if now - _last_tick >= _TICK_EVERY_S:
            _last_tick = now
            _stopping = bool(_cancel_check())
    return _stopping


def task_tick() -> None:
    """Raises TaskCancelled when task_stopping() (face_task: after every DD step; the
    mu^c iterations). A cancelled task counts as not done (it is in flight, so the
    checkpoint keeps it as open). A no-op outside a task."""
    if task_stopping():
        raise TaskCancelled()


def _run_cancellable(handler, ctx, payload, check):
    global _cancel_check, _last_tick, _stopping
    _cancel_check, _last_tick, _stopping = check, time.monotonic(), False
    try:
        return handler(ctx, payload)
    finally:
        _cancel_check, _stopping = None, False


# ---------------------------------------------------------------- task kinds

KINDS: dict = {
    "subtree": "hpcwedge.parallel:explore_task",
    "mu_c": "hpcwedge.parallel:mu_c_task",
    "face": "hpcwedge.parallel:face_task",  # the 2D double description split over faces (SPEC §5)
}


#: modules a worker imports before its first task (the engines' heavy imports)
WARM_UP = ["hpcwedge.patterns", "hpcwedge.mu_critical", "hpcwedge.dd"]


def register(kind: str, handler) -> None:
    """handler: callable(context, payload) -> result, or a "module:function" string."""
    KINDS[kind] = handler


def handler_for(kind: str):
    h = KINDS.get(kind, kind if ":" in kind else None)
    if h is None:
        raise KeyError(f"unknown task kind {kind!r}")
    if isinstance(h, str):
        mod, name = h.split(":")
        h = getattr(importlib.import_module(mod), name)
        KINDS[kind] = h
    return h


# ---------------------------------------------------------------- the communicator

_MPI_ENV = ("OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE", "MPI_LOCALNRANKS")


def world():
    """The MPI world communicator when launched by an MPI launcher (mpirun, srun
    --mpi=pmix) with more than one rank, else None (no MPI is initialised).

    Set HPCWEDGE_MPI=0 to never use MPI, =1 to always initialise it. When
    SLURM_NTASKS is set, the world size must equal it: srun without a working
    PMIx starts N independent single-rank copies, which would each redo the
    whole run and race on the output (ParallelError; HPCWEDGE_IGNORE_SLURM_NTASKS=1
    skips the check)."""
    mode = os.environ.get("HPCWEDGE_MPI", "")
    if mode == "0":
        return None
    ntasks = os.environ.get("SLURM_NTASKS", "")
    ntasks = int(ntasks) if ntasks.isdigit() else None
    launched = any(k in os.environ for k in _MPI_ENV)
    if not (launched or mode == "1" or (ntasks or 0) > 1):
        return None
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    if ntasks is not None and comm.size != ntasks and not os.environ.get("HPCWEDGE_IGNORE_SLURM_NTASKS"):
        raise ParallelError(
            f"SLURM_NTASKS={ntasks} but this process is rank {comm.rank} of an MPI world of "
            f"{comm.size}: the launcher started independent copies (srun without PMIx?); use "
            f"`srun --mpi=pmix` or `mpirun -n {ntasks}`, or set HPCWEDGE_IGNORE_SLURM_NTASKS=1")
    return comm if comm.size > 1 else None


# ---------------------------------------------------------------- sign-pattern subtrees


class PatternContext:
    """What a worker needs to explore subtrees: make_tree(mu) -> a tree with
    root() and explore(subtree, budget) (patterns.PatternTree), and the mu list."""

    def __init__(self, make_tree, mus):
        self.make_tree, self.mus = make_tree, list(mus)
        self._trees = {}

    def tree(self, i: int):
        if i not in self._trees:
            self._trees[i] = self.make_tree(self.mus[i])
        return self._trees[i]

    def __getstate__(self):
        return {"make_tree": self.make_tree, "mus": self.mus, "_trees": {}}


STAT_KEYS = ("nodes", "solves", "skipped", "pruned", "undecided")


def explore_task(ctx: PatternContext, payload):
    """Task "subtree": payload (mu index, Subtree, budget, witness x or None) ->
    (found, open, stats dict, undecided found, open witnesses). Stopped by the
    engine (task_stopping), it returns what it found and hands the rest back as open."""
    i, subtree, budget, x = payload
    out = ctx.tree(i).explore(subtree, budget, x=x)
    stats = {k: getattr(out.stats, k) for k in STAT_KEYS}
    for k, v in (getattr(out.stats, "statuses", None) or {}).items():
        stats[f"status_{k}"] = v
    return out.found, out.open, stats, list(getattr(out, "undecided", [])), list(out.open_x)


def _bits_to_words(values, words: int) -> np.ndarray:
    out = np.zeros((len(values), words), dtype=np.uint64)
    for r, v in enumerate(values):
        for w in range(words):
            out[r, w] = (v >> (64 * w)) & 0xFFFFFFFFFFFFFFFF
    return out


def _words_to_bits(arr: np.ndarray) -> list[int]:
    arr = np.asarray(arr, dtype=np.uint64)
    if arr.ndim == 1:
        arr = arr[:, None]
    return [sum(int(x) << (64 * w) for w, x in enumerate(row)) for row in arr]


def canonical_key(subtree, m: int) -> int:
    """Patterns sort by their gap set read as a binary word with node 0 first:
    the serial depth-first order (contact before gap, node 0 decided first)."""
    return int(format(subtree.gap, f"0{m}b")[::-1], 2)


class SubtreeJob:
    """The sign-pattern trees of every mu, explored by budgeted subtree tasks.

    An open subtree travels with its root's witness (the parent's point that proves
    it feasible, or None), so that the tree, and every counter of it (nodes, solves,
    skipped, undecided, solver statuses), is the same for every split of the work:
    plain, resumed, any budget or rank count.

    Checkpoint data: mus, m; found_mu, found_depth, found_contact, found_gap,
    found_undecided (one row per found pattern); open_mu, open_depth,
    open_contact, open_gap, open_has_x, open_x (the pool and the tasks in flight;
    open_x: (rows, d) float64, rows without a witness zero). Bit sets are
    (rows, ceil(m/64)) uint64 words, bit i of word w = node 64 w + i."""

    kind = "subtree"

    def __init__(self, name: str, make_tree, mus, budget: int = DEFAULT_BUDGET):
        self.name, self.mus, self.budget = name, [float(v) for v in mus], int(budget)
        self.context = PatternContext(make_tree, self.mus)
        trees = [self.context.tree(i) for i in range(len(self.mus))]
        self.m = trees[0].m if trees else 0
        self.found = [[] for _ in self.mus]
        self.undecided = [[] for _ in self.mus]
        self.counters = {"tasks": 0, "handed_back": 0, **{k: 0 for k in STAT_KEYS}}
        self._pool: list = []
        self._seq = 0
        for i, tree in enumerate(trees):
            self._push(i, tree.root())

    def _push(self, i, subtree, x=None):
        heapq.heappush(self._pool, (subtree.depth, self._seq, i, subtree, x))
        self._seq += 1

    def pending(self) -> int:
        return len(self._pool)

    def take(self, n_workers: int):
        if not self._pool:
            return None
        _, _, i, subtree, x = heapq.heappop(self._pool)
        budget = self.budget if len(self._pool) < 2 * n_workers else self.budget * BUDGET_SCALE
        return (i, subtree, x), (i, subtree, budget, x)

    def merge(self, token, result) -> None:
        i = token[0]
        found, open_, stats, undecided, open_x = result
        self.found[i].extend(found)
        self.undecided[i].extend(undecided)
        for s, x in zip(open_, open_x, strict=True):
            self._push(i, s, x)
        self.counters["tasks"] += 1
        self.counters["handed_back"] += len(open_)
        for k, v in stats.items():
            self.counters[k] = self.counters.get(k, 0) + v

    def save(self, in_flight) -> dict:
        words = max(1, math.ceil(self.m / 64))
        doubt = [set(u) for u in self.undecided]
        found = [(i, s) for i, lst in enumerate(self.found) for s in lst]
        opens = [(i, s, x) for _, _, i, s, x in self._pool] + [tuple(t) for t in in_flight]
        xs = [x for _, _, x in opens]
        d = next((len(x) for x in xs if x is not None), 0)
        data = {"mus": np.array(self.mus, dtype=float),
                "found_mu": np.array([i for i, _ in found], dtype=np.int32),
                "found_depth": np.array([s.depth for _, s in found], dtype=np.int32),
                "found_contact": _bits_to_words([s.contact for _, s in found], words),
                "found_gap": _bits_to_words([s.gap for _, s in found], words),
                "found_undecided": np.array([s in doubt[i] for i, s in found], dtype=bool),
                "open_mu": np.array([i for i, _, _ in opens], dtype=np.int32),
                "open_depth": np.array([s.depth for _, s, _ in opens], dtype=np.int32),
                "open_contact": _bits_to_words([s.contact for _, s, _ in opens], words),
                "open_gap": _bits_to_words([s.gap for _, s, _ in opens], words),
                "open_has_x": np.array([x is not None for x in xs], dtype=bool),
                "open_x": np.array([np.zeros(d) if x is None else np.asarray(x, dtype=np.float64) for x in xs],
                                   dtype=np.float64).reshape(len(xs), d)}
        return {"attrs": {"m": self.m, "budget": self.budget}, "data": data}

    def load(self, state: dict) -> None:
        from .patterns import Subtree
        a, d = state["attrs"], state["data"]
        if int(a["m"]) != self.m or list(np.asarray(d["mus"], dtype=float)) != self.mus:
            raise CheckpointError(f"job {self.name!r}: the checkpoint was taken on other mu values or m")
        self.found = [[] for _ in self.mus]
        self.undecided = [[] for _ in self.mus]
        for i, depth, c, g, u in zip(d["found_mu"], d["found_depth"], _words_to_bits(d["found_contact"]),
                                     _words_to_bits(d["found_gap"]), d["found_undecided"]):
            s = Subtree(int(depth), c, g)
            self.found[int(i)].append(s)
            if u:
                self.undecided[int(i)].append(s)
        self._pool, self._seq = [], 0
        n = len(d["open_mu"])
        has_x = d.get("open_has_x", np.zeros(n, dtype=bool))
        xs = d.get("open_x", np.zeros((n, 0)))
        for i, depth, c, g, h, x in zip(d["open_mu"], d["open_depth"], _words_to_bits(d["open_contact"]),
                                        _words_to_bits(d["open_gap"]), has_x, xs):
            self._push(int(i), Subtree(int(depth), c, g), np.array(x, dtype=np.float64) if h else None)

    def output(self) -> "Patterns":
        key = lambda s: canonical_key(s, self.m)
        return Patterns(mus=self.mus, m=self.m,
                        found=[sorted(lst, key=key) for lst in self.found],
                        undecided=[sorted(lst, key=key) for lst in self.undecided],
                        counters=dict(self.counters))


@dataclass
class Patterns:
    """run_patterns' answer: per mu (in the given order) the feasible full
    patterns (patterns.Subtree, depth m) in canonical order, the ones among
    them no solver decided, and the job's counters: nodes (tree nodes visited),
    solves, skipped, pruned, undecided and status_* (how each solve was decided)
    are the same for every split, rank count or resume (open subtrees carry their
    witness; PatternTree learns no cores by default); tasks and handed_back depend
    on the schedule (the pipeline reports them under stats.parallel only)."""

    mus: list
    m: int
    found: list
    undecided: list
    counters: dict = field(default_factory=dict)


# ---------------------------------------------------------------- independent tasks


def mu_c_task(solve, payload) -> dict:
    """Task "mu_c": payload (zero_u, zero_r, mu_hi) -> MuC fields (mu_c NaN = None)."""
    zero_u, zero_r, mu_hi = payload
    r = solve(np.asarray(zero_u, dtype=bool), np.asarray(zero_r, dtype=bool), mu_hi=mu_hi)
    return {"mu_c": np.nan if r.mu_c is None else float(r.mu_c), "polished": bool(r.polished),
            "lps": int(r.solves), "undecided": int(r.undecided)}


@dataclass
class FaceContext:
    """The shared data of "face" tasks: the constraint rows A of every mu
    (problem.friction_rows_2d: float, or exact integer object arrays), m, and
    whether the DD runs in exact arithmetic."""

    rows: list
    m: int
    exact: bool = False
    max_memory_gb: float | str = "auto"     # run.max_memory_gb (progress.MemoryGuard)


def face_payloads(n_mu: int, m: int, nodes) -> list[tuple]:
    """The "face" tasks of a split: (mu index, face) for every mu and every face of
    dd.split_faces(m, nodes), face by face (the face where every branching node is in
    contact, usually the largest, first for every mu: big tasks start first)."""
    from .dd import split_faces
    return [(i, f) for f in split_faces(m, nodes) for i in range(n_mu)]


def face_task(ctx: FaceContext, payload: tuple) -> dict:
    """Task "face": payload (mu index, (contact, gap)) -> the DD of that face
    (dd.complementary_rays(..., face=...); task_tick() and the memory guard after every
    step: progress.MemoryLimit when run.max_memory_gb would be exceeded) as a dict
    of numbers and arrays, so that checkpoints can hold it: mu_index; contact, gap
    ((m,) bool masks of the face); X (R, d) float64 rays, or exact integers as
    decimal strings (bytes); zero (R, ceil(3m / 8)) uint8, the zero flags packed
    along rows (np.packbits); the counters initial_rays, pairs_tested,
    pairs_adjacent, max_rays and seconds; a float DD's numerics close_calls,
    cancellation and closest (NaN: no close call). face_result() turns it back into
    a dd.DDResult."""
    from .dd import complementary_rays
    from .progress import MemoryGuard
    i, (contact, gap) = payload
    guard = MemoryGuard(ctx.max_memory_gb, ranks_on_host())
    where = f" of face (contact {list(contact)}, gap {list(gap)})"

    def tick(info):
        task_tick()
        guard.dd_step(info, where)

    dd = complementary_rays(ctx.rows[i], ctx.m, exact=ctx.exact, face=(contact, gap), progress=tick)
    nodes = np.arange(ctx.m)
    out = {"mu_index": int(i), "contact": np.isin(nodes, list(contact)), "gap": np.isin(nodes, list(gap)),
           "X": _encode_rays(dd.X), "zero": np.packbits(dd.zero, axis=1)}
    for key in ("initial_rays", "pairs_tested", "pairs_adjacent", "max_rays"):
        out[key] = int(dd.stats[key])
    out["seconds"] = float(dd.stats["seconds"])
    if not ctx.exact:
        out["close_calls"] = int(dd.stats["close_calls"])
        out["cancellation"] = float(dd.stats["cancellation"])
        closest = dd.stats["closest"]
        out["closest"] = float("nan") if closest is None else float(closest)
    return out


def face_result(res: dict) -> "DDResult":
    """The dd.DDResult of a face_task result (as returned, or as read back from a
    checkpoint); stats["face"] is the face, as dd.merge_results expects."""
    from .dd import DDResult
    contact, gap = np.asarray(res["contact"], dtype=bool), np.asarray(res["gap"], dtype=bool)
    m = len(contact)
    zero = np.unpackbits(np.asarray(res["zero"], dtype=np.uint8).reshape(-1, -(-3 * m // 8)),
                         axis=1, count=3 * m).astype(bool)
    stats = {k: res[k] for k in ("initial_rays", "pairs_tested", "pairs_adjacent", "max_rays", "seconds")}
    if "close_calls" in res:
        closest = float(res["closest"])
        stats.update(close_calls=int(res["close_calls"]), cancellation=float(res["cancellation"]),
                     closest=None if np.isnan(closest) else closest)
    stats["face"] = (tuple(np.flatnonzero(contact).tolist()), tuple(np.flatnonzero(gap).tolist()))
    return DDResult(X=_decode_rays(res["X"]), zero=zero, stats=stats)


def _encode_rays(X: np.ndarray) -> np.ndarray:
    """Float rays as they are; exact ones (object ints) as decimal strings."""
    if X.dtype != object:
        return X
    return X.astype(str).astype("S") if X.size else np.zeros(X.shape, dtype="S1")


def _decode_rays(X: np.ndarray) -> np.ndarray:
    X = np.asarray(X)
    if X.dtype.kind != "S":
        return X
    return np.frompyfunc(int, 1, 1)(X).astype(object)


class TaskJob:
    """A fixed list of independent tasks of one kind; results are dicts whose
    values are numbers/bools (stored as one column per key) or arrays (stored
    concatenated along axis 0, with <key>_offsets). Checkpoint data: done (the
    indices whose result is in), the result columns.

    layout: optional JSON value from which the payloads were made (e.g. the face
    split, which depends on the rank count); it is saved, and a resumed job whose
    layout differs takes the saved one, with payloads_for(saved layout) as its
    payloads, so that the finished tasks stay valid (without payloads_for a
    differing layout is a CheckpointError). Results should then say which task they
    answer: their order follows the adopted payloads."""

    def __init__(self, name: str, kind: str, context, payloads: list, layout=None, payloads_for=None):
        self.name, self.kind, self.context = name, kind, context
        self.layout, self.payloads_for = _json_value(layout), payloads_for
        self.payloads = list(payloads)
        self.results: list = [None] * len(self.payloads)
        self._todo = list(range(len(self.payloads)))[::-1]
        self.counters = {"tasks": 0}

    def pending(self) -> int:
        return len(self._todo)

    def take(self, n_workers: int):
        if not self._todo:
            return None
        k = self._todo.pop()
        return k, self.payloads[k]

    def merge(self, token, result) -> None:
        self.results[token] = result
        self.counters["tasks"] += 1

    def save(self, in_flight) -> dict:
        done = [k for k, r in enumerate(self.results) if r is not None]
        data = {"done": np.array(done, dtype=np.int64)}
        keys = sorted(self.results[done[0]]) if done else []
        for key in keys:
            vals = [self.results[k][key] for k in done]
            if all(np.ndim(v) == 0 for v in vals):
                data[key] = np.array(vals)
            else:
                arrs = [np.atleast_1d(np.asarray(v)) for v in vals]
                data[key] = np.concatenate(arrs, axis=0)
                data[key + "_offsets"] = np.cumsum([0] + [len(a) for a in arrs])
        return {"attrs": {"n_tasks": len(self.payloads), "result_keys": json.dumps(keys),
                          "layout": json.dumps(self.layout)}, "data": data}

    def load(self, state: dict) -> None:
        a, d = state["attrs"], state["data"]
        saved = json.loads(a.get("layout", "null"))
        if saved != self.layout:
            if self.payloads_for is None:
                raise CheckpointError(f"job {self.name!r}: the checkpoint's task layout {saved!r} is not "
                                      f"this run's {self.layout!r}")
            self.layout, self.payloads = saved, list(self.payloads_for(saved))
        if int(a["n_tasks"]) != len(self.payloads):
            raise CheckpointError(f"job {self.name!r}: the checkpoint has {a['n_tasks']} tasks, "
                                  f"this run {len(self.payloads)}")
        keys = json.loads(a["result_keys"])
        done = [int(k) for k in d["done"]]
        self.results = [None] * len(self.payloads)
        for row, k in enumerate(done):
            res = {}
            for key in keys:
                if key + "_offsets" in d:
                    off = d[key + "_offsets"]
                    res[key] = d[key][off[row]:off[row + 1]]
                else:
                    res[key] = d[key][row].item()
            self.results[k] = res
        self._todo = [k for k in range(len(self.payloads)) if self.results[k] is None][::-1]
        self.counters["tasks"] = len(done)

    def output(self) -> list:
        return self.results


def _json_value(v):
    """v as it reads back from JSON (tuples become lists), for comparisons."""
    return json.loads(json.dumps(v))


# ---------------------------------------------------------------- the engine


class Engine:
    """Runs jobs serially (comm None) or as the master of a world of workers.

    checkpoint: set with use_checkpoint(); signals: install_signals() (master,
    command line only). summary(): how the work was split (depends on the rank
    count and on resumes, unlike every answer)."""

    def __init__(self, comm=None, progress=None):
        self.comm = comm
        self.size = comm.size if comm is not None else 1
        self.rank = comm.rank if comm is not None else 0
        self.progress = progress
        self.workers = list(range(1, self.size))
        self._jobs: dict = {}            # finished jobs, by name, in order
        self._restored: dict = {}        # name -> saved state
        self._restored_order: list = []
        self._current = None             # the job being run
        self._inflight: dict = {}        # worker -> token (master)
        self._ctx_sent: dict = {}        # worker -> job id whose context it holds
        self._job_id = 0
        self._flags: set = set()
        self._defer = False              # signals only set flags (inside run())
        self._old_handlers: dict = {}
        self._stopped = False
        self._done = False
        self._ckpt = None                # (path, scene_hash, scene_text, every_s, inputs)
        self._next_ckpt = math.inf
        self._t0 = time.monotonic()
        self._job_start = (self._t0, 0)    # (when, tasks done) as the current job started
        #: progress.MemoryGuard of the run (run.max_memory_gb), checked after merges (pipeline sets it)
        self.guard = None
        self._guarded = 0.0
        self._elapsed_before = 0.0
        self.resumes = 0
        self.checkpoints_written = 0
        self.checkpoint_reason = None
        self.tasks_per_rank = [0] * self.size  # this session, merged tasks by the rank that ran them
        if comm is not None and self.rank == 0:
            me = (socket.gethostname(), os.getpid())
            for w in self.workers:              # small: an eager send, returns at once
                comm.send(me, dest=w, tag=_HELLO)

    @property
    def is_master(self) -> bool:
        return self.rank == 0

    # ---- checkpoints

    def use_checkpoint(self, path: str, scene_hash: str, scene_text: str, every_s: float,
                       resume: bool, inputs: dict[str, str] | None = None) -> bool:
        """Write checkpoints to `path`; with resume, continue from it if it exists. The
        checkpoint's identity is the scene's hash and `inputs` (Scene.input_digests: the
        bytes of the files the scene names): a damaged file, another scene or a changed input
        file is a CheckpointError, and the file is left untouched. Returns True when a
        checkpoint was loaded."""
        inputs = dict(inputs or {})
        self._ckpt = (path, scene_hash, scene_text, float(every_s), inputs)
        self._next_ckpt = time.monotonic() + float(every_s)
        if not (resume and os.path.exists(path)):
            return False
        from . import __version__
        ck = read_checkpoint(path)
        a = ck["attrs"]
        if a["scene_hash"] != scene_hash:
            raise CheckpointError(f"{path}: the checkpoint belongs to another scene (scene hash "
                                  f"{a['scene_hash'][:12]}..., this scene {scene_hash[:12]}...); "
                                  f"use the scene it was started with, or remove it to start afresh")
        try:
            saved = json.loads(a["inputs"])
            changed = sorted(k for k in saved.keys() | inputs.keys() if saved.get(k) != inputs.get(k))
        except (TypeError, ValueError, AttributeError):
            raise CheckpointError(f"{path}: unreadable checkpoint (bad attribute 'inputs')") from None
        if changed:
            raise CheckpointError(f"{path}: {changed[0]} changed since the checkpoint was written (SHA-256 "
                                  f"{(saved.get(changed[0]) or 'none')[:12]}... then, "
                                  f"{(inputs.get(changed[0]) or 'none')[:12]}... now); put the file back "
                                  f"as it was, or remove the checkpoint to start afresh")
        if a["version"] != __version__:
            raise CheckpointError(f"{path}: written by hpcwedge {a['version']}, this is {__version__}; "
                                  f"finish the run with that version, or remove it to start afresh")
        self._restored = ck["jobs"]
        self._restored_order = list(ck["order"])
        self._elapsed_before = float(a["elapsed_s"])
        self.resumes = int(a["resumes"]) + 1
        return True

    def restored(self, name: str) -> bool:
        """The checkpoint this run resumed from holds a job `name` not run yet in
        this session (the pipeline then runs that stage as jobs again, so that the
        saved work is used)."""
        return name in self._restored

    def elapsed(self) -> float:
        return self._elapsed_before + time.monotonic() - self._t0

    def write_checkpoint(self, reason: str = "timer") -> bool:
        """Write the master's state now (no-op without a checkpoint path); True if written.
        A write that fails (OSError: full disk, read-only folder...) keeps the previous
        checkpoint, says so in one line on stderr and returns False: the run goes on and the
        next timer or signal tries again."""
        if self._ckpt is None or not self.is_master:
            return False
        path, scene_hash, text, every, inputs = self._ckpt
        jobs = []
        for name, job in self._jobs.items():
            jobs.append((name, self._state(job, [], finished=True)))
        if self._current is not None and self._current.name not in self._jobs:
            jobs.append((self._current.name,
                         self._state(self._current, list(self._inflight.values()), finished=False)))
        names = {n for n, _ in jobs}
        for name in self._restored_order:       # restored jobs this session has not reached yet
            if name not in names and name in self._restored:
                jobs.append((name, self._restored[name]))
        header = {"scene_hash": scene_hash, "inputs": json.dumps(inputs), "elapsed_s": self.elapsed(),
                  "resumes": self.resumes, "ranks": self.size, "reason": reason}
        try:
            write_checkpoint(path, header, text, jobs)
        except (OSError, CheckpointError) as e:   # full disk, read-only folder...: the run goes on
            print(f"hpcwedge: warning: checkpoint not written to {path} ({error_reason(e)}); the previous one "
                  f"is kept, the next timer or signal tries again", file=sys.stderr)
            self._next_ckpt = time.monotonic() + every
            return False
        self.checkpoints_written += 1
        self.checkpoint_reason = reason
        self._next_ckpt = time.monotonic() + every
        return True

    def remove_checkpoint(self) -> None:
        """The result is written: the checkpoint (and a stale temp) are no longer needed. One
        that cannot be removed is said in one line (harmless: a later --resume from it ends
        with the same result)."""
        if self._ckpt is None:
            return
        for p in (self._ckpt[0], self._ckpt[0] + ".tmp"):
            try:
                os.unlink(p)
            except FileNotFoundError:
                pass
            except OSError as e:
                print(f"hpcwedge: warning: cannot remove {p} ({error_reason(e)})", file=sys.stderr)

    @staticmethod
    def _state(job, in_flight, finished: bool) -> dict:
        st = job.save(in_flight)
        st["attrs"].update({"kind": job.kind, "finished": finished, "counters": json.dumps(job.counters)})
        return st

    # ---- signals

    def install_signals(self) -> None:
        """Master: SIGUSR1 = checkpoint and go on; SIGTERM/SIGINT = checkpoint and stop.
        (Main thread only; elsewhere signals stay as they are.)"""
        import threading
        if threading.current_thread() is not threading.main_thread():
            return
        for sig in (signal.SIGUSR1, signal.SIGTERM, signal.SIGINT):
            self._old_handlers[sig] = signal.signal(sig, self._on_signal)

    def mark_done(self) -> None:
        """Nothing is left to save (the result or the final checkpoint is written):
        from now on SIGTERM/SIGINT/SIGUSR1 change nothing, up to the process's exit.
        They are set to SIG_IGN: CPython's finalisation resets signals that have a
        Python handler to their default action, and a SIGTERM during the seconds
        of interpreter shutdown would turn a finished run into a killed one."""
        self._done = True
        for sig in self._old_handlers:
            signal.signal(sig, signal.SIG_IGN)

    def _on_signal(self, signum, frame):
        name = signal.Signals(signum).name
        if self._done:
            return
        if signum == signal.SIGUSR1:
            self._flags.add(name)
            return
        self._flags.add("STOP:" + name)
        if not self._defer:
            self._defer = True        # a second signal must not interrupt the checkpoint write
            raise Interrupted(name)

    def _stop_flag(self):
        return next((f[5:] for f in self._flags if f.startswith("STOP:")), None)

    def _safe_point(self) -> None:
        """Between merges: act on signals and the checkpoint timer."""
        stop = self._stop_flag()
        if stop:
            raise Interrupted(stop)
        self._serve_checkpoint()

    def _serve_checkpoint(self) -> None:
        """Write the checkpoint SIGUSR1 or the timer asks for (tasks in flight saved as open)."""
        if "SIGUSR1" in self._flags:
            self._flags.discard("SIGUSR1")
            self.write_checkpoint("SIGUSR1")
        elif time.monotonic() >= self._next_ckpt:
            self.write_checkpoint("timer")

    def _in_task(self) -> bool:
        """In-process engine, polled inside a task (task_stopping): serves SIGUSR1 and
        the checkpoint timer there (the running task is saved as open), and says
        whether a SIGTERM/SIGINT asks the task to stop."""
        if self._stop_flag():
            return True
        self._serve_checkpoint()
        return False

    # ---- running jobs

    def run(self, job):
        """Run `job` to the end (resuming it from the checkpoint if it is there); returns it."""
        if not self.is_master:
            raise RuntimeError("Engine.run is for the master; workers call serve()")
        if job.name in self._jobs:
            raise ValueError(f"job name {job.name!r} used twice")
        self._defer = True            # from here on, signals act at safe points only
        try:
            state = self._restored.get(job.name)
            if state is not None:
                if state["attrs"].get("kind") != job.kind:
                    raise CheckpointError(f"job {job.name!r}: checkpoint kind {state['attrs'].get('kind')!r}, "
                                          f"this run {job.kind!r}")
                job.load(state)
                job.counters.update(json.loads(state["attrs"]["counters"]))
            self._job_id += 1
            self._current, self._inflight = job, {}
            self._job_start = (time.monotonic(), job.counters.get("tasks", 0))
            self._restored.pop(job.name, None)
            if self._stop_flag():
                raise Interrupted(self._stop_flag())
            if self.size == 1:
                self._run_serial(job)
            else:
                self._run_master(job)
            self._jobs[job.name] = job
            self._current, self._inflight = None, {}
        finally:
            self._defer = False
        if self._stop_flag():
            raise Interrupted(self._stop_flag())
        return job

    def _run_serial(self, job) -> None:
        handler = handler_for(job.kind)
        last_note = time.monotonic()
        while True:
            self._safe_point()
            taken = job.take(1)
            if taken is None:
                return
            token, payload = taken
            self._inflight[0] = token
            try:
                result = _run_cancellable(handler, job.context, payload, self._in_task)
            except TaskCancelled:
                raise Interrupted(self._stop_flag()) from None
            job.merge(token, result)           # done (or stopped, the rest handed back as open)
            del self._inflight[0]
            self.tasks_per_rank[0] += 1
            last_note = self._note(job, last_note)

    def _run_master(self, job) -> None:
        from mpi4py import MPI
        comm = self.comm
        idle = [w for w in self.workers if w not in self._inflight][::-1]
        n_workers = len(self.workers)
        last_note = time.monotonic()
        while True:
            while idle:
                taken = job.take(n_workers)
                if taken is None:
                    break
                token, payload = taken
                w = idle.pop()
                fresh = self._ctx_sent.get(w) != self._job_id
                self._ctx_sent[w] = self._job_id
                self._inflight[w] = token
                comm.send((self._job_id, job.kind, payload, fresh, job.context if fresh else None),
                          dest=w, tag=_TASK)
            if not self._inflight:
                return                         # pool empty, nothing in flight: done
            got = self._wait_any(MPI, deadline=self._next_ckpt)
            if got is not None:
                w, tag, msg = got
                idle.append(w)
                self._take_result(job, w, tag, msg)
            try:
                self._safe_point()
            except Interrupted:
                self._stop_workers(job)
                raise
            last_note = self._note(job, last_note)

    def _take_result(self, job, w: int, tag: int, msg) -> None:
        """Merge worker w's answer to its task in flight (done: in the master's state);
        a cancelled task stays open (not in flight any more: the caller keeps it)."""
        token = self._inflight.pop(w)
        if tag == _CANCELLED:
            self._inflight[w] = token
            return
        self.tasks_per_rank[w] += 1
        if tag == _ERROR and isinstance(msg, _UserFailure):
            from .scene import SceneError
            raise SceneError(msg.line)
        if tag == _ERROR:
            raise RuntimeError(f"worker rank {w} failed on a {job.kind!r} task:\n{msg}")
        job.merge(token, msg)

    def _stop_workers(self, job, timeout: float = 60.0) -> None:
        """SIGTERM/SIGINT on the master, inside a job: stop every worker and collect
        what is in flight before the checkpoint — a subtree task hands back what it
        found and its open subtrees (merged, nothing lost), another kind is
        cancelled (kept as open). At most `timeout` seconds (a worker blocked in a
        large send would never read the stop); afterwards close() has nothing to do."""
        from mpi4py import MPI
        if self._stopped:
            return
        self._stopped = True
        for w in self.workers:
            self.comm.send(None, dest=w, tag=_STOP)
        status = MPI.Status()
        waiting = set(self._inflight)
        end = time.monotonic() + timeout
        while waiting and time.monotonic() < end:
            if _probe(self.comm, MPI.ANY_SOURCE, MPI.ANY_TAG, status):
                src, tag = status.Get_source(), status.Get_tag()
                msg = self.comm.recv(source=src, tag=tag)
                if src in waiting:
                    waiting.discard(src)
                    if tag == _ERROR:                # the checkpoint must still be written
                        continue
                    self._take_result(job, src, tag, msg)
            else:
                time.sleep(0.005)

    def _wait_any(self, MPI, deadline: float):
        """The next message from any worker, or None at the deadline or on a signal."""
        status = MPI.Status()
        t0 = time.monotonic()
        while True:
            if _probe(self.comm, MPI.ANY_SOURCE, MPI.ANY_TAG, status):
                src, tag = status.Get_source(), status.Get_tag()
                return src, tag, self.comm.recv(source=src, tag=tag)
            now = time.monotonic()
            if self._flags or now >= deadline:
                return None
            time.sleep(_backoff(now - t0, POLL_MAX_MASTER))

    def _note(self, job, last: float) -> float:
        """After a merge: the memory guard (at most every GUARD_EVERY_S), and every 10 s a
        progress line."""
        now = time.monotonic()
        if self.guard is not None and now - self._guarded >= GUARD_EVERY_S:
            self._guarded = now
            self.guard.check(0, f"the {job.name!r} stage holds its results and {job.pending()} "
                                f"open tasks after {job.counters.get('tasks', 0)} tasks")
        if self.progress is None or now - last < 10.0:
            return last
        from .progress import eta
        done = job.counters.get("tasks", 0)
        left = ""
        if isinstance(job, TaskJob):           # a fixed list of tasks: the time left at this session's rate
            t0, done0 = self._job_start
            total = len(job.payloads)
            left = eta(now - t0, done - done0, total - done0)
        self.progress.note(f"{job.name}: {done} tasks done, {job.pending()} pending, "
                           f"{len(self._inflight)} running ({self.size} rank(s), {self.elapsed():.0f} s{left})")
        return now

    def summary(self) -> dict:
        """How the work was split: depends on ranks and resumes (answers do not)."""
        return {"ranks": self.size, "resumes": self.resumes, "tasks_per_rank": list(self.tasks_per_rank),
                "checkpoints_written": self.checkpoints_written,
                "last_checkpoint_reason": self.checkpoint_reason or "",
                "elapsed_s_all_sessions": self.elapsed(),
                "jobs": {name: dict(job.counters) for name, job in self._jobs.items()}}

    # ---- workers

    def serve(self) -> None:
        """Worker loop (ranks >= 1): run tasks until the master says stop.

        SIGUSR1, SIGTERM and SIGINT are ignored: the master acts on them. (mpirun
        forwards SIGUSR1 to every rank, whose default action is to die. On
        SIGTERM, mpirun sends SIGCONT to every rank, SIGTERM 1 s later and
        SIGKILL ~1 s after that; a worker that died at once would make it kill
        the master before its checkpoint is written.)

        A worker exits when its parent (mpirun) is gone, or when its master runs
        on the same host and has died (kill -9): mpirun would otherwise take
        ~2 s (SIGCONT, SIGTERM, SIGKILL) to tear the job down."""
        from mpi4py import MPI
        for sig in (signal.SIGUSR1, signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, signal.SIG_IGN)
        comm, ppid = self.comm, os.getppid()
        for mod in WARM_UP:            # while the master condenses, not at the first task
            importlib.import_module(mod)
        ctx_id, ctx = None, None
        status = MPI.Status()
        master_pid, host = None, socket.gethostname()
        while True:
            t0 = checked = time.monotonic()
            while not _probe(comm, 0, MPI.ANY_TAG, status):
                now = time.monotonic()
                if now - checked >= MASTER_CHECK_S:
                    checked = now
                    if os.getppid() != ppid or (master_pid is not None and not _pid_alive(master_pid)):
                        os._exit(3)
                time.sleep(_backoff(now - t0, POLL_MAX))
            tag = status.Get_tag()
            msg = comm.recv(source=0, tag=tag)
            if tag == _STOP:
                return
            if tag == _HELLO:
                master_pid = msg[1] if msg[0] == host else None
                continue
            job_id, kind, payload, fresh, new_ctx = msg
            if fresh:
                ctx_id, ctx = job_id, new_ctx
            try:
                if ctx_id != job_id:
                    raise RuntimeError(f"task of job {job_id} without its context")
                result = _run_cancellable(handler_for(kind), ctx, payload,
                                          lambda: _probe(comm, 0, _STOP, status))
            except TaskCancelled:
                comm.send(None, dest=0, tag=_CANCELLED)     # the stop is read next
            except MemoryError:
                from .progress import out_of_memory
                comm.send(_UserFailure(str(out_of_memory(f"a {kind!r} task on rank {comm.rank}"))), dest=0, tag=_ERROR)
            except Exception as e:          # noqa: BLE001  (the master reports it)
                from .scene import SceneError
                comm.send(_UserFailure(str(e)) if isinstance(e, SceneError) else traceback.format_exc(),
                          dest=0, tag=_ERROR)
            else:
                comm.send(result, dest=0, tag=_RESULT)

    def close(self, timeout: float = 60.0, restore_signals: bool = True) -> None:
        """Master: stop every worker — one in a task that calls task_tick() drops it
        and says so — and collect what is still in flight (a worker blocked in a
        large send would never read the stop; at most `timeout` seconds); restore
        the signal handlers (the command line keeps its own to the end: a signal
        after mark_done() must not turn a finished run into a failed one)."""
        if self.comm is not None and self.is_master and not self._stopped:
            from mpi4py import MPI
            self._stopped = True
            for w in self.workers:
                self.comm.send(None, dest=w, tag=_STOP)
            status = MPI.Status()
            end = time.monotonic() + timeout
            while self._inflight and time.monotonic() < end:
                if _probe(self.comm, MPI.ANY_SOURCE, MPI.ANY_TAG, status):
                    src, tag = status.Get_source(), status.Get_tag()
                    self.comm.recv(source=src, tag=tag)
                    self._inflight.pop(src, None)
                else:
                    time.sleep(0.005)
        if restore_signals:
            for sig, h in self._old_handlers.items():
                signal.signal(sig, h)
            self._old_handlers = {}


@dataclass
class _UserFailure:
    """A worker's task stopped on a user-facing error (run.max_memory_gb, bad input):
    its one line, raised again on the master (exit status 2, no traceback)."""

    line: str


def ranks_on_host() -> int:
    """How many ranks of this MPI job share the host (1 outside mpirun)."""
    for key in ("OMPI_COMM_WORLD_LOCAL_SIZE", "MPI_LOCALNRANKS", "SLURM_NTASKS_PER_NODE"):
        v = os.environ.get(key, "")
        if v.isdigit() and int(v) > 0:
            return int(v)
    return 1


def _pid_alive(pid: int) -> bool:
    """False once the process is gone or a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except (OSError, IndexError):
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except OSError:
            pass
        return True


def _backoff(waited: float, cap: float) -> float:
    return min(cap, max(1e-4, POLL_FRACTION * waited))


def _probe(comm, source, tag, status) -> bool:
    for _ in range(PROBE_BURST):
        if comm.Iprobe(source=source, tag=tag, status=status):
            return True
    return False


# ---------------------------------------------------------------- what the pipeline calls


def run_patterns(make_tree, mus, engine: Engine | None = None, budget: int = DEFAULT_BUDGET,
                 name: str = "patterns") -> Patterns:
    """Feasible sign patterns at every mu in `mus`, through the engine.

    make_tree: a picklable callable, make_tree(mu) -> a tree with root(), m and
    explore(subtree, budget) -> (found, open, stats[, undecided]) — e.g.
    functools.partial(patterns.PatternTree, param, m) — for 2D and 3D alike."""
    engine = engine or Engine()
    return engine.run(SubtreeJob(name, make_tree, mus, budget)).output()


def run_mu_c(solve, items, engine: Engine | None = None, name: str = "mu_c") -> list:
    """mu^c of every (zero_u, zero_r, mu_hi) in `items`, through the engine.

    solve: a picklable callable solve(zero_u, zero_r, mu_hi=...) -> mu_critical.MuC,
    e.g. functools.partial(mu_critical.mu_critical, param, m, mu_max=..., method=..., tol=...).
    Returns the MuC list in the order of items."""
    from .mu_critical import MuC
    engine = engine or Engine()
    payloads = [(np.asarray(zu, dtype=bool), np.asarray(zr, dtype=bool), float(mu_hi))
                for zu, zr, mu_hi in items]
    out = engine.run(TaskJob(name, "mu_c", solve, payloads)).output()
    return [MuC(mu_c=None if math.isnan(r["mu_c"]) else float(r["mu_c"]), polished=bool(r["polished"]),
                solves=int(r["lps"]), undecided=int(r["undecided"])) for r in out]


def run_tasks(kind: str, context, payloads: list, engine: Engine | None = None, name: str | None = None,
              layout=None, payloads_for=None) -> list:
    """Results of independent tasks of a registered kind (e.g. "face"), in order.
    Results must be dicts of numbers/bools/arrays (so that checkpoints can hold them).
    layout, payloads_for: see TaskJob (a resumed run keeps the saved layout)."""
    engine = engine or Engine()
    return engine.run(TaskJob(name or kind, kind, context, payloads, layout, payloads_for)).output()


def run_faces(rows: list, m: int, exact: bool = False, engine: Engine | None = None,
              nodes=(), name: str = "rays", max_memory_gb: float | str = "auto") -> list["DDResult"]:
    """The complementary rays at every mu, the double description split over the
    faces of the branching nodes `nodes` (SPEC §5; the scene's choice,
    dd.branching_nodes; none: one face, the whole cone), one "face" task per
    (mu, face), through the engine.

    rows: the constraint rows A of every mu (problem.friction_rows_2d). Returns one
    dd.DDResult per mu (merge_results of its faces: canonical order, duplicates
    removed, stats with faces, face_seconds and branching_nodes). A resumed run
    keeps the split its checkpoint was made with, so finished faces are reused
    whatever the rank count now is. The zero flags, and so every count, cone and
    mu^c, are those of the unsplit run; the float ray vectors equal them to
    rounding (a ray's floats depend on the DD's path to it: ~1e-13 relative), and
    bit for bit those of any run with the same split, on any number of ranks."""
    from .dd import merge_results
    engine = engine or Engine()
    nodes = [int(i) for i in nodes]

    def payloads_for(layout):
        return face_payloads(len(rows), m, layout["branching_nodes"])

    layout = {"branching_nodes": nodes}
    out = run_tasks("face", FaceContext(list(rows), m, exact, max_memory_gb), payloads_for(layout), engine, name,
                    layout=layout, payloads_for=payloads_for)
    per_mu: list = [[] for _ in rows]
    for res in out:
        per_mu[int(res["mu_index"])].append(face_result(res))
    merged = []
    for faces in per_mu:
        dd = merge_results(faces)
        split = sorted({i for f in faces for part in f.stats["face"] for i in part})
        dd.stats["branching_nodes"] = split
        merged.append(dd)
    return merged


def strip_exact(param):
    """A parametrisation without its exact (flint) copies: the float engines'
    context, cheap to pickle."""
    if getattr(param, "Uq", None) is None and getattr(param, "Rq", None) is None:
        return param
    return replace(param, Uq=None, Rq=None)
