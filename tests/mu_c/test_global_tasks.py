"""The 3D global bracket split into tasks (mu_c/global_tasks.py) against the one-task bracket
(global_search.bracket_task, the route before the split): the same best value bit for bit,
status, pattern and every counter, serially with rounds of 1 to 4 nodes, and under the real
`mpirun -n 3` through the command line; the walk's rounds against PatternTree.explore where
predictions fail."""
from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.linalg as sla
from instances import plug3d_param, random_problem_3d, rigid_modes_local_3d, symmetric_problem_3d
from mpi_helpers import needs_mpirun, run, show_json

from hpcwedge.contact.problem import ContactProblem, parametrize
from hpcwedge.mu_c import global_tasks
from hpcwedge.mu_c.global_search import BRACKET_STATUS, GlobalSearch, bracket_task, run_bracket
from hpcwedge.parallel.engine import Engine, run_tasks
from hpcwedge.patterns.symmetry import node_symmetries
from hpcwedge.patterns.tree import PatternTree, Subtree
from hpcwedge.solvers.feasibility import DEFAULT_OPTIONS, Decision
from hpcwedge.solvers.rows import Status


def search_of(param, m: int, symmetry=None) -> GlobalSearch:
    return GlobalSearch(param, m, 100.0, "accurate", 1e-6, symmetry, None, "auto", True)


def same_bracket(a: dict, b: dict) -> None:
    """Two bracket results agree: best to the bit, status, pattern, counts (the split's
    unused decisions aside)."""
    sa, sb = json.loads(a["stats"]), json.loads(b["stats"])
    sb["extra"].pop("dive_unused", None)
    assert np.array_equal(np.float64(a["best"]), np.float64(b["best"]), equal_nan=True)
    assert int(a["status"]) == int(b["status"])
    assert np.array_equal(a["zero_u"], b["zero_u"]) and np.array_equal(a["zero_r"], b["zero_r"])
    assert sa == sb


def bodies():
    """(param, m, symmetry): free and supported random bodies (m = 5..7), a free plug, and a
    symmetric random body searched with its node symmetries (orbital branching and fixing)."""
    out = []
    for seed in range(3):
        for free in (True, False):
            m = 5 + seed
            out.append((parametrize(random_problem_3d(np.random.default_rng(seed), m, free)), m, None))
    out.append((*plug3d_param(2, 5), None))
    prob = symmetric_problem_3d(np.random.default_rng(1), 6, free=True)
    out.append((parametrize(prob), 6, node_symmetries(prob.K, 3)))
    assert out[-1][2].order >= 6
    return out


@pytest.mark.parametrize("chain", [(1, 2), (4, 4)])
def test_split_bracket_is_the_one_task_bracket(monkeypatch, chain):
    """Rounds of 1 (then 2) or 4 nodes: the bracket's answer and counts equal the one task's
    on random bodies and a plug, in several rounds of node tasks."""
    monkeypatch.setattr(global_tasks, "CHAIN_FIRST", chain[0])
    monkeypatch.setattr(global_tasks, "CHAIN_MAX", chain[1])
    for param, m, symmetry in bodies():
        search = search_of(param, m, symmetry)
        want = run_tasks(bracket_task, search, [0], engine=Engine(), kind="global_bracket")[0]
        engine = Engine()
        got = run_bracket(search, engine)
        same_bracket(want, got)
        assert BRACKET_STATUS[int(got["status"])] == "settle"
        jobs = engine.summary()["jobs"]
        assert jobs["global_bracket"]["tasks"] == 1 + chain[0] and "global_dive_1" in jobs


def test_no_wedge_at_any_mu_drops_the_bracket():
    """A body whose contact normals all point up from a flat floor has no wedge at any mu: the
    split says "none_at_any_mu" with the frictionless dive's counts alone, as the one task."""
    rng = np.random.default_rng(1)
    m = 6
    pts = rng.uniform(-1, 1, size=(m, 3))
    pts[:, 2] = 0.0
    frames = np.tile(np.eye(3), (m, 1, 1))
    M = rigid_modes_local_3d(pts, frames)
    U, s, _ = np.linalg.svd(M, full_matrices=False)
    N = U[:, s > 1e-10 * s[0]]
    B = sla.null_space(N.T)
    G = rng.standard_normal((B.shape[1], B.shape[1]))
    K = B @ (G @ G.T + 0.2 * np.eye(B.shape[1])) @ B.T
    search = search_of(parametrize(ContactProblem(3, 0.5 * (K + K.T), N)), m)
    want = run_tasks(bracket_task, search, [0], engine=Engine(), kind="global_bracket")[0]
    got = run_bracket(search, Engine())
    assert BRACKET_STATUS[int(want["status"])] == "none_at_any_mu"
    same_bracket(want, got)


class Oracle(PatternTree):
    """The frictionless tree of a plug with made-up decisions (`oracle_decision`): a test of
    the walk, not of a body."""

    def _solve(self, node, mu, stats):
        stats.solves += 1
        return oracle_decision(self.m, node.contact)


def oracle_decision(m: int, contact: int) -> Decision:
    """Infeasible when the contact set holds nodes m-1 and m-3 (a contact child broken
    from depth 3 on) or m-2 and m-5; else feasible, with no point."""
    bad = (contact >> (m - 1) & 1 and contact >> (m - 3) & 1) or (contact >> (m - 2) & 1 and contact >> (m - 5) & 1)
    return Decision(Status.INFEASIBLE if bad else Status.FEASIBLE)


def test_the_walk_follows_explore_where_the_path_breaks(monkeypatch):
    """Where contact children are infeasible the predicted path breaks: the split's rounds
    start again from the node the walk needs, and its leaf and counters are those of
    PatternTree.explore with the same decisions; the decisions below a broken node are
    counted as unused."""
    param, m = plug3d_param(2, 5)
    tree = Oracle(param, m, np.inf, False, options=DEFAULT_OPTIONS)
    want = tree.explore(Subtree(0), first_only=True)
    monkeypatch.setattr(global_tasks, "node_decision",
                        lambda search, key: (oracle_decision(search.m, key[1]), {"oracle": 1}))
    monkeypatch.setattr(global_tasks, "CHAIN_FIRST", 3)
    search = search_of(param, m)
    ctx = global_tasks.DiveContext(search, bracket_task)
    start = {"best": None, "bound": 100.0, "zero_u": [False] * m, "zero_r": [False] * m,
             "stats": json.dumps({"solves": 0, "skipped": 0, "pruned": 0, "undecided": 0, "nodes": 0, "lps": 0,
                                  "extra": {}, "statuses": {}})}
    engine = Engine()
    leaf, stats, _ = global_tasks.split_bracket(ctx, start, engine)
    assert leaf == want.found[0]
    assert (stats.nodes, stats.solves, stats.skipped) == (want.stats.nodes, want.stats.solves, want.stats.skipped)
    assert stats.statuses["oracle"] == want.stats.solves and want.stats.nodes > m + 1
    assert stats.extra["dive_unused"] > 0
    assert len([j for j in engine.summary()["jobs"] if j.startswith("global_dive_")]) >= 2


GLOBAL_32 = """name = "plug3d-4x8"
dim = 3
[model]
kind = "plug3d"
levels = 4
ring = 8
taper_deg = 10.0
[friction]
mu = [0.1]
[compute]
enumerate = false
mu_c = "global"
[run]
symmetry = false
"""


@pytest.mark.mpi
@needs_mpirun
def test_mpirun_3_global_mu_c_is_the_serial_one(tmp_path):
    """plug3d 4 x 8 (m = 32: two rounds of node tasks, the first beside the bracket): `mpirun -n 3`
    gives the serial run's global mu^c bit for bit and the same stats.bnb, and its workers
    really shared the bracket's job."""
    scene = tmp_path / "g.toml"
    scene.write_text(GLOBAL_32)
    run(None, "run", str(scene), "-o", str(tmp_path / "serial.h5"), "-q")
    run(3, "run", str(scene), "-o", str(tmp_path / "mpi.h5"), "-q")
    a, b = show_json(str(tmp_path / "serial.h5")), show_json(str(tmp_path / "mpi.h5"))
    assert a["mu_c"] == b["mu_c"] and a["mu_c_status"] == b["mu_c_status"] == "found"
    assert np.float64(a["mu_c"]).tobytes() == np.float64(b["mu_c"]).tobytes()
    assert a["stats"]["bnb"] == b["stats"]["bnb"]
    par = b["stats"]["parallel"]
    assert par["ranks"] == 3 and all(n > 0 for n in par["tasks_per_rank"][1:]), par
    assert par["jobs"]["global_bracket"]["tasks"] == a["stats"]["parallel"]["jobs"]["global_bracket"]["tasks"] == 1 + 32
    assert "global_dive_1" in par["jobs"]
