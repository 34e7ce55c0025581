"""The face split of the DD (SPEC §5): the branching nodes, their 2^k faces, and the
merge of the face runs into the DD of the whole cone.

Every complementary ray lies on {u_n,i = 0} or {r_n,i = 0} at every node, so for k
branching nodes the complementary extreme rays of P are the union of those of the 2^k
faces (split_faces), each run by dd.complementary_rays(..., face=), deduplicated and put
in canonical order (merge_results). The split is a function of the scene alone
(branching_nodes), never of the rank count.

The engine's "face" task (FaceContext, face_payloads, face_task, face_result,
run_faces) runs one (mu, face) DD per task; a face task's answer is a dict of numbers
and arrays, so that checkpoints can hold it.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from hpcwedge.nodesets import Face, canonical_order
from hpcwedge.parallel.cancel import task_tick
from hpcwedge.parallel.engine import Engine, run_tasks
from hpcwedge.progress import MemoryGuard, ranks_on_host
from hpcwedge.rays.dd import DDResult, closest_to_tolerance, complementary_rays


def encode_rays(X: np.ndarray) -> np.ndarray:
    """Rays as a checkpoint holds them: float rays as they are; exact ones (object ints)
    as decimal strings."""
    if X.dtype != object:
        return X
    return X.astype(str).astype("S") if X.size else np.zeros(X.shape, dtype="S1")


def decode_rays(X: np.ndarray) -> np.ndarray:
    """encode_rays undone: decimal strings back to exact (object int) rays."""
    X = np.asarray(X)
    if X.dtype.kind != "S":
        return X
    return np.frompyfunc(int, 1, 1)(X).astype(object)


def split_faces(m: int, nodes) -> list[Face]:
    """The 2^k faces of P given by k branching nodes: for every node, u_n = 0
    (contact) or r = 0 (gap). Every complementary ray lies on one of them (on
    several if u_n = r_n = 0 at a branching node). Listed in canonical order
    (node by node, contact before gap; the first node varies slowest)."""
    nodes = [int(i) for i in nodes]
    if len(set(nodes)) != len(nodes) or any(not 0 <= i < m for i in nodes):
        raise ValueError(f"branching nodes must be distinct nodes of 0..{m - 1}: {nodes}")
    faces = []
    for choice in itertools.product((0, 1), repeat=len(nodes)):
        contact = tuple(sorted(i for i, c in zip(nodes, choice) if c == 0))
        gap = tuple(sorted(i for i, c in zip(nodes, choice) if c == 1))
        faces.append((contact, gap))
    return faces


def merge_results(results: list[DDResult]) -> DDResult:
    """Union of face runs (any order), duplicates removed, rays in canonical order
    (lexicographic in the zero flags, as pipeline._fill_rays). A ray found on
    several faces is taken from the first face in canonical face order, so the
    merge does not depend on the order in which the results arrive."""
    if not results:
        raise ValueError("nothing to merge")
    results = sorted(results, key=lambda r: r.stats.get("face", ((), ())))
    X = np.concatenate([r.X for r in results])
    zero = np.concatenate([r.zero for r in results])
    order, words = canonical_order(zero, return_words=True)   # stable: first face first
    words = words[order]
    new = np.ones(len(zero), dtype=bool)
    new[1:] = np.any(words[1:] != words[:-1], axis=1)
    keep = order[new]
    X, zero = X[keep], zero[keep]
    stats = {"faces": len(results),
             "rays_found": int(sum(len(r.X) for r in results)),
             "initial_rays": int(sum(r.stats.get("initial_rays", 0) for r in results)),
             "pairs_tested": int(sum(r.stats.get("pairs_tested", 0) for r in results)),
             "pairs_adjacent": int(sum(r.stats.get("pairs_adjacent", 0) for r in results)),
             "max_rays": int(max(r.stats.get("max_rays", 0) for r in results)),
             "seconds": float(sum(r.stats.get("seconds", 0.0) for r in results)),
             "close_calls": int(sum(r.stats.get("close_calls", 0) for r in results)),
             "cancellation": float(min(r.stats.get("cancellation", 1.0) for r in results)),
             "closest": closest_to_tolerance(r.stats.get("closest") for r in results),
             "face_seconds": [float(r.stats.get("seconds", 0.0)) for r in results]}
    return DDResult(X=X, zero=zero, stats=stats)


#: run.face_split = "auto" splits from this m on (below, one DD takes < 1 s)
FACE_SPLIT_MIN_M = 16
#: at most this many branching nodes: the face where every branching node is in
#: contact holds ~97% of plug2d's rays and costs ~40% of the full run whatever k is,
#: so more faces only add work (scripts/bench_dd_faces.py, plug2d m = 18: k = 3
#: sums 6.4 s CPU, largest face 2.8 s; k = 4 sums 8.6 s, largest 4.2 s)
MAX_BRANCHING_NODES = 3


def branching_nodes(m: int, split: int | str = "auto") -> list[int]:
    """The nodes whose faces split the DD (SPEC §5): the last k nodes m-k..m-1, k
    from the scene's run.face_split — "auto": MAX_BRANCHING_NODES when m >=
    FACE_SPLIT_MIN_M, else 0 (one DD); an integer: that many — at most m - 1.

    A function of the scene alone, never of the rank count: a ray's floats depend on
    the DD's path to it, so one split gives the same bits on 1 or 100 ranks. (On
    plug2d the last nodes are the top of the right wall; splitting there was the
    cheapest of the node sets measured: the bottom nodes or both top corners cost
    1.5-2x more CPU in total.)"""
    k = (MAX_BRANCHING_NODES if m >= FACE_SPLIT_MIN_M else 0) if split == "auto" else int(split)
    k = max(0, min(k, m - 1))
    return list(range(m - k, m))


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
    split_faces(m, nodes), face by face (the face where every branching node is in
    contact, usually the largest, first for every mu: big tasks start first)."""
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
    i, (contact, gap) = payload
    guard = MemoryGuard(ctx.max_memory_gb, ranks_on_host())
    where = f" of face (contact {list(contact)}, gap {list(gap)})"

    def tick(info):
        task_tick()
        guard.dd_step(info, where)

    dd = complementary_rays(ctx.rows[i], ctx.m, exact=ctx.exact, face=(contact, gap), progress=tick)
    nodes = np.arange(ctx.m)
    out = {"mu_index": int(i), "contact": np.isin(nodes, list(contact)), "gap": np.isin(nodes, list(gap)),
           "X": encode_rays(dd.X), "zero": np.packbits(dd.zero, axis=1)}
    for key in ("initial_rays", "pairs_tested", "pairs_adjacent", "max_rays"):
        out[key] = int(dd.stats[key])
    out["seconds"] = float(dd.stats["seconds"])
    if not ctx.exact:
        out["close_calls"] = int(dd.stats["close_calls"])
        out["cancellation"] = float(dd.stats["cancellation"])
        closest = dd.stats["closest"]
        out["closest"] = float("nan") if closest is None else float(closest)
    return out


def face_result(res: dict) -> DDResult:
    """The dd.DDResult of a face_task result (as returned, or as read back from a
    checkpoint); stats["face"] is the face, as merge_results expects."""
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
    return DDResult(X=decode_rays(res["X"]), zero=zero, stats=stats)


def run_faces(rows: list, m: int, exact: bool = False, engine: Engine | None = None,
              nodes=(), name: str = "rays", max_memory_gb: float | str = "auto") -> list[DDResult]:
    """The complementary rays at every mu, the double description split over the
    faces of the branching nodes `nodes` (SPEC §5; the scene's choice,
    branching_nodes; none: one face, the whole cone), one "face" task per
    (mu, face), through the engine.

    rows: the constraint rows A of every mu (problem.friction_rows_2d). Returns one
    dd.DDResult per mu (merge_results of its faces: canonical order, duplicates
    removed, stats with faces, face_seconds and branching_nodes). A resumed run
    keeps the split its checkpoint was made with, so finished faces are reused
    whatever the rank count now is. The zero flags, and so every count, cone and
    mu^c, are those of the unsplit run; the float ray vectors equal them to
    rounding (a ray's floats depend on the DD's path to it: ~1e-13 relative), and
    bit for bit those of any run with the same split, on any number of ranks."""
    engine = engine or Engine()
    nodes = [int(i) for i in nodes]

    def payloads_for(layout):
        return face_payloads(len(rows), m, layout["branching_nodes"])

    layout = {"branching_nodes": nodes}
    out = run_tasks(face_task, FaceContext(list(rows), m, exact, max_memory_gb), payloads_for(layout), engine, name,
                    layout=layout, payloads_for=payloads_for, kind="face")
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
