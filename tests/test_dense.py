"""hpcwedge.dense: long LAPACK calls in a thread that a signal can interrupt; its null space
against scipy's."""
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import scipy.linalg as sla
from mpi_helpers import python_child, stopped_by_sigterm

from hpcwedge import dense


def test_interruptible_returns_and_raises_what_fn_does():
    assert dense.interruptible(divmod, 7, 2) == (3, 1)
    with pytest.raises(ZeroDivisionError):
        dense.interruptible(divmod, 1, 0)


def test_dense_call_gives_the_direct_call_bits_on_both_sides_of_the_threshold():
    rng = np.random.default_rng(0)
    for shape in ((20, 10), (500, 400)):                     # 200 and 200,000 entries
        a = rng.standard_normal(shape)
        assert np.array_equal(dense.dense_call(np.linalg.svd, a, compute_uv=False),
                              np.linalg.svd(a, compute_uv=False))


def test_null_space_spans_scipys_and_counts_its_rank_alike():
    """Random rank-deficient matrices (the null space of rank r of n columns, some with a
    singular value just above and just below rcond): the same dimension as scipy's, orthonormal
    columns that a annihilates, and the same subspace (projectors equal to 1e-12)."""
    rng = np.random.default_rng(1)
    for m, n, r in ((5, 8, 3), (40, 40, 39), (30, 60, 30), (60, 30, 30), (1, 7, 1)):
        a = rng.standard_normal((m, r)) @ rng.standard_normal((r, n))
        for rcond in (None, 1e-10):
            z, ref = dense.null_space(a, rcond=rcond), sla.null_space(a, rcond=rcond)
            assert z.shape == ref.shape == (n, n - r)
            assert np.allclose(z.T @ z, np.eye(n - r), atol=1e-12)
            assert np.abs(a @ z).max(initial=0.0) <= 1e-10 * np.abs(a).max()
            assert np.allclose(z @ z.T, ref @ ref.T, atol=1e-12)
    a = np.diag([1.0, 1e-9, 1e-11])                          # rcond 1e-10: one value below it
    assert dense.null_space(a, rcond=1e-10).shape == sla.null_space(a, rcond=1e-10).shape == (3, 1)


def test_a_signal_is_served_during_a_long_call():
    """A process blocked in one long call (a 60 s sleep through interruptible) ends on SIGTERM
    within seconds: the Python handler runs in the waiting thread."""
    p = python_child(stopped_by_sigterm("import time\nfrom hpcwedge import dense", "dense.interruptible(time.sleep, 60.0)"))
    try:
        assert p.stdout.readline().strip() == "ready"
        start = time.monotonic()
        p.send_signal(signal.SIGTERM)
        assert p.wait(timeout=30) == 75
        assert time.monotonic() - start < 5.0
    finally:
        p.kill()
        p.wait()


def test_numpys_svd_lets_the_waiting_thread_run_and_scipys_does_not():
    """Why null_space uses numpy's SVD: during one SVD of 1,200 x 1,200 in a thread, the caller
    wakes many times with numpy's and (measured here: not at all) with scipy's."""
    import threading
    a = np.random.default_rng(2).standard_normal((1200, 1200))
    wakes = {}
    for name, fn in (("numpy", np.linalg.svd), ("scipy", sla.svd)):
        thread = threading.Thread(target=fn, args=(a,), daemon=True)
        thread.start()
        wakes[name] = 0
        while thread.is_alive():
            thread.join(dense.WAIT_STEP_S)
            wakes[name] += 1
    assert wakes["numpy"] >= 3 and wakes["numpy"] > 2 * wakes["scipy"], wakes
