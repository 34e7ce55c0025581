"""The double description's adjacency test: which pairs (p, q) of rays on the two sides
of a new row combine into an extreme ray of the next cone (dd.py, "Adjacency").

Zero sets are (R, W) uint64 words in nodesets.RowBits's layout. adjacent_pairs is the one
entry point: a hash join on the "keys" of the simple rays (their zero sets minus one
removable bit), probes for the degenerate x simple pairs, brute force for the rare
degenerate x degenerate ones. Every test is combinatorial and exact on the zero sets.
"""
from __future__ import annotations

import numpy as np

HASH_MUL = (np.uint64(0x9E3779B97F4A7C15), np.uint64(0xC2B2AE3D27D4EB4F), np.uint64(0x165667B19E3779F9))
P_SIDE, M_SIDE, O_SIDE, PROBE = 0, 1, 2, 3


def adjacent_pairs(P, M, Z, done, fixed, nz1, bits, stats, work):
    """Pairs (p in P, q in M) that share a face at every finished node, have
    |Z(p) & Z(q)| >= nz1 - 1, and are adjacent (combinatorial test, exact).

    A ray is simple when it has exactly nz1 zeros (d - 1, plus the rows implied by
    a face), else degenerate. The *keys* of a simple ray are its zero set minus one removable bit (one whose loss keeps a face
    at every finished node). For simple p and q, C = Z(p) & Z(q) has nz1 - 1
    elements iff it is a key of both, and then every simple witness (a third ray
    whose zero set contains C) has C among its keys too. So (p, q) is adjacent iff
    C occurs once among the keys of P, once among those of M, never among those of
    the other simple rays, and no degenerate ray (more than nz1 zeros) contains C.
    For a degenerate g and a simple q, C = Z(g) & Z(q) with |C| >= nz1 - 1 is a key
    of q (C is not Z(q): two extreme rays never have nested zero sets), so the pair
    is adjacent iff C occurs exactly once among the simple rays' keys (q's own) and
    no degenerate ray but g contains C: C is looked up as a "probe" in the same join.
    Pairs of two degenerate rays are tested by brute force (they are rare).
    (In exact arithmetic the counting conditions always hold once C is a key of a
    simple ray: its nz1 - 1 rows have rank d - 2, so the face {x : A_C x = 0} is
    2-dimensional and holds no third extreme ray. They stay as a cheap check on
    float zero sets; the join's cost is in finding the common keys.)

    The join (_join) never sorts all keys: the hashes of the keys of the side with
    fewer keys (and of the probes) mark a table; the other side's keys are generated
    one removed bit at a time and kept only if their hash is marked; then the small
    side is filtered by a table of the survivors, and both once more with other hash
    bits. A key present on both sides (or probed) has every one of its occurrences
    survive, so the exact join by sorting, run on the survivors only (about two per
    adjacent pair), counts occurrences exactly. Hash collisions only let extra keys
    through to the exact join.
    """
    empty = np.zeros(0, dtype=np.intp)
    if len(P) == 0 or len(M) == 0:
        return empty, empty
    R = Z.shape[0]
    simple = np.bitwise_count(Z).sum(axis=1, dtype=np.int64) == nz1
    sign = np.zeros(R, dtype=np.int8)
    sign[P], sign[M] = 1, -1
    deg = np.flatnonzero(~simple)
    sP, sM = P[simple[P]], M[simple[M]]
    gP, gM = P[~simple[P]], M[~simple[M]]
    out_p, out_q = [], []
    # degenerate x simple: candidate pairs, probed in the join
    cand_p, cand_q = [empty], [empty]
    for g in gP:
        pi, qi = _candidates(np.array([g]), sM, Z, done, nz1, bits)
        cand_p.append(pi)
        cand_q.append(qi)
    for g in gM:
        pi, qi = _candidates(sP, np.array([g]), Z, done, nz1, bits)
        cand_p.append(pi)
        cand_q.append(qi)
    cand_p, cand_q = np.concatenate(cand_p), np.concatenate(cand_q)
    probes = Z[cand_p] & Z[cand_q]
    pi, qi, probe_ok = _join(Z, sP, sM, np.flatnonzero(simple & (sign == 0)), probes, done, fixed, work)
    stats["pairs_tested"] += len(pi) + len(cand_p)
    if len(deg):
        Zd = Z[deg]
        good = _contained_count(Z[pi] & Z[qi], Zd) == 0
        pi, qi = pi[good], qi[good]
        probe_ok &= _contained_count(probes, Zd) == 1          # g itself only
    stats["pairs_adjacent"] += len(pi) + int(probe_ok.sum())
    out_p += [pi, cand_p[probe_ok]]
    out_q += [qi, cand_q[probe_ok]]
    # degenerate x degenerate: brute force, witnesses among the rays sharing
    # >= nz1 - 1 zeros with the degenerate p
    for g in gP:
        pi, qi = _candidates(np.array([g]), gM, Z, done, nz1, bits)
        if len(pi):
            near = np.bitwise_count(Z & Z[g]).sum(axis=1, dtype=np.int64) >= nz1 - 1
            pi, qi = _adjacent(pi, qi, Z, Z[near], stats)
            out_p.append(pi)
            out_q.append(qi)
    return np.concatenate(out_p), np.concatenate(out_q)


def _contained_count(C, Zd):
    """(n, W) sets C, (k, W) sets Zd -> (n,) number of rows of Zd containing each C."""
    out = np.zeros(len(C), dtype=np.int64)
    step = max(1, (1 << 22) // max(1, Zd.shape[0] * Zd.shape[1]))
    for a in range(0, len(C), step):
        c = C[a:a + step]
        out[a:a + step] = np.all((Zd[None, :, :] & c[:, None, :]) == c[:, None, :], axis=-1).sum(axis=1)
    return out


def _table(work: dict, B: int) -> np.ndarray:
    """A zeroed bool table of 2^B slots, from a buffer reused across steps (a fresh
    one would page-fault in every step)."""
    buf = work.get("table")
    if buf is None or len(buf) < (1 << B):
        buf = work["table"] = np.zeros(1 << B, dtype=bool)
        return buf
    table = buf[:1 << B]
    table.fill(False)
    return table


def _removable(Zr, done, fixed):
    """Bits of each zero set whose removal keeps a face at every finished node (never
    an equality row of the face: those are in every zero set)."""
    one, two = np.uint64(1), np.uint64(2)
    u = Zr & done
    f = (Zr >> one) & (Zr >> two) & done
    wild = u & f
    req_u, req_f = u & ~wild, f & ~wild
    return Zr & ~(req_u | (req_f << one) | (req_f << two) | fixed)


def _key_bits(rem):
    """The removable bits present in rem (n, W): yields (w, bit, rows having it)."""
    for w in range(rem.shape[1]):
        col = rem[:, w]
        present = int(np.bitwise_or.reduce(col)) if len(col) else 0
        while present:
            low = present & -present
            present ^= low
            bit = np.uint64(low)
            yield w, bit, np.flatnonzero(col & bit)


def _hash(K):
    """(n, W) uint64 -> (n,) uint64, linear in the words (mod 2^64), so that the hash
    of a key is the hash of its zero set minus that of the removed bit. Table slots
    are its top bits."""
    h = K[:, 0] * HASH_MUL[0]
    for w in range(1, K.shape[1]):
        h += K[:, w] * HASH_MUL[w % len(HASH_MUL)]
    return h


def _bit_hash(w, bit):
    """_hash of the one-bit set (word w, bit)."""
    return np.uint64(int(bit) * int(HASH_MUL[w % len(HASH_MUL)]) % (1 << 64))


class _KeySet:
    """The keys of a set of simple rays (global indices rows, zero sets Zr), kept as
    (row, removed bit) and their hashes; keys are built only for the survivors."""

    def __init__(self, Zr, rows, done, fixed, side):
        self.Zr, self.rows, self.side = Zr, rows, side
        self.rem = _removable(Zr, done, fixed)
        self.count = int(np.bitwise_count(self.rem).sum(dtype=np.int64))
        self.hz = _hash(Zr)

    def chunks(self, shift):
        """Yields (w, bit, local rows, table slots) one removed bit at a time."""
        for w, bit, sel in _key_bits(self.rem):
            yield w, bit, sel, ((self.hz[sel] - _bit_hash(w, bit)) >> shift).view(np.int64)

    def keys(self, parts):
        """Keys and ray indices of the (w, bit, local rows) parts."""
        W = self.Zr.shape[1]
        if not parts:
            return np.zeros((0, W), dtype=np.uint64), np.zeros(0, dtype=np.intp)
        Ks, os_ = [], []
        for w, bit, sel in parts:
            K = self.Zr[sel]
            K[:, w] ^= bit
            Ks.append(K)
            os_.append(self.rows[sel])
        return np.concatenate(Ks), np.concatenate(os_)


def _join(Z, sP, sM, sO, probes, done, fixed, work):
    """Simple pairs (p, q) whose key occurs exactly twice among the simple rays' keys
    (once in P, once in M), and for each probe whether it occurs exactly once."""
    sets = [_KeySet(Z[sP], sP, done, fixed, P_SIDE), _KeySet(Z[sM], sM, done, fixed, M_SIDE)]
    small, big = sorted(sets, key=lambda k: k.count)
    other = _KeySet(Z[sO], sO, done, fixed, O_SIDE)
    B = int(np.clip(int(np.ceil(np.log2(max(small.count + len(probes), 1)))) + 3, 12, 28))
    shift = np.uint64(64 - B)
    hp = (_hash(probes) >> shift).view(np.int64)
    table = _table(work, B)
    small_parts = list(small.chunks(shift))
    for _, _, _, h in small_parts:
        table[h] = True
    table[hp] = True
    # the other side, filtered while it is generated; the simple rays outside P and M
    big_parts = []
    for w, bit, sel, h in big.chunks(shift):
        hit = table[h]
        big_parts.append((w, bit, sel[hit], h[hit]))
    other_parts = [(w, bit, sel[table[h]]) for w, bit, sel, h in other.chunks(shift)]
    table[:] = False
    for _, _, _, h in big_parts:
        table[h] = True
    table[hp] = True
    small_parts = [(w, bit, sel[hit], h[hit]) for w, bit, sel, h in small_parts
                   for hit in [table[h]]]
    # one more round each way with the next B bits of the hash (an independent
    # filter): false positives of the first round are mostly gone
    shift2 = np.uint64(64 - 2 * B)
    mask = np.int64((1 << B) - 1)
    hp2 = ((_hash(probes) >> shift2).view(np.int64)) & mask
    small_parts = [(w, bit, sel, ((small.hz[sel] - _bit_hash(w, bit)) >> shift2).view(np.int64) & mask)
                   for w, bit, sel, _ in small_parts]
    big_parts = [(w, bit, sel, ((big.hz[sel] - _bit_hash(w, bit)) >> shift2).view(np.int64) & mask)
                 for w, bit, sel, _ in big_parts]
    table[:] = False
    for _, _, _, h in small_parts:
        table[h] = True
    table[hp2] = True
    big_parts = [(w, bit, sel[hit], h[hit]) for w, bit, sel, h in big_parts for hit in [table[h]]]
    table[:] = False
    for _, _, _, h in big_parts:
        table[h] = True
    table[hp2] = True
    small_parts = [(w, bit, sel[table[h]]) for w, bit, sel, h in small_parts]
    del table
    Ks, os_ = small.keys(small_parts)
    Kb, ob = big.keys([(w, bit, sel) for w, bit, sel, _ in big_parts])
    Ko, oo = other.keys(other_parts)
    # exact join on the survivors
    keys = np.concatenate([Ks, Kb, Ko, probes])
    side = np.concatenate([np.full(len(Ks), small.side, np.int8), np.full(len(Kb), big.side, np.int8),
                           np.full(len(Ko), O_SIDE, np.int8), np.full(len(probes), PROBE, np.int8)])
    owner = np.concatenate([os_, ob, oo, np.arange(len(probes), dtype=np.intp)])
    probe_ok = np.zeros(len(probes), dtype=bool)
    empty = np.zeros(0, dtype=np.intp)
    if len(keys) == 0:
        return empty, empty, probe_ok
    order = np.argsort(_as_key(keys))
    ks, ss, os_ = keys[order], side[order], owner[order]
    first = np.ones(len(ks), dtype=bool)
    first[1:] = np.any(ks[1:] != ks[:-1], axis=1)
    run = np.cumsum(first) - 1
    nr = int(run[-1]) + 1
    real = ss != PROBE
    count = np.bincount(run[real], minlength=nr)
    isp, ism = ss == P_SIDE, ss == M_SIDE
    cp = np.bincount(run[isp], minlength=nr)
    cm = np.bincount(run[ism], minlength=nr)
    p_of = np.zeros(nr, dtype=np.intp)
    q_of = np.zeros(nr, dtype=np.intp)
    p_of[run[isp]] = os_[isp]
    q_of[run[ism]] = os_[ism]
    good = np.flatnonzero((count == 2) & (cp == 1) & (cm == 1))
    pr = ss == PROBE
    probe_ok[os_[pr]] = count[run[pr]] == 1
    return p_of[good], q_of[good], probe_ok


def _as_key(K):
    if K.shape[1] == 1:
        return K[:, 0].copy()
    K = np.ascontiguousarray(K)
    return K.view(np.dtype((np.void, 8 * K.shape[1]))).ravel()


def _candidates(P, M, Z, done, nz1, bits):
    """All (p, q) in P x M with a shared face at finished nodes and |Z(p) & Z(q)| >= nz1-1."""
    ZP = Z[P]
    chunk = max(1, (1 << 20) // max(1, len(P)))
    out_p, out_q = [np.zeros(0, dtype=np.intp)], [np.zeros(0, dtype=np.intp)]
    for a in range(0, len(M), chunk):
        q = M[a:a + chunk]
        common = ZP[None, :, :] & Z[q][:, None, :]            # (cq, |P|, W)
        ok = np.bitwise_count(common).sum(axis=-1, dtype=np.int64) >= nz1 - 1
        ok &= bits.complementary_at(common, done)
        qq, pp = np.nonzero(ok)
        out_p.append(P[pp])
        out_q.append(q[qq])
    return np.concatenate(out_p), np.concatenate(out_q)


def _adjacent(pi, qi, Z, Zw, stats):
    """Keep pairs for which no ray of Zw but p and q has a zero set containing Z(p) & Z(q)
    (Zw must hold p, q and every possible witness)."""
    stats["pairs_tested"] += len(pi)
    if len(pi) == 0:
        return pi, qi
    keep = np.zeros(len(pi), dtype=bool)
    chunk = max(1, (1 << 22) // max(1, Zw.shape[0] * Zw.shape[1]))
    for a in range(0, len(pi), chunk):
        Zc = Z[pi[a:a + chunk]] & Z[qi[a:a + chunk]]          # (c, W)
        contains = np.all((Zw[None, :, :] & Zc[:, None, :]) == Zc[:, None, :], axis=-1)
        keep[a:a + chunk] = contains.sum(axis=1) == 2
    stats["pairs_adjacent"] += int(keep.sum())
    return pi[keep], qi[keep]
