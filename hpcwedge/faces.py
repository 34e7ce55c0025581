"""The "face" task of the engine: the 2D double description split over the faces
of a few branching nodes (SPEC §5), one task per (mu, face), and its merge.

A face task's answer is a dict of numbers and arrays, so that checkpoints can
hold it (face_task); face_result turns it back into a dd.DDResult, and
run_faces merges the faces of every mu (dd.merge_results)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .dd import DDResult, complementary_rays, merge_results, split_faces
from .parallel import Engine, decode_rays, encode_rays, ranks_on_host, run_tasks
from .parallel.tasks import task_tick
from .progress import MemoryGuard


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
    checkpoint); stats["face"] is the face, as dd.merge_results expects."""
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
