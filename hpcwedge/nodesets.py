"""Node sets: their spellings, the conversions between them, and the canonical order.

A set of contact nodes (0..m-1) is spelled four ways, and these functions are the one
place that converts between them:

  - a node list: sorted node indices (what the result file holds);
  - a mask: (m,) bool, or (R, m) bool for R sets at once;
  - a bitset: a Python int, bit i set when node i is in the set (patterns, symmetries);
  - words: uint64 words of a bitset, bit i in word i // 64 (checkpoints, numpy tables).

The double description's zero sets have their own layout (RowBits): three constraint rows
per node (problem.U_N, F_PLUS, F_MINUS), NODES_PER_WORD nodes per uint64 word, so that a
node's test stays inside one word.

Canonical order (SPEC §4: "lexicographic in their zero sets or pattern bits"): rows of
zero flags sort lexicographically, column 0 first, False < True (canonical_order: rays,
merged face runs); a sign pattern sorts by its contact bitset (pattern_key); a face
(contact nodes, gap nodes) is canonical with each side sorted and without repeats
(canonical_face).
"""
from __future__ import annotations

import numpy as np

#: nodes per uint64 word of a DD zero set (3 rows each: 63 of the 64 bits)
NODES_PER_WORD = 21

#: a face of the DD's cone: (contact nodes: u_n = 0, gap nodes: r = 0)
Face = tuple[tuple[int, ...], tuple[int, ...]]


def to_bits(nodes) -> int:
    """Node list -> bitset."""
    out = 0
    for i in nodes:
        out |= 1 << int(i)
    return out


def bits_to_nodes(bits: int, m: int) -> tuple[int, ...]:
    """Bitset -> sorted node tuple (nodes 0..m-1; bits beyond m ignored)."""
    bits &= (1 << m) - 1
    out = []
    while bits:
        low = bits & -bits                      # the lowest set bit
        out.append(low.bit_length() - 1)
        bits ^= low
    return tuple(out)


def bits_to_mask(bits: int, m: int) -> np.ndarray:
    """Bitset -> (m,) bool mask (any m: Python ints; bits beyond m ignored)."""
    raw = np.frombuffer((bits & ((1 << m) - 1)).to_bytes((m + 7) // 8, "little"), np.uint8)
    return np.unpackbits(raw, count=m, bitorder="little").view(bool)


def to_mask(nodes, m: int) -> np.ndarray:
    """Node list -> (m,) bool mask."""
    z = np.zeros(m, dtype=bool)
    z[list(nodes)] = True
    return z


def masks_to_bits(masks: np.ndarray) -> np.ndarray:
    """(R, m) bool masks -> (R,) int64 bitsets (m <= 63)."""
    return masks @ (1 << np.arange(masks.shape[1], dtype=np.int64))


def bits_to_words(values, words: int) -> np.ndarray:
    """Bitsets -> (len(values), words) uint64, bit i in word i // 64."""
    out = np.zeros((len(values), words), dtype=np.uint64)
    for r, v in enumerate(values):
        for w in range(words):
            out[r, w] = (v >> (64 * w)) & 0xFFFFFFFFFFFFFFFF
    return out


def words_to_bits(arr: np.ndarray) -> list[int]:
    """(R, words) or (R,) uint64 -> R bitsets (the inverse of bits_to_words)."""
    arr = np.asarray(arr, dtype=np.uint64)
    if arr.ndim == 1:
        arr = arr[:, None]
    return [sum(int(x) << (64 * w) for w, x in enumerate(row)) for row in arr]


def bit_images(bits: int, perms: np.ndarray) -> np.ndarray:
    """The images p(S) of the node set S (a bitset, m <= 64) under every node permutation
    p (rows of perms, (order, m)), as uint64 bitsets (order,)."""
    m = perms.shape[1]
    mask = ((np.uint64(bits) >> np.arange(m, dtype=np.uint64)) & np.uint64(1)).astype(bool)
    w = np.uint64(1) << perms.astype(np.uint64)
    return np.where(mask[None, :], w, np.uint64(0)).sum(axis=1, dtype=np.uint64)


def pack_rows(masks: np.ndarray) -> np.ndarray:
    """(R, k) bool -> (R, ceil(k / 8)) uint8, 8 columns a byte, column 0 the high bit."""
    return np.packbits(masks, axis=1)


def unpack_rows(packed: np.ndarray, k: int) -> np.ndarray:
    """The inverse of pack_rows: (R, ceil(k / 8)) uint8 -> (R, k) bool."""
    packed = np.asarray(packed, dtype=np.uint8).reshape(-1, -(-k // 8))
    return np.unpackbits(packed, axis=1, count=k).astype(bool)


def pattern_key(contact: int) -> int:
    """The sort key of a sign pattern given by its contact bitset: the bitset itself."""
    return contact


def canonical_face(face: Face) -> Face:
    """(contact, gap) with each side sorted, without repeats, as ints."""
    contact, gap = face
    return (tuple(sorted({int(i) for i in contact})), tuple(sorted({int(i) for i in gap})))


def canonical_order(zero: np.ndarray, return_words: bool = False):
    """Stable permutation sorting the rows of zero (R, k) bool lexicographically
    (column 0 first, False < True): the same as np.lexsort(zero.T[::-1]), but on
    the rows packed into big-endian 64-bit words (one sort key per 64 columns).
    With return_words, also the packed rows (R, ceil(k / 64)) uint64."""
    R, k = zero.shape
    nw = max(1, -(-k // 64))
    packed = np.zeros((R, 8 * nw), dtype=np.uint8)
    if k:
        packed[:, :-(-k // 8)] = pack_rows(zero)
    words = packed.view(">u8").astype(np.uint64)
    order = np.lexsort(words.T[::-1]) if nw > 1 else np.argsort(words[:, 0], kind="stable")
    return (order, words) if return_words else order


class RowBits:
    """Bit layout of the DD's zero sets over the 3m constraint rows of m nodes: row
    3i + kind of node i is bit 3 * (i % NODES_PER_WORD) + kind of word i // NODES_PER_WORD.
    A node set in this layout (`done`, node_mask) has bit 3j of node j's slot."""

    def __init__(self, m: int):
        self.m = m
        self.W = max(1, -(-m // NODES_PER_WORD))
        self.node_mask = np.zeros(self.W, dtype=np.uint64)   # bits 3j of every node slot used
        for i in range(m):
            self.add_node(self.node_mask, i)

    def pos(self, c: int) -> tuple[int, np.uint64]:
        """Row c -> (word, bit)."""
        i, kind = divmod(c, 3)
        w, b = divmod(i, NODES_PER_WORD)
        return w, np.uint64(1) << np.uint64(3 * b + kind)

    @staticmethod
    def add_node(words: np.ndarray, i: int) -> None:
        """Set node i's bit (3j of its slot) in the (W,) node-set words, in place."""
        w, b = divmod(i, NODES_PER_WORD)
        words[w] |= np.uint64(1) << np.uint64(3 * b)

    def pack(self, zero: np.ndarray) -> np.ndarray:
        """(R, 3m) bool -> (R, W) uint64."""
        Z = np.zeros((zero.shape[0], self.W), dtype=np.uint64)
        for c in range(zero.shape[1]):
            w, bit = self.pos(c)
            Z[zero[:, c], w] |= bit
        return Z

    def unpack(self, Z: np.ndarray) -> np.ndarray:
        """(R, W) uint64 -> (R, 3m) bool."""
        out = np.zeros((Z.shape[0], 3 * self.m), dtype=bool)
        for c in range(3 * self.m):
            w, bit = self.pos(c)
            out[:, c] = (Z[:, w] & bit) != 0
        return out

    @staticmethod
    def complementary_at(Z: np.ndarray, done: np.ndarray) -> np.ndarray:
        """(..., W) zero words -> (...) bool: at every node in `done` (W words of
        bits 3j) u_n = 0 or both friction rows tight."""
        one, two = np.uint64(1), np.uint64(2)
        ok = (Z | ((Z >> one) & (Z >> two))) & done
        return np.all(ok == done, axis=-1)
