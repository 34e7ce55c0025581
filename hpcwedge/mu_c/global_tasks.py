"""The 3D global search's bracket as tasks that run at once (global_search.run_bracket).

The bracket is a chain: the dive with r_t free (is there any wedge at all?), then the dive
at mu_max, the certified mu^c of its leaf, the dive a step below, and so on; every tree
node of a dive waits for its parent's problem. Two things need nothing of what comes before:

- the rest of the bracket (from mu_max) needs of the frictionless dive only whether it found
  a leaf: the two run as tasks of one job, and the bracket's result is dropped when the
  frictionless dive finds none ("none_at_any_mu", as before);
- with r_t free the tree branches in its static order, so the path of contact children
  below a node is known before any of them is solved (`Prefetched.predicted`): the next
  `size` nodes on it are decided as separate tasks (`dive_task`, each a function of its
  node alone), and the master then walks the tree with those decisions in place of its own
  solves (`Prefetched`). A node the walk needs and no task decided (the path left the
  prediction at an infeasible contact child) starts the next round of tasks from it.

A round's size is CHAIN_FIRST, doubled (to CHAIN_MAX) after a round the walk used to its
end. The tasks follow from the walk alone, never from the rank count: the leaf, every
decision and every counter are those of the one-task dive, for any rank count, budget or
resume (SPEC §5); decisions computed and not used (below an infeasible node) are counted
as stats.extra["dive_unused"].
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from hpcwedge.parallel.cancel import TaskCancelled
from hpcwedge.parallel.engine import Engine, run_tasks
from hpcwedge.patterns.tree import BnBStats, PatternTree, Subtree
from hpcwedge.solvers.feasibility import DEFAULT_OPTIONS, Decision, decide
from hpcwedge.solvers.rows import Status, pattern_rows

#: tree nodes decided ahead in the first round and at most in one round. The first round
#: shares its job with the bracket's task, and a job's tasks go to whichever worker is free,
#: so its nodes fill in for that task's length (plug3d 8 x 16: the bracket ~10 s, a node's
#: LP ~0.5 s, 129 nodes in rounds of 32, 64 and 33)
CHAIN_FIRST, CHAIN_MAX = 32, 64
#: the decision statuses as task results carry them (an index)
STATUSES = tuple(Status)


@dataclass(frozen=True)
class DiveContext:
    """The split bracket's job context: `search` (global_search.GlobalSearch: param, m,
    symmetry) and `bracket(search, payload)`, the bracket's own task (bracket_task)."""

    search: object
    bracket: Callable


def node_decision(search, key: tuple[int, int, int]) -> tuple[Decision, dict]:
    """(decision, statuses counted) of the frictionless tree node key = (depth, contact,
    gap), exactly as PatternTree(..., friction=False, options=DEFAULT_OPTIONS) solves it."""
    zu, zr = Subtree(*key).masks(search.m)
    counts: dict = {}
    dec = decide(pattern_rows(search.param, search.m, zu, zr, False), 0.0, DEFAULT_OPTIONS, counts)
    return dec, counts


def dive_task(ctx: DiveContext, payload):
    """Task of the split bracket. payload a dict: the bracket from that state (ctx.bracket;
    its result, or its Continuation); a (depth, contact, gap) tuple: that node's decision.
    Either result has the keys of the bracket's (best, status, zero_u, zero_r, stats) and x,
    positive; a node's status is an index into STATUSES, its stats its statuses' JSON."""
    import json
    if isinstance(payload, dict):
        out = ctx.bracket(ctx.search, payload)
        return out if not isinstance(out, dict) else {**out, "x": np.zeros(0), "positive": False}
    dec, counts = node_decision(ctx.search, tuple(int(v) for v in payload))
    none = np.zeros(0, dtype=bool)
    return {"best": np.nan, "status": STATUSES.index(dec.status), "zero_u": none, "zero_r": none,
            "stats": json.dumps(counts, sort_keys=True).encode(),
            "x": np.zeros(0) if dec.x is None else np.asarray(dec.x, dtype=float), "positive": bool(dec.positive)}


class Prefetched(PatternTree):
    """The frictionless tree with its node problems looked up in `decided` ((depth, contact,
    gap) -> (Decision, statuses)) instead of solved, counted as the tree counts its own
    solves; a node not there stops explore (handed back open, no count changed, as at a
    stop). `used`: the keys looked up."""

    def __init__(self, search):
        super().__init__(search.param, search.m, np.inf, False, symmetry=search.symmetry, options=DEFAULT_OPTIONS)
        self.decided: dict = {}
        self.used: set = set()
        self._path: list | None = None

    def _solve(self, node: Subtree, mu: float, stats: BnBStats) -> Decision:
        key = (node.depth, node.contact, node.gap)
        if self._path is not None:                # predicting: every node feasible, no point
            self._path.append(key)
            return Decision(Status.FEASIBLE)
        if key not in self.decided:
            raise TaskCancelled()
        dec, counts = self.decided[key]
        self.used.add(key)
        stats.solves += 1
        for k, v in counts.items():
            stats.statuses[k] = stats.statuses.get(k, 0) + v
        return dec

    def predicted(self, node: Subtree, x, size: int) -> list[tuple[int, int, int]]:
        """The next `size` nodes explore would solve from (node, witness x) if every one
        were feasible (the contact-first descent; those a parent's point decides are left
        out), less those decided already."""
        self._path = []
        try:
            self.explore(node, budget=size, first_only=True, x=x)
        finally:
            path, self._path = self._path, None
        return [k for k in path if k not in self.decided]


def split_bracket(ctx: DiveContext, start: dict, engine: Engine) -> tuple[Subtree | None, BnBStats, dict]:
    """(first leaf of the frictionless dive or None, its counts, the bracket's result from
    `start`): jobs "global_bracket" (the bracket's task, then the first round of node
    decisions) and "global_dive_<k>" (the later rounds). Module doc."""
    tree, stats = Prefetched(ctx.search), BnBStats()
    opens = [(tree.root(), None)]
    chain = tree.predicted(tree.root(), None, CHAIN_FIRST)
    results = run_tasks(dive_task, ctx, [start, *chain], engine=engine, name="global_bracket", kind="global_bracket")
    bracket, rnd = results[0], 0
    while True:
        _record(tree, chain, results[-len(chain):] if chain else [])
        leaf, opens = _walk(tree, opens, stats)
        if leaf is not None or not opens:
            break
        size = min(2 * len(chain), CHAIN_MAX) if set(chain) <= tree.used else CHAIN_FIRST
        chain, rnd = tree.predicted(*opens[0], size), rnd + 1
        results = run_tasks(dive_task, ctx, chain, engine=engine, name=f"global_dive_{rnd}", kind="global_dive")
    unused = len(set(tree.decided) - tree.used)
    if unused:
        stats.extra["dive_unused"] = unused
    return leaf, stats, bracket


def _record(tree: Prefetched, chain: list, results: list) -> None:
    """The tasks' decisions of the nodes `chain` into tree.decided."""
    import json
    for key, r in zip(chain, results, strict=True):
        x = np.asarray(r["x"], dtype=float)
        dec = Decision(STATUSES[int(r["status"])], x if x.size else None, bool(r["positive"]))
        stats = r["stats"]
        tree.decided[key] = (dec, json.loads(stats.decode() if isinstance(stats, bytes) else stats))


def _walk(tree: Prefetched, opens: list, stats: BnBStats) -> tuple[Subtree | None, list]:
    """The depth-first dive over the open subtrees (node, witness) in order, with the
    decisions known: (its first leaf, []), or (None, the open subtrees, the first one a node
    no task decided), or (None, []) when the tree holds no leaf. Counted into stats."""
    while opens:
        node, x = opens[0]
        out = tree.explore(node, first_only=True, x=x)
        stats.add(out.stats)
        if out.found:
            return out.found[0], []
        opens = list(zip(out.open, out.open_x)) + opens[1:] if out.stopped else opens[1:]
        if out.stopped:
            return None, opens
    return None, []
