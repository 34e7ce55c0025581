"""Assembly of element matrices into a global sparse stiffness, chunked over elements."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

#: element-matrix entries per assembly chunk (65536 Q4 elements; bounds the temporaries to ~100 MB)
CHUNK_ENTRIES = 65536 * 64


def _node_pattern(conn: np.ndarray, n_nodes: int):
    """Node-level CSR pattern (indptr, indices) of the element graph and sorted keys i*n + j."""
    nen = conn.shape[1]
    idx = np.int32 if n_nodes < 2 ** 31 - 1 else np.int64
    I = np.repeat(conn.astype(idx), nen, axis=1).ravel()
    Jc = np.tile(conn.astype(idx), (1, nen)).ravel()
    P = sp.coo_matrix((np.ones(I.size, dtype=np.int8), (I, Jc)), shape=(n_nodes, n_nodes)).tocsr()
    del I, Jc
    P.sum_duplicates()
    P.sort_indices()
    rows = np.repeat(np.arange(n_nodes, dtype=np.int64), np.diff(P.indptr))
    keys = rows * n_nodes + P.indices
    return P.indptr, P.indices, keys


def assemble_blocks(conn: np.ndarray, n_nodes: int, dim: int, element_matrices,
                    chunk: int | None = None, elements: np.ndarray | None = None) -> sp.csr_matrix:
    """Assemble (n_nodes*dim)^2 CSR from element matrices without a global COO array.

    conn: (ne, nen) node ids; element_matrices(sel) -> (k, nen*dim, nen*dim) exactly
    symmetric matrices with node-major local DOFs of the elements `sel` (a slice(lo, hi), or
    an ascending index array when `elements` is given). The node-level pattern is built once;
    each chunk's blocks are added into it with bincount, in element order, so the result is
    exactly symmetric. Memory ~ nnz of K plus one chunk of temporaries (chunk elements;
    default CHUNK_ENTRIES / (nen*dim)^2).
    elements: None (all), or ascending ids of the only elements to assemble. Chunks are the
    same ranges of element ids either way, so an entry (i, j) that gets every element holding
    both i and j is bit for bit the entry of the whole assembly (a chunk without such an
    element adds exactly 0): the rows of the nodes whose incident elements are all selected
    are exactly those of the whole K.
    """
    ne, nen = conn.shape
    if chunk is None:
        chunk = max(1, CHUNK_ENTRIES // (nen * dim) ** 2)
    sel_all = None if elements is None else np.asarray(elements, dtype=np.int64)
    indptr, indices, keys = _node_pattern(conn if sel_all is None else conn[sel_all], n_nodes)
    nnzb = keys.size
    data = np.zeros((dim, dim, nnzb))
    for lo in range(0, ne, chunk):
        hi = min(ne, lo + chunk)
        if sel_all is None:
            sel = slice(lo, hi)
        else:
            sel = sel_all[np.searchsorted(sel_all, lo):np.searchsorted(sel_all, hi)]
            if sel.size == 0:
                continue
        c = conn[sel].astype(np.int64)
        k = len(c)
        pos = np.searchsorted(keys, (c[:, :, None] * n_nodes + c[:, None, :]).ravel())
        ke = element_matrices(sel).reshape(k, nen, dim, nen, dim)
        for p in range(dim):
            for q in range(dim):
                data[p, q] += np.bincount(pos, weights=ke[:, :, p, :, q].ravel(), minlength=nnzb)
    blocks = np.ascontiguousarray(data.transpose(2, 0, 1))
    del data
    K = sp.bsr_matrix((blocks, indices, indptr), shape=(n_nodes * dim, n_nodes * dim)).tocsr()
    K.sort_indices()
    return K
