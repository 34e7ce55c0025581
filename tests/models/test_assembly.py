"""Assembly by rows (models/assembly.py, continuum.ContinuumAssembly): the rows of a set of DOFs
from the elements incident to their nodes equal the whole stiffness's rows bit for bit, and
agree with a plain element-by-element dense scatter; continuum models assemble K lazily."""
import numpy as np
import pytest
from model_cases import hex_model

from hpcwedge.models import block2d
from hpcwedge.models.assembly import assemble_blocks
from hpcwedge.models.continuum import ContinuumAssembly, continuum_stiffness
from hpcwedge.models.elements import element_stiffness


def _mixed_mesh():
    """block2d(3, 2, 3)'s grid, every other quad split into two triangles: a 2D mesh of two
    cell blocks, E varying per element."""
    m = block2d(3, 2, 3)
    Q = m.cells["quad"]
    split = np.arange(len(Q)) % 2 == 1
    tris = np.concatenate([Q[split][:, [0, 1, 2]], Q[split][:, [0, 2, 3]]])
    cells = {"quad": Q[~split], "triangle": tris}
    E = 1.0 + np.arange(sum(len(q) for q in cells.values())) / 7.0
    return m.coords, cells, E


def _dense_scatter(X, cells, E, nu=0.3):
    """K by a dense loop: every element matrix added into its rows and columns one by one."""
    n, d = X.shape
    K = np.zeros((n * d, n * d))
    o = 0
    for cell, Q in cells.items():
        for e, nodes in enumerate(Q):
            ke = element_stiffness(cell, X[nodes][None], E[o + e:o + e + 1], np.array([nu]), np.ones(1))[0]
            dofs = (d * nodes[:, None] + np.arange(d)).ravel()
            K[np.ix_(dofs, dofs)] += ke
        o += len(Q)
    return K


def test_rows_equal_whole_and_dense_scatter():
    X, cells, E = _mixed_mesh()
    asm = ContinuumAssembly(X, cells, E)
    K = asm.full()
    Kd = _dense_scatter(X, cells, E)
    assert np.abs(K.toarray() - Kd).max() <= 1e-13 * np.abs(Kd).max()
    rng = np.random.default_rng(3)
    for size in (1, 5, 40):
        dofs = rng.choice(K.shape[0], size, replace=False)          # any order
        R = asm.rows(dofs)
        assert R.shape == (size, K.shape[0])
        assert np.array_equal(R.toarray(), K[dofs].toarray())        # bit for bit
    assert asm.full_assemblies == 1 and asm.row_assemblies == 3


@pytest.mark.parametrize("chunk", [1, 3, 10])
def test_subset_chunks_match_whole_bit_for_bit(chunk):
    # element chunks are the same id ranges with and without a subset: rows whose elements
    # are all selected are those of the whole assembly exactly, whatever the chunking
    X, cells, E = _mixed_mesh()
    Q = cells["quad"]
    n = len(X)

    def mats(sel):
        idx = np.arange(sel.start, sel.stop) if isinstance(sel, slice) else sel
        return element_stiffness("quad", X[Q[sel]], E[idx], np.full(len(idx), 0.3), np.ones(len(idx)))

    whole = assemble_blocks(Q, n, 2, mats, chunk=chunk)
    nodes = np.unique(Q[[2, 7]])
    elements = np.flatnonzero(np.isin(Q, nodes).any(axis=1))
    part = assemble_blocks(Q, n, 2, mats, chunk=chunk, elements=elements)
    dofs = (2 * nodes[:, None] + np.arange(2)).ravel()
    assert np.array_equal(part[dofs].toarray(), whole[dofs].toarray())
    assert part.nnz < whole.nnz


@pytest.mark.parametrize("make, node, incident", [(lambda: block2d(2, 2, 4), 2 * 9 + 4, 4),
                                                   (hex_model, 2 + 5 * (2 + 5 * 2), 8)])
def test_rows_assemble_incident_elements_only(make, node, incident):
    m = make()
    R = m.assembly.rows(m.dim * node + np.arange(m.dim))
    assert m.assembly.elements_assembled == incident               # an interior node's elements
    assert np.array_equal(R.toarray(), m.K[m.dim * node + np.arange(m.dim)].toarray())


def test_continuum_models_assemble_lazily():
    m = block2d(3, refine=4, contact_patch=0.15)
    assert m.tie is not None and m.assembly.full_assemblies == 0    # the patch left K alone
    K = m.K
    assert m.K is K and m.assembly.full_assemblies == 1              # assembled once, kept
    K0 = continuum_stiffness(m.coords, m.cells, 1.0, 0.3, 1.0)
    assert np.array_equal(K.indptr, K0.indptr) and np.array_equal(K.indices, K0.indices)
    assert np.array_equal(K.data, K0.data)
    h = hex_model()
    assert h.assembly.full_assemblies == 0 and h.K.shape == (3 * 125, 3 * 125)
