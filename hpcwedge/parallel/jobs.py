"""The generic job of the engine: a fixed list of independent tasks (`TaskJob`).

A *job* is a pool of tasks and the merge of their results: ``name``, ``kind`` (a label
its checkpoint keeps), ``handler`` (a module-level callable ``handler(context, payload) ->
result``, sent to the workers by reference, as mpi4py.futures does), ``context`` (the
job's shared read-only data, sent once to each worker), ``counters``, and pending(),
take(n_workers, scale) -> (token, payload) | None (scale: how many times its usual work
the task may do, at most the job's ``max_scale``, 1 if it has none), merge(token, result), save(in_flight) /
load(state) to and from plain arrays and attributes (checkpoint.py writes them),
progress() and output(). The engine knows nothing else of a job. Two generic jobs:
`TaskJob`, a fixed list of independent tasks, and `TreeJob`, a budgeted tree search whose
open nodes travel between the master's pool and the tasks (its subclass gives their
checkpoint encoding).
"""
from __future__ import annotations

import heapq
import json
import math

import numpy as np

from hpcwedge.parallel.cancel import Continuation
from hpcwedge.parallel.checkpoint import CheckpointError


class TaskJob:
    """A fixed list of independent tasks run by one handler; results are dicts whose
    values are numbers/bools (stored as one column per key) or arrays (stored
    concatenated along axis 0, with <key>_offsets). Checkpoint data: done (the
    indices whose result is in), the result columns.

    layout: optional JSON value from which the payloads were made (e.g. the face
    split, which depends on the rank count); it is saved, and a resumed job whose
    layout differs takes the saved one, with payloads_for(saved layout) as its
    payloads, so that the finished tasks stay valid (without payloads_for a
    differing layout is a CheckpointError). Results should then say which task they
    answer: their order follows the adopted payloads.

    A task may return a `Continuation` (cancel.task_pausing): its payload replaces the
    task's, the task stays open and is handed out next; the checkpoint keeps such payloads
    (JSON, attribute "continued"), so a resumed run goes on from there. It is not a task
    done (counters["tasks"] counts results; counters["continued"] the continuations)."""

    def __init__(self, name: str, handler, context, payloads: list, *, kind: str | None = None,
                 layout=None, payloads_for=None):
        self.name, self.handler, self.context = name, handler, context
        self.kind = kind or handler.__name__
        self.layout, self.payloads_for = _json_value(layout), payloads_for
        self.payloads = list(payloads)
        self.results: list = [None] * len(self.payloads)
        self._todo = list(range(len(self.payloads)))[::-1]
        self.counters = {"tasks": 0}
        self._continued: dict = {}       # index -> payload of a task continued, while open

    def pending(self) -> int:
        return len(self._todo)

    def progress(self) -> str:
        """Nothing beyond the task counts (the engine adds the time left)."""
        return ""

    def take(self, n_workers: int, scale: int = 1):
        if not self._todo:
            return None
        k = self._todo.pop()
        return k, self.payloads[k]

    def merge(self, token, result) -> None:
        if isinstance(result, Continuation):
            self.payloads[token] = self._continued[token] = result.payload
            self._todo.append(token)
            self.counters["continued"] = self.counters.get("continued", 0) + 1
            return
        self._continued.pop(token, None)
        self.results[token] = result
        self.counters["tasks"] += 1

    def save(self, in_flight) -> dict:
        done = [k for k, r in enumerate(self.results) if r is not None]
        data = {"done": np.array(done, dtype=np.int64)}
        # the keys every result has (a job resumed from an older version's checkpoint mixes its
        # results with this version's, which may carry more)
        keys = sorted(set.intersection(*(set(self.results[k]) for k in done))) if done else []
        for key in keys:
            vals = [self.results[k][key] for k in done]
            if all(np.ndim(v) == 0 for v in vals):
                data[key] = np.array(vals)
            else:
                arrs = [np.atleast_1d(np.asarray(v)) for v in vals]
                data[key] = np.concatenate(arrs, axis=0)
                data[key + "_offsets"] = np.cumsum([0] + [len(a) for a in arrs])
        continued = {str(k): p for k, p in self._continued.items() if self.results[k] is None}
        return {"attrs": {"n_tasks": len(self.payloads), "result_keys": json.dumps(keys),
                          "layout": json.dumps(self.layout), "continued": json.dumps(continued)},
                "data": data}

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
        self._continued = {int(k): p for k, p in json.loads(a.get("continued", "{}")).items()}
        for k, p in self._continued.items():
            self.payloads[k] = p
        self._todo = [k for k in range(len(self.payloads)) if self.results[k] is None][::-1]
        self.counters["tasks"] = len(done)

    def output(self) -> list:
        return self.results


def _json_value(v):
    """v as it reads back from JSON (tuples become lists), for comparisons."""
    return json.loads(json.dumps(v))


#: the largest multiple of its budget a TreeJob task gets (the engine's scale, schedule.cut)
BUDGET_SCALE = 16


class TreeJob:
    """A budgeted search over the trees of one or more groups (after mplrs' budgets).

    handler(context, (group, node, budget, witness)) explores at most `budget` nodes below
    `node` and returns (found, open, counters, flagged, witnesses): the leaves it found, the
    nodes it left open with one witness each (data the node's exploration may reuse, or
    None), its counters (summed into the job's), and the found leaves it doubts. A node
    has a `depth`; the pool hands out the shallowest first, in push order among equals. A
    task explores one node while the pool holds fewer nodes than there are workers (more
    than one: the ramp-up and the tail, where a node handed back at once feeds an idle
    worker soonest), `budget` nodes while it holds fewer than two per worker, and budget x
    scale (the engine's, at most max_scale) when it is long. Tasks are always bounded, so a
    checkpoint never waits long and loses little.

    A subclass gives save() / load() from `saved_nodes` / `restore` and output()."""

    kind = "tree"
    max_scale = BUDGET_SCALE

    def __init__(self, name: str, handler, context, roots: list, budget: int, counters: dict,
                 groups: int | None = None):
        self.name, self.handler, self.context, self.budget = name, handler, context, int(budget)
        groups = len(roots) if groups is None else groups
        self.found: list[list] = [[] for _ in range(groups)]
        self.flagged: list[list] = [[] for _ in range(groups)]
        self.counters = {"tasks": 0, "handed_back": 0, **counters}
        self._pool: list = []
        self._seq = 0
        #: the roots' mass (decided_share)
        self._mass = sum(math.ldexp(1.0, -node.depth) for node in roots)
        for group, node in enumerate(roots):
            self._push(group, node)

    def _push(self, group: int, node, witness=None) -> None:
        heapq.heappush(self._pool, (node.depth, self._seq, group, node, witness))
        self._seq += 1

    def pending(self) -> int:
        return len(self._pool)

    def progress(self) -> str:
        """What a subclass adds to the engine's progress line (e.g. ", 3 leaves found")."""
        return ""

    def take(self, n_workers: int, scale: int = 1):
        if not self._pool:
            return None
        _, _, group, node, witness = heapq.heappop(self._pool)
        left = len(self._pool)
        budget = (1 if n_workers > 1 and left < n_workers else self.budget if left < 2 * n_workers
                  else self.budget * max(1, min(int(scale), self.max_scale)))
        return (group, node, witness), (group, node, budget, witness)

    def merge(self, token, result) -> None:
        group = token[0]
        found, open_, counters, flagged, witnesses = result
        self.found[group].extend(found)
        self.flagged[group].extend(flagged)
        for node, witness in zip(open_, witnesses, strict=True):
            self._push(group, node, witness)
        self.counters["tasks"] += 1
        self.counters["handed_back"] += len(open_)
        for k, v in counters.items():
            self.counters[k] = self.counters.get(k, 0) + v

    def put(self, tokens: list) -> None:
        """Open nodes, as take()'s tokens (group, node, witness), into the pool (hub.py)."""
        for group, node, witness in tokens:
            self._push(group, node, witness)

    def give(self, n: int) -> list:
        """The n shallowest open nodes out of the pool, as tokens (hub.py)."""
        return [heapq.heappop(self._pool)[2:] for _ in range(min(n, len(self._pool)))]

    def absorb(self, found: list, flagged: list, counters: dict) -> None:
        """Leaves found (a list per group), those doubted, and counters summed in: what a hub
        reports of the tasks it merged (hub.py)."""
        for group, (leaves, doubt) in enumerate(zip(found, flagged, strict=True)):
            self.found[group].extend(leaves)
            self.flagged[group].extend(doubt)
        for k, v in counters.items():
            self.counters[k] = self.counters.get(k, 0) + v

    def saved_nodes(self, in_flight) -> tuple[list, list]:
        """What a checkpoint keeps: [(group, leaf, flagged)] found, and [(group, node,
        witness)] open (the pool, then the tasks in flight, whose tokens are these)."""
        doubt = [set(f) for f in self.flagged]
        found = [(g, leaf, leaf in doubt[g]) for g, leaves in enumerate(self.found) for leaf in leaves]
        return found, self.open_nodes(in_flight)

    def open_nodes(self, in_flight) -> list:
        """[(group, node, witness)]: the pool's open nodes, then those of the tasks in flight."""
        return [(g, n, w) for _, _, g, n, w in self._pool] + [tuple(t) for t in in_flight]

    def decided_share(self, in_flight) -> float:
        """The share of the trees decided, in [0, 1]: 1 - the open nodes' mass over the roots',
        a node at depth d weighing 2^-d (the share of a binary tree's leaves below it). It
        never falls: a node's children weigh no more than it (depth d + 1 each, or deeper),
        and a closed node weighs nothing. in_flight: the tokens of the tasks in flight."""
        if not self._mass:
            return 1.0
        left = sum(math.ldexp(1.0, -node.depth) for _, node, _ in self.open_nodes(in_flight))
        return min(1.0, max(0.0, 1.0 - left / self._mass))

    def restore(self, found: list, opens: list) -> None:
        """The state of saved_nodes' lists (a resumed job)."""
        self.found = [[] for _ in self.found]
        self.flagged = [[] for _ in self.flagged]
        for group, leaf, flagged in found:
            self.found[group].append(leaf)
            if flagged:
                self.flagged[group].append(leaf)
        self._pool, self._seq = [], 0
        for group, node, witness in opens:
            self._push(group, node, witness)

