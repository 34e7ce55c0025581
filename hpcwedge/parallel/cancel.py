"""Cancellation of a running task: what a long loop polls (`task_stopping`, `task_tick`,
`task_pausing`), how a long task hands back its progress (`Continuation`) and how the
engine runs a task under it (`run_cancellable`).

A leaf: no MPI, no HDF5, nothing of the domain, so every engine may import it.
"""
from __future__ import annotations

import contextlib
import math
import time

from hpcwedge import dense
from hpcwedge.errors import Interrupted

#: how often task_stopping() asks the engine, at most (seconds)
TICK_EVERY_S = 0.05


class TaskCancelled(Exception):
    """Raised by task_tick() inside a task the engine is stopping."""


class Continuation:
    """What a long task returns instead of its result when task_pausing() says so: the
    payload that runs the rest of it (JSON data: the job keeps it as the task's open payload,
    in its checkpoint too, and runs the task again with it). The task's answer must not
    depend on where it paused."""

    def __init__(self, payload):
        self.payload = payload

    def __repr__(self) -> str:
        return f"Continuation({self.payload!r})"


# ---------------------------------------------------------------- cancellation

#: set while a task runs (run_cancellable): returns True when the task should stop
_cancel_check = None
_tick_every_s = TICK_EVERY_S
_last_tick = 0.0
_stopping = False
_pause_at = math.inf


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


dense.on_wait(task_tick)          # a long dense call (dense.interruptible) is cancelled within a step


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


def in_task_scopes(handler, ctx, payload):
    """handler(ctx, payload) inside a fresh entry of every task_scope."""
    with contextlib.ExitStack() as scopes:
        for factory in list(_scopes):
            scopes.enter_context(factory())
        return handler(ctx, payload)


def task_pausing() -> bool:
    """A task that can hand back a Continuation polls this between its steps: True when it
    should (the engine is stopping, or the task has run pause_every_s seconds since it was
    handed out: the master's next checkpoint then holds its progress). False outside a task."""
    return task_stopping() or (_cancel_check is not None and time.monotonic() >= _pause_at)


def run_cancellable(handler, ctx, payload, check, tick_every_s: float = TICK_EVERY_S,
                    pause_every_s: float = math.inf):
    """handler(ctx, payload) inside every task_scope, during which task_stopping() asks check() (at most every
    tick_every_s seconds) whether the task should stop, and task_pausing() turns True
    pause_every_s seconds from now."""
    global _cancel_check, _tick_every_s, _last_tick, _stopping, _pause_at
    now = time.monotonic()
    _cancel_check, _tick_every_s, _last_tick, _stopping = check, tick_every_s, now, False
    _pause_at = now + pause_every_s
    try:
        return in_task_scopes(handler, ctx, payload)
    finally:
        _cancel_check, _stopping, _pause_at = None, False, math.inf


__all__ = ["Interrupted", "TaskCancelled", "Continuation", "TICK_EVERY_S", "task_stopping", "task_tick",
           "task_pausing", "run_cancellable", "task_scope", "in_task_scopes"]
