"""The face split of the DD (SPEC §5): the branching nodes, their 2^k faces, and the
merge of the face runs into the DD of the whole cone.

Every complementary ray lies on {u_n,i = 0} or {r_n,i = 0} at every node, so for k
branching nodes the complementary extreme rays of P are the union of those of the 2^k
faces (split_faces), each run by dd.complementary_rays(..., face=), deduplicated and put
in canonical order (merge_results). The split is a function of the scene alone
(branching_nodes), never of the rank count.
"""
from __future__ import annotations

import itertools

import numpy as np

from .dd import DDResult, closest_to_tolerance
from .nodesets import Face, canonical_order


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
