"""faces.py: the face split of the DD (SPEC §5). Every face run gives exactly the full
run's rays on its face, the merge of the 2^k faces is the full run (canonical order,
whatever order the faces arrive in), on random bodies and on plug2d, float and exact."""
import json
import os
import signal

import numpy as np
import pytest
from instances import random_problem

from hpcwedge.contact.problem import friction_rows_2d, parametrize
from hpcwedge.errors import Interrupted
from hpcwedge.nodesets import canonical_order
from hpcwedge.parallel.checkpoint import CheckpointError, read_checkpoint
from hpcwedge.parallel.engine import Engine
from hpcwedge.parallel.jobs import TaskJob
from hpcwedge.rays import faces
from hpcwedge.rays.dd import complementary_rays
from hpcwedge.rays.faces import branching_nodes, face_task, merge_results, run_faces, split_faces


def _on_face(zero: np.ndarray, face) -> np.ndarray:
    contact, gap = face
    ok = np.ones(len(zero), dtype=bool)
    for i in contact:
        ok &= zero[:, 3 * i]
    for i in gap:
        ok &= zero[:, 3 * i + 1] & zero[:, 3 * i + 2]
    return ok


FACE_CASES = [(seed, m, free, nodes) for seed in range(12) for m, free, nodes in
              [(2, False, (1,)), (2, True, (0, 1)), (3, True, (2,)), (3, False, (0, 2)),
               (4, True, (3, 1)), (4, False, (0, 1, 2)), (5, True, (4, 2))]]


@pytest.mark.parametrize("seed,m,free,nodes,exact",
                         [c + (ex,) for c in FACE_CASES for ex in (False, True) if c[1] <= 4 or not ex])
def test_faces_union_is_full(seed, m, free, nodes, exact):
    """Every face run gives exactly the full run's rays on that face; the merged
    union of the 2^k faces is the full ray set, without duplicates."""
    rng = np.random.default_rng(500 + 1000 * seed + 10 * m + free)
    prob = random_problem(rng, m, free)
    mu = float(rng.uniform(0.2, 1.5))
    p = parametrize(prob, exact=exact)
    A = friction_rows_2d(p, mu, m, exact=exact)
    full = complementary_rays(A, m, exact=exact)
    ref = set(map(tuple, full.zero))
    faces = split_faces(m, nodes)
    assert len(faces) == 2 ** len(nodes)
    results = [complementary_rays(A, m, exact=exact, face=f) for f in faces]
    for f, r in zip(faces, results):
        assert set(map(tuple, r.zero)) == set(map(tuple, full.zero[_on_face(full.zero, f)]))
        assert _on_face(r.zero, f).all()
    merged = merge_results(results)
    assert len(merged.zero) == len(ref) and set(map(tuple, merged.zero)) == ref
    # canonical order, independent of the order in which the face results arrive
    assert np.array_equal(np.lexsort(merged.zero.T[::-1]), np.arange(len(merged.zero)))
    again = merge_results(results[::-1])
    assert np.array_equal(again.zero, merged.zero)
    assert np.array_equal(again.X, merged.X)
    if not exact:
        V = merged.X @ A.T
        assert np.all(V >= -1e-9)
        assert np.array_equal(np.abs(V) <= 1e-9, merged.zero)


@pytest.mark.parametrize("seed", range(6))
def test_face_with_node_in_contact_and_gap(seed):
    """A face may fix u_n = 0 and r = 0 at the same node."""
    rng = np.random.default_rng(900 + seed)
    m = 4
    prob = random_problem(rng, m, free=bool(seed % 2))
    p = parametrize(prob)
    A = friction_rows_2d(p, 0.9, m)
    full = complementary_rays(A, m)
    for face in [((1,), (1,)), ((0, 2), (2, 3)), ((), ())]:
        r = complementary_rays(A, m, face=face)
        assert set(map(tuple, r.zero)) == set(map(tuple, full.zero[_on_face(full.zero, face)]))


def test_split_faces():
    assert split_faces(4, [2]) == [((2,), ()), ((), (2,))]
    assert split_faces(4, [3, 1]) == [((1, 3), ()), ((3,), (1,)), ((1,), (3,)), ((), (1, 3))]
    assert split_faces(4, []) == [((), ())]
    with pytest.raises(ValueError):
        split_faces(4, [4])
    with pytest.raises(ValueError):
        split_faces(4, [1, 1])


@pytest.fixture(scope="module")
def plug2d_rows():
    from hpcwedge.contact.condense import condense
    from hpcwedge.contact.problem import ContactProblem
    from hpcwedge.models.library import plug2d

    def rows(n, exact=False):
        K, N = condense(plug2d(n, 3, 10.0))
        p = parametrize(ContactProblem(2, K, N), exact=exact)
        return friction_rows_2d(p, 0.65, 2 * n, exact=exact)
    return rows


@pytest.mark.parametrize("rows,nodes,wedged", [(4, (7,), 244), (4, (3, 7), 244), (5, (9,), 1148),
                                               (5, (8, 9), 1148), (5, (4, 8, 9), 1148)])
def test_faces_plug2d_counts(plug2d_rows, rows, nodes, wedged):
    m = 2 * rows
    A = plug2d_rows(rows)
    full = complementary_rays(A, m)
    merged = merge_results([complementary_rays(A, m, face=f) for f in split_faces(m, nodes)])
    assert int(merged.wedged().sum()) == int(full.wedged().sum()) == wedged
    assert set(map(tuple, merged.zero)) == set(map(tuple, full.zero))
    assert len(merged.zero) == len(full.zero)


def test_faces_plug2d_exact(plug2d_rows):
    A = plug2d_rows(3, exact=True)
    full = complementary_rays(A, 6, exact=True)
    merged = merge_results([complementary_rays(A, 6, exact=True, face=f) for f in split_faces(6, (5, 2))])
    assert int(merged.wedged().sum()) == 44
    assert set(map(tuple, merged.zero)) == set(map(tuple, full.zero))


def _plug_rows(rows: int, mus, exact: bool = False):
    """friction_rows_2d of plug2d (rows x 3, taper 10 deg) at every mu; m = 2 rows."""
    from hpcwedge.contact.condense import condense
    from hpcwedge.contact.problem import ContactProblem
    from hpcwedge.models.library import plug2d
    param = parametrize(ContactProblem(2, *condense(plug2d(rows, 3, 10.0))), exact=exact)
    return [friction_rows_2d(param, mu, 2 * rows, exact=exact) for mu in mus]


def test_branching_nodes():
    assert branching_nodes(16) == [13, 14, 15] and branching_nodes(15) == []    # "auto"
    assert branching_nodes(12, 2) == [10, 11] and branching_nodes(12, 0) == []
    assert branching_nodes(3, 4) == [1, 2] and branching_nodes(1, 4) == []


@pytest.mark.parametrize("exact", [False, True])
def test_face_tasks_checkpoint_resume_in_process(tmp_path, exact, monkeypatch):
    """run_faces gives the unsplit DD's zero flags (and, exact, its rays). SIGTERM
    during the 5th face task: the task is dropped at its first task_tick(), the
    checkpoint holds the 4 finished faces (HDF5 round trip: float rays, exact ones
    as decimal strings), and a resumed engine asked for another split (as another
    rank count would choose) keeps the saved one, runs only the 12 missing faces
    and gives bit for bit the uninterrupted answer."""
    rows_n, nodes = (3, [3, 4, 5]) if exact else (5, [7, 8, 9])
    m, mus = 2 * rows_n, [0.65, 1.0]
    rows = _plug_rows(rows_n, mus, exact)
    ref = run_faces(rows, m, exact, nodes=nodes)
    for A, dd in zip(rows, ref):
        full = complementary_rays(A, m, exact=exact)
        order = canonical_order(full.zero)
        assert dd.stats["faces"] == 8 and dd.stats["branching_nodes"] == nodes
        assert np.array_equal(dd.zero, full.zero[order])
        if exact:
            assert dd.X.dtype == object and np.array_equal(dd.X, full.X[order])
        else:
            assert np.allclose(dd.X, full.X[order], rtol=0, atol=1e-11)
    ckpt = str(tmp_path / "f.ckpt")
    calls, kill_at = [], [5]

    def task(ctx, payload):
        calls.append(payload)
        if len(calls) in kill_at:
            os.kill(os.getpid(), signal.SIGTERM)
        return face_task(ctx, payload)

    eng = Engine(tick_every_s=0.0)                # cancel at the first tick
    eng.use_checkpoint(ckpt, "hash", "scene", 1000.0, resume=False)
    eng.install_signals()
    try:
        monkeypatch.setattr(faces, "face_task", task)
        with pytest.raises(Interrupted):
            run_faces(rows, m, exact, engine=eng, nodes=nodes)
        assert eng.write_checkpoint("SIGTERM")
    finally:
        eng.close()
    saved = read_checkpoint(ckpt)["jobs"]["rays"]
    assert not saved["attrs"]["finished"]
    assert saved["data"]["done"].tolist() == [0, 1, 2, 3]
    assert saved["data"]["X"].dtype.kind == ("S" if exact else "f")
    assert json.loads(saved["attrs"]["layout"]) == {"branching_nodes": nodes}
    calls.clear()
    kill_at.clear()
    eng = Engine()
    assert eng.use_checkpoint(ckpt, "hash", "scene", 1000.0, resume=True) and eng.restored("rays")
    out = run_faces(rows, m, exact, engine=eng, nodes=[m - 1])
    assert len(calls) == 2 * 8 - 4
    for a, b in zip(out, ref):
        assert a.stats["branching_nodes"] == nodes and a.stats["faces"] == 8
        assert np.array_equal(a.zero, b.zero) and np.array_equal(a.X, b.X) and a.X.dtype == b.X.dtype
    # without payloads_for, another layout is refused
    with pytest.raises(CheckpointError, match="layout"):
        job = TaskJob("rays", face_task, None, [], kind="face", layout={"branching_nodes": [1]})
        job.load(read_checkpoint(ckpt)["jobs"]["rays"])
