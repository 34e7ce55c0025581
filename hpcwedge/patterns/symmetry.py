"""Node symmetries of a contact problem, and the orbits of sign patterns under them.

A symmetry is a permutation p of the m contact nodes together with one sign per
tangent axis, s (dim - 1,), the same at every node, such that the condensed
stiffness in local frames is unchanged:

    D K[p(i), p(j)] D = K[i, j]   (dim x dim blocks),   D = diag(1, s).

Then (u, r) solves the wedging problem iff its image (node i's local values
moved to p(i), tangent components times s) does: u_n, r_n, ||r_t|| and the
friction cones are untouched, and K u = r is preserved. So the feasible sign
patterns at any mu, the cones and every pattern's mu^c are invariant: a pattern
(C, G) is feasible iff (p(C), p(G)) is, with the same mu^c. An axisymmetric plug
(plug3d: the dihedral group of its ring, 2 x ring elements) has them; a generic
body has only the identity.

`node_symmetries` finds the whole group by backtracking over node images (a
node can only go to a node with the same diagonal block; each assignment must
keep every block with the nodes already placed). Blocks are compared to
`rtol` times the largest entry of K; the group is given up (identity only)
beyond `max_order` elements.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from hpcwedge.nodesets import bit_images

#: blocks equal to this fraction of max |K| (condensation round-off is ~1e-13 of it)
SYMMETRY_RTOL = 1e-9
#: larger groups are not used (the identity alone is returned)
MAX_ORDER = 4096


@dataclass(frozen=True)
class Symmetry:
    """A group of node permutations: perms (order, m), row 0 the identity; signs
    (order, dim - 1) the tangent signs of each element (documentation: patterns
    do not see them)."""

    perms: np.ndarray
    signs: np.ndarray

    @property
    def order(self) -> int:
        return len(self.perms)

    @property
    def m(self) -> int:
        return self.perms.shape[1]

    def images(self, bits: int) -> np.ndarray:
        """The node sets g(bits) for every element g, as uint64 bit sets (order,)."""
        return bit_images(bits, self.perms)

    def stabilizer(self, contact: int, gap: int) -> "Symmetry":
        """The elements that map the contact set and the gap set onto themselves."""
        keep = (self.images(contact) == np.uint64(contact)) & (self.images(gap) == np.uint64(gap))
        return Symmetry(self.perms[keep], self.signs[keep])

    def orbit(self, i: int) -> np.ndarray:
        """The nodes g(i) over the group, sorted."""
        return np.unique(self.perms[:, i])

    def expand(self, patterns: list[tuple[int, int]]) -> list[tuple[int, int]]:
        """Every image of every (contact bits, gap bits) pattern, without repeats,
        sorted by (contact, gap)."""
        out = set()
        for c, g in patterns:
            out.update(zip((int(v) for v in self.images(c)), (int(v) for v in self.images(g))))
        return sorted(out)

    def canonical(self, contact: int, gap: int) -> tuple[int, int]:
        """The least (contact, gap) over the orbit of a pattern: its representative."""
        return min(zip((int(v) for v in self.images(contact)), (int(v) for v in self.images(gap))))


def identity(m: int, dim: int) -> Symmetry:
    return Symmetry(np.arange(m)[None, :], np.ones((1, dim - 1), dtype=np.int8))


def node_symmetries(K: np.ndarray, dim: int, rtol: float = SYMMETRY_RTOL,
                    max_order: int = MAX_ORDER) -> Symmetry:
    """The symmetry group of the condensed local stiffness K (n x n, block order
    [n.., t1.., (t2..)] as SPEC §1). Identity only for m > 64 (patterns are bit sets
    of uint64) or when the group exceeds max_order."""
    n = K.shape[0]
    m = n // dim
    if m > 64 or m == 0:
        return identity(max(m, 1), dim)
    B = K.reshape(dim, m, dim, m).transpose(1, 3, 0, 2)          # B[i, j] = block (dim, dim)
    tol = rtol * max(np.abs(K).max(), 1e-300)
    perms, signs = [], []
    for s in itertools.product((1, -1), repeat=dim - 1):
        d = np.array((1,) + s, dtype=float)
        Bs = B * d[None, None, :, None] * d[None, None, None, :]   # D B D
        found = _automorphisms(B, Bs, tol, max_order - len(perms))
        if found is None:
            return identity(m, dim)
        perms += found
        signs += [s] * len(found)
    perms = np.array(perms, dtype=np.int64)
    signs = np.array(signs, dtype=np.int8).reshape(len(perms), dim - 1)
    first = np.flatnonzero((perms == np.arange(m)).all(axis=1) & (signs == 1).all(axis=1))
    if len(first) != 1:                     # not a group we can trust (tolerance too loose)
        return identity(m, dim)
    order = np.concatenate([first, np.delete(np.arange(len(perms)), first)])
    return Symmetry(perms[order], signs[order])


def _automorphisms(B: np.ndarray, Bs: np.ndarray, tol: float, limit: int) -> list[list[int]] | None:
    """All p with Bs[p(i), p(j)] == B[i, j] (to tol) for all i, j; None past `limit`."""
    m = B.shape[0]
    diag = np.abs(Bs[np.arange(m), np.arange(m)][:, None, :, :] - B[np.arange(m), np.arange(m)][None, :, :, :])
    cand = [np.flatnonzero(diag[:, i].max(axis=(1, 2)) <= tol) for i in range(m)]   # images allowed for i
    out: list[list[int]] = []
    p = np.full(m, -1)
    used = np.zeros(m, dtype=bool)

    def place(i: int) -> bool:
        if i == m:
            out.append(p.tolist())
            return len(out) <= limit
        for k in cand[i]:
            if used[k]:
                continue
            if i and np.abs(Bs[k, p[:i]] - B[i, :i]).max() > tol:
                continue
            p[i], used[k] = k, True
            if not place(i + 1):
                return False
            used[k] = False
        p[i] = -1
        return True

    return out if place(0) else None
