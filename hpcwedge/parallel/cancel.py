"""Cancellation of a running task: what a long loop polls (`task_stopping`, `task_tick`)
and how the engine runs a task under it (`run_cancellable`).

A leaf: no MPI, no HDF5, nothing of the domain, so every engine may import it.
"""
from __future__ import annotations

import contextlib
import time

from hpcwedge.errors import Interrupted

#: how often task_stopping() asks the engine, at most (seconds)
TICK_EVERY_S = 0.05


class TaskCancelled(Exception):
    """Raised by task_tick() inside a task the engine is stopping."""


# ---------------------------------------------------------------- cancellation

#: set while a task runs (run_cancellable): returns True when the task should stop
_cancel_check = None
_tick_every_s = TICK_EVERY_S
_last_tick = 0.0
_stopping = False


def task_stopping() -> bool:
    """Long loops of a task call this now and then: True when the engine is stopping —
    a worker whose master sent stop (after SIGTERM: the master checkpoints, then stops
    the workers; mpirun would otherwise wait for the task, or kill it), or the
    in-process engine after SIGTERM/SIGINT. A loop that can hand back what is left
    (PatternTree.explore: its open subtrees) returns then; others call task_tick().
    In-process, the call also serves SIGUSR1 and the checkpoint timer (the running
    task is saved as open). Cheap: looks at most every TICK_EVERY_S; once True, stays
    True to the end of the task; False outside a task."""
    global _last_tick, _stopping
    if _cancel_check is None:
        return False
    if not _stopping:
        now = time.monotonic()
        if now - _last_tick >= _tick_every_s:
            _last_tick = now
            _stopping = bool(_cancel_check())
    return _stopping


def task_tick() -> None:
    """Raises TaskCancelled when task_stopping() (face_task: after every DD step; the
    mu^c iterations). A cancelled task counts as not done (it is in flight, so the
    checkpoint keeps it as open). A no-op outside a task."""
    if task_stopping():
        raise TaskCancelled()


# ---------------------------------------------------------------- task scopes

#: context-manager factories entered around every task (task_scope)
_scopes: list = []


def task_scope(factory) -> None:
    """Register factory(), a context manager that run_cancellable enters around every task,
    in whatever process runs it (in-process, or a worker). For state a module keeps between
    calls (solvers/conic.py's kept Clarabel solvers): the task starts with its own, empty,
    and the caller's is back afterwards, so that a task's answer is a function of its
    payload alone — not of which tasks the rank ran before — and the master's state is
    the same serially and under mpirun (SPEC §5: the same bits for any rank count)."""
    if factory not in _scopes:
        _scopes.append(factory)


def run_cancellable(handler, ctx, payload, check, tick_every_s: float = TICK_EVERY_S):
    """handler(ctx, payload) inside every task_scope, during which task_stopping() asks
    check() (at most every tick_every_s seconds) whether the task should stop."""
    global _cancel_check, _tick_every_s, _last_tick, _stopping
    _cancel_check, _tick_every_s, _last_tick, _stopping = check, tick_every_s, time.monotonic(), False
    try:
        with contextlib.ExitStack() as scopes:
            for factory in list(_scopes):
                scopes.enter_context(factory())
            return handler(ctx, payload)
    finally:
        _cancel_check, _stopping = None, False


__all__ = ["Interrupted", "TaskCancelled", "TICK_EVERY_S", "task_stopping", "task_tick", "run_cancellable",
           "task_scope"]
