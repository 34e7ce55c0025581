"""nodesets.py: the node-set spellings convert into each other and back, the DD's row
layout packs and tests zero sets as the plain definitions say, canonical order."""
import itertools

import numpy as np
import pytest

from hpcwedge.nodesets import (
    NODES_PER_WORD,
    RowBits,
    bit_images,
    bits_to_mask,
    bits_to_nodes,
    bits_to_words,
    canonical_face,
    canonical_order,
    masks_to_bits,
    pack_rows,
    pattern_key,
    to_bits,
    to_mask,
    unpack_rows,
    words_to_bits,
)


@pytest.mark.parametrize("m", [1, 5, 63])
def test_list_mask_bits_round_trip(m):
    rng = np.random.default_rng(m)
    for _ in range(20):
        nodes = tuple(sorted(rng.choice(m, size=rng.integers(0, m + 1), replace=False).tolist()))
        bits = to_bits(nodes)
        assert bits == sum(2 ** i for i in nodes) and bits_to_nodes(bits, m) == nodes
        mask = to_mask(nodes, m)
        assert mask.dtype == bool and tuple(np.flatnonzero(mask)) == nodes
        assert int(masks_to_bits(mask[None, :])[0]) == bits


@pytest.mark.parametrize("m", [0, 1, 7, 8, 9, 18, 64, 65, 130])
def test_bits_to_mask_and_nodes_read_bit_i_as_node_i(m):
    """Against the definition (bit i set: node i in the set), on any m, not only whole bytes
    or words, the bits at and beyond m ignored."""
    rng = np.random.default_rng(m)
    for _ in range(30):
        bits = int.from_bytes(rng.bytes(m // 8 + 2), "little")
        want = [bool(bits >> i & 1) for i in range(m)]
        mask = bits_to_mask(bits, m)
        assert mask.dtype == bool and mask.shape == (m,) and mask.tolist() == want
        assert bits_to_nodes(bits, m) == tuple(i for i in range(m) if want[i])


def test_words_round_trip_beyond_64_nodes():
    values = [0, 1, (1 << 64) - 1, 1 << 64, (1 << 130) | 5, 0xDEADBEEF << 70]
    arr = bits_to_words(values, 3)
    assert arr.shape == (6, 3) and arr.dtype == np.uint64
    assert int(arr[3, 1]) == 1 and int(arr[3, 0]) == 0
    assert words_to_bits(arr) == values
    assert words_to_bits(np.array([3, 5], dtype=np.uint64)) == [3, 5]      # one word per row


def test_bit_images_are_the_permuted_sets():
    m = 6
    perms = np.array([list(p) for p in itertools.islice(itertools.permutations(range(m)), 0, 720, 37)])
    for bits in (0, 1, 0b101101, (1 << m) - 1):
        got = bit_images(bits, perms)
        want = [to_bits(p[i] for i in bits_to_nodes(bits, m)) for p in perms]
        assert got.dtype == np.uint64 and [int(v) for v in got] == want


@pytest.mark.parametrize("k", [1, 7, 8, 9, 63])
def test_pack_rows_round_trip(k):
    z = np.random.default_rng(k).random((11, k)) < 0.5
    p = pack_rows(z)
    assert p.shape == (11, -(-k // 8)) and np.array_equal(unpack_rows(p, k), z)
    assert np.array_equal(unpack_rows(p.ravel(), k), z)            # flat, as a checkpoint holds it


@pytest.mark.parametrize("m", [1, 20, 21, 22, 50])
def test_row_bits_pack_unpack_and_complementarity(m):
    bits = RowBits(m)
    assert bits.W == -(-m // NODES_PER_WORD)
    rng = np.random.default_rng(m)
    zero = rng.random((40, 3 * m)) < 0.5
    Z = bits.pack(zero)
    assert Z.shape == (40, bits.W) and np.array_equal(bits.unpack(Z), zero)
    for c in range(3 * m):                                          # one row, one bit
        w, bit = bits.pos(c)
        assert np.array_equal((Z[:, w] & bit) != 0, zero[:, c])
    done_nodes = [i for i in range(m) if rng.random() < 0.6]
    done = np.zeros(bits.W, dtype=np.uint64)
    for i in done_nodes:
        bits.add_node(done, i)
    all_nodes = np.zeros(bits.W, dtype=np.uint64)
    for i in range(m):
        bits.add_node(all_nodes, i)
    assert np.array_equal(all_nodes, bits.node_mask)
    want = np.array([all(z[3 * i] or (z[3 * i + 1] and z[3 * i + 2]) for i in done_nodes) for z in zero])
    assert np.array_equal(bits.complementary_at(Z, done), want)


def test_canonical_face_and_pattern_key():
    assert canonical_face(([3, 1, 3], (np.int64(2),))) == ((1, 3), (2,))
    assert all(type(i) is int for part in canonical_face(([np.int64(4)], [])) for i in part)
    assert sorted([0b110, 0b001, 0b011], key=pattern_key) == [0b001, 0b011, 0b110]


@pytest.mark.parametrize("R,k", [(0, 6), (7, 0), (200, 3), (500, 60), (500, 64), (500, 65), (300, 130)])
def test_canonical_order_is_lexsort(R, k):
    rng = np.random.default_rng(R + k)
    z = rng.random((R, k)) < 0.3
    z[R // 2:] = z[:R - R // 2]                       # duplicates: the order must be stable
    ref = np.lexsort(z.T[::-1]) if k else np.arange(R)
    assert np.array_equal(canonical_order(z), ref)


def test_bit_words_beyond_64_nodes():
    vals = [0, 1, (1 << 64) | 5, (1 << 130) - 1, 1 << 127]
    words = bits_to_words(vals, 3)
    assert words.shape == (5, 3) and words.dtype == np.uint64
    assert words_to_bits(words) == vals
    assert words_to_bits(np.zeros((0, 1), dtype=np.uint64)) == []
