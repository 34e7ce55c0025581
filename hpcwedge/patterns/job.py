"""The sign-pattern search as a job of the parallel engine: the engine's generic budgeted
tree search (parallel.jobs.TreeJob) over PatternTree subtrees, and their checkpoint
encoding (SPEC §5).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hpcwedge.nodesets import bits_to_words, pattern_key, words_to_bits
from hpcwedge.parallel.checkpoint import CheckpointError
from hpcwedge.parallel.engine import Engine
from hpcwedge.parallel.jobs import TreeJob
from hpcwedge.patterns.tree import STAT_KEYS, PatternContext, Subtree, explore_task

#: default node budget of a subtree task (scene key run.task_budget)
DEFAULT_BUDGET = 64


class SubtreeJob(TreeJob):
    """The sign-pattern trees of every mu (a group each), explored by budgeted subtree tasks
    (parallel.jobs.TreeJob): a leaf is a feasible full pattern, a flagged one is undecided.

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
        self.mus = [float(v) for v in mus]
        context = PatternContext(make_tree, self.mus)
        trees = [context.tree(i) for i in range(len(self.mus))]
        self.m = trees[0].m if trees else 0
        #: the trees find orbit representatives (a symmetry), expanded at the end
        self._representatives = any(getattr(t, "symmetry", None) is not None for t in trees)
        super().__init__(name, explore_task, context, [t.root() for t in trees], budget,
                         {k: 0 for k in STAT_KEYS})

    def progress(self) -> str:
        """What the engine's progress line adds for this job: patterns found so far (the
        orbit representatives where a tree has a symmetry, expanded at the end) and tree
        nodes visited."""
        what = "pattern representatives" if self._representatives else "patterns"
        return (f", {sum(map(len, self.found))} {what} found, "
                f"{self.counters.get('nodes', 0)} tree nodes")

    def save(self, in_flight) -> dict:
        words = max(1, math.ceil(self.m / 64))
        found, opens = self.saved_nodes(in_flight)
        xs = [x for _, _, x in opens]
        d = next((len(x) for x in xs if x is not None), 0)
        data = {"mus": np.array(self.mus, dtype=float),
                "found_mu": np.array([i for i, _, _ in found], dtype=np.int32),
                "found_depth": np.array([s.depth for _, s, _ in found], dtype=np.int32),
                "found_contact": bits_to_words([s.contact for _, s, _ in found], words),
                "found_gap": bits_to_words([s.gap for _, s, _ in found], words),
                "found_undecided": np.array([u for _, _, u in found], dtype=bool),
                "open_mu": np.array([i for i, _, _ in opens], dtype=np.int32),
                "open_depth": np.array([s.depth for _, s, _ in opens], dtype=np.int32),
                "open_contact": bits_to_words([s.contact for _, s, _ in opens], words),
                "open_gap": bits_to_words([s.gap for _, s, _ in opens], words),
                "open_has_x": np.array([x is not None for x in xs], dtype=bool),
                "open_x": np.array([np.zeros(d) if x is None else np.asarray(x, dtype=np.float64) for x in xs],
                                   dtype=np.float64).reshape(len(xs), d)}
        return {"attrs": {"m": self.m, "budget": self.budget}, "data": data}

    def load(self, state: dict) -> None:
        a, d = state["attrs"], state["data"]
        if int(a["m"]) != self.m or list(np.asarray(d["mus"], dtype=float)) != self.mus:
            raise CheckpointError(f"job {self.name!r}: the checkpoint was taken on other mu values or m")
        found = [(int(i), Subtree(int(depth), c, g), bool(u))
                 for i, depth, c, g, u in zip(d["found_mu"], d["found_depth"], words_to_bits(d["found_contact"]),
                                              words_to_bits(d["found_gap"]), d["found_undecided"])]
        n = len(d["open_mu"])
        has_x = d.get("open_has_x", np.zeros(n, dtype=bool))
        xs = d.get("open_x", np.zeros((n, 0)))
        opens = [(int(i), Subtree(int(depth), c, g), np.array(x, dtype=np.float64) if h else None)
                 for i, depth, c, g, h, x in zip(d["open_mu"], d["open_depth"], words_to_bits(d["open_contact"]),
                                                 words_to_bits(d["open_gap"]), has_x, xs)]
        self.restore(found, opens)

    def output(self) -> "Patterns":
        key = lambda s: pattern_key(s.contact)
        return Patterns(mus=self.mus, m=self.m,
                        found=[sorted(lst, key=key) for lst in self.found],
                        undecided=[sorted(lst, key=key) for lst in self.flagged],
                        counters=dict(self.counters))


def describe_saved(attrs, data) -> dict | None:
    """What `show` says of a saved SubtreeJob (parallel.checkpoint.checkpoint_summary's
    describe): its mu values, patterns found, subtrees open and the share of its trees decided
    (TreeJob.decided_share: every mu's tree has one root, at depth 0; the tasks in flight were
    saved as open); None for other jobs."""
    if attrs["kind"] != SubtreeJob.kind:
        return None
    mus = [float(v) for v in data["mus"]]
    left = float(np.ldexp(1.0, -np.asarray(data["open_depth"], dtype=np.int64)).sum()) if len(data["open_depth"]) else 0.0
    return {"mu": mus, "found": len(data["found_mu"]), "open": len(data["open_mu"]),
            "decided": min(1.0, max(0.0, 1.0 - left / len(mus))) if mus else 1.0}


@dataclass
class Patterns:
    """run_patterns' answer: per mu (in the given order) the feasible full
    patterns (patterns.Subtree, depth m) in canonical order, the ones among
    them no solver decided, and the job's counters: nodes (tree nodes visited),
    solves, skipped, pruned, undecided and status_* (how each solve was decided)
    are the same for every split, rank count or resume (open subtrees carry their
    witness); tasks and handed_back depend
    on the schedule (the pipeline reports them under stats.parallel only)."""

    mus: list
    m: int
    found: list
    undecided: list
    counters: dict = field(default_factory=dict)


def run_patterns(make_tree, mus, engine: Engine | None = None, budget: int = DEFAULT_BUDGET,
                 name: str = "patterns") -> Patterns:
    """Feasible sign patterns at every mu in `mus`, through the engine.

    make_tree: a picklable callable, make_tree(mu) -> a tree with root(), m and
    explore(subtree, budget) -> (found, open, stats[, undecided]) — e.g.
    functools.partial(PatternTree, param, m) — for 2D and 3D alike."""
    engine = engine or Engine()
    return engine.run(SubtreeJob(name, make_tree, mus, budget)).output()
