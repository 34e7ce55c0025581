"""From the complementary rays' zero sets: the cross-complementarity graph, its maximal
cliques (the solution cones), and the 2D sign patterns the rays imply.

Rays enter as support masks over nodes: gap (u_n,i != 0) and load (r_n,i != 0).
Two complementary rays are cross-complementary when gap(a) & load(b) and
gap(b) & load(a) are empty. Rays with the same (gap, load) are twins (adjacent
to each other, same neighbours), so cliques are found on the graph of distinct
signatures and expanded back; networkx's find_cliques does the search.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hpcwedge.nodesets import bits_to_nodes, masks_to_bits, pack_rows


@dataclass(frozen=True)
class Cone:
    """rays: indices into the ray list (ascending); zero_u, zero_r: (m,) bool."""

    rays: tuple[int, ...]
    zero_u: np.ndarray
    zero_r: np.ndarray

    def key(self) -> tuple:
        return (tuple(np.flatnonzero(self.zero_u)), tuple(np.flatnonzero(self.zero_r)))


def cross_complementary(gap_a: np.ndarray, load_a: np.ndarray,
                        gap_b: np.ndarray, load_b: np.ndarray) -> np.ndarray:
    """(A, m) x (B, m) bool masks -> (A, B) bool: the pairwise cross-complementarity."""
    ga, la = pack_rows(gap_a), pack_rows(load_a)
    gb, lb = pack_rows(gap_b), pack_rows(load_b)
    clash = (ga[:, None, :] & lb[None, :, :]) | (gb[None, :, :] & la[:, None, :])
    return ~clash.any(axis=-1)


def maximal_cones(gap: np.ndarray, load: np.ndarray, wedged: np.ndarray) -> list[Cone]:
    """Maximal cliques of the cross-complementarity graph on the complementary rays
    (gap, load: (R, m) bool; wedged: (R,) bool) that contain a wedged ray, with
    their zero sets, in canonical order (sorted by (zero_u, zero_r) node lists)."""
    R, m = gap.shape
    if R == 0:
        return []
    sig = np.hstack([gap, load])
    packed = np.ascontiguousarray(pack_rows(sig))        # rows of bytes: a cheap unique
    _, first, inverse = np.unique(packed.view(np.dtype((np.void, packed.shape[1]))).ravel(),
                                  return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    classes = sig[first]
    cg, cl = classes[:, :m], classes[:, m:]
    adj = cross_complementary(cg, cl, cg, cl)
    import networkx as nx  # here: ~0.1 s of import that a 3D run never needs
    G = nx.Graph()
    G.add_nodes_from(range(len(classes)))
    ii, jj = np.nonzero(np.triu(adj, 1))
    G.add_edges_from(zip(ii.tolist(), jj.tolist()))
    has_wedged = np.zeros(len(classes), dtype=bool)
    has_wedged[inverse[wedged]] = True
    members = [[] for _ in range(len(classes))]
    for r, c in enumerate(inverse):
        members[c].append(r)
    cones = []
    for clique in nx.find_cliques(G):
        if not has_wedged[clique].any():
            continue
        rays = tuple(sorted(r for c in clique for r in members[c]))
        zero_u = ~cg[clique].any(axis=0)
        zero_r = ~cl[clique].any(axis=0)
        cones.append(Cone(rays=rays, zero_u=zero_u, zero_r=zero_r))
    cones.sort(key=Cone.key)
    return cones


def implied_patterns(ray_zero: np.ndarray, m: int) -> set[tuple[int, ...]]:
    """The 2D sign patterns the wedged rays imply (SPEC §2): (C, G) is feasible iff some
    wedged ray has supp(r_n) in C and supp(u_n) in G. ray_zero: (R, 3m) zero flags of the
    wedged rays (pipeline Run.ray_zero). Returns the contact sets C as sorted tuples."""
    out: set[int] = set()
    zu = ray_zero[:, 0::3]
    zr = ray_zero[:, 1::3] & ray_zero[:, 2::3]
    for need, free in zip(masks_to_bits(~zr), masks_to_bits(zu & zr)):
        sub = int(free)
        while True:                      # every subset of the free nodes
            out.add(int(need) | sub)
            if sub == 0:
                break
            sub = (sub - 1) & int(free)
    return {bits_to_nodes(c, m) for c in out}
