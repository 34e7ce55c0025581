"""Long dense linear algebra that a signal can interrupt (`interruptible`, `dense_call`,
`null_space`).

One LAPACK call on a large matrix (an SVD of 2,563 x 2,563: ~7 s) keeps a signal's Python
handler waiting to its end. Here it runs in a daemon thread while the calling thread waits
in steps of WAIT_STEP_S: the handler runs within a step (outside a task SIGTERM raises
Interrupted at once), and so does every poll registered with `on_wait` — the parallel layer
registers task_tick, which raises TaskCancelled inside a task the engine is stopping. A call
given up on runs to its end in the background, its result dropped.

A leaf: numpy only, imported by the model layers and the engine alike.
"""
from __future__ import annotations

import threading

#: interruptible: the waiting thread wakes this often (seconds)
WAIT_STEP_S = 0.05
#: dense_call: arrays of at least this many entries go through `interruptible` (an SVD of
#: 450 x 450 takes ~50 ms; a thread costs ~0.1 ms)
DENSE_CALL_MIN = 200_000

_polls: list = []


def on_wait(poll) -> None:
    """Register poll(), called by the waiting thread after every step (it may raise to give
    the call up: parallel.cancel's task_tick)."""
    if poll not in _polls:
        _polls.append(poll)


def run_polls() -> None:
    """Call every poll registered with `on_wait` (what a waiting thread does after each step)."""
    for poll in _polls:
        poll()


def interruptible(fn, *args, **kwargs):
    """fn(*args, **kwargs) in a daemon thread, this one waiting in steps (module doc): for one
    long call that releases the GIL (numpy's LAPACK calls; not scipy.linalg's, see
    `null_space`). fn's exception is raised here."""
    box: dict = {}

    def run():
        try:
            box["value"] = fn(*args, **kwargs)
        except BaseException as e:          # handed to the caller's thread
            box["error"] = e

    thread = threading.Thread(target=run, daemon=True, name="hpcwedge-dense")
    thread.start()
    while thread.is_alive():
        thread.join(WAIT_STEP_S)
        run_polls()
    if "error" in box:
        raise box["error"]
    return box["value"]


def dense_call(fn, a, *args, **kwargs):
    """fn(a, *args, **kwargs), through `interruptible` when the array a has DENSE_CALL_MIN
    entries or more (the same bits either way: the same LAPACK call on another thread)."""
    if getattr(a, "size", 0) >= DENSE_CALL_MIN:
        return interruptible(fn, a, *args, **kwargs)
    return fn(a, *args, **kwargs)


def null_space(a, rcond: float | None = None):
    """An orthonormal basis (n, k) of the null space of a (m, n), as scipy.linalg.null_space
    (singular values above rcond times the largest count; rcond None: eps max(m, n)), by
    numpy's SVD through dense_call: scipy's LAPACK wrapper keeps the GIL for the whole call
    (an SVD of 1,800 x 1,800: no other thread ran for 3.9 s), numpy's releases it."""
    import numpy as np
    _, s, vh = dense_call(np.linalg.svd, a, full_matrices=True)
    if rcond is None:
        rcond = np.finfo(s.dtype).eps * max(a.shape)
    rank = int(np.sum(s > s.max(initial=0.0) * rcond))
    return vh[rank:, :].T.conj()
