"""Task kinds and cancellation: the registry kind -> handler, and the state a running
task polls (task_stopping, task_tick). No MPI here (the engines import this module).

A *task* is (kind, payload). A kind names a handler ``handler(context, payload)
-> result``; ``context`` is the job's shared read-only data (a picklable object:
the parametrisation, the mu list, ...), sent once to each worker. Each handler
lives beside its engine; the registry only maps names to ``"module:function"``
strings, imported on first use on every rank. Adding a kind is one line in
the table below, or ``register(kind, handler)`` in a module every rank imports.
"""
from __future__ import annotations

import importlib
import time
from contextlib import contextmanager

_KINDS: dict = {
    "subtree": "hpcwedge.patterns:explore_task",    # sign-pattern subtrees (budgeted)
    "mu_c": "hpcwedge.mu_critical:mu_c_task",       # mu^c of one cone or pattern
    "face": "hpcwedge.faces:face_task",             # the 2D double description split over faces (SPEC §5)
    "global_bracket": "hpcwedge.global_mu_c:bracket_task",   # the global mu^c search's bracket
}

#: modules a worker imports before its first task (the task handlers' heavy imports)
WARM_UP = ["hpcwedge.patterns", "hpcwedge.mu_critical", "hpcwedge.faces", "hpcwedge.global_mu_c"]

#: how often task_stopping() asks the engine, at most (seconds)
TICK_EVERY_S = 0.05


class Interrupted(BaseException):
    """SIGTERM/SIGINT reached the master: write the checkpoint and stop. A BaseException,
    like KeyboardInterrupt: the handlers that turn a library's errors into one line (an
    unreadable K file or mesh, a model that fails to build on a worker) must not take a stop
    for one (a SIGTERM while K was read gave 'model.file: cannot read ...', exit 2; during
    a distributed build it was swallowed and the run went on for 20 s)."""


class TaskCancelled(Exception):
    """Raised by task_tick() inside a task the engine is stopping."""


# ---------------------------------------------------------------- the registry


def register(kind: str, handler):
    """handler: callable(context, payload) -> result, or a "module:function" string.
    Returns what the kind was registered as before (None: nothing)."""
    previous = _KINDS.get(kind)
    _KINDS[kind] = handler
    return previous


@contextmanager
def registered(kind: str, handler):
    """register(kind, handler) for the duration of a with block, then the previous one."""
    previous = register(kind, handler)
    try:
        yield
    finally:
        if previous is None:
            _KINDS.pop(kind, None)
        else:
            _KINDS[kind] = previous


def handler_for(kind: str):
    """The handler of `kind` (a registered kind, or a "module:function" string), imported on first use."""
    h = _KINDS.get(kind, kind if ":" in kind else None)
    if h is None:
        raise KeyError(f"unknown task kind {kind!r}")
    if isinstance(h, str):
        mod, name = h.split(":")
        h = getattr(importlib.import_module(mod), name)
        _KINDS[kind] = h
    return h


def warm_up() -> None:
    """Import the WARM_UP modules (a worker, while the master condenses)."""
    for mod in WARM_UP:
        importlib.import_module(mod)


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


def run_cancellable(handler, ctx, payload, check, tick_every_s: float = TICK_EVERY_S):
    """handler(ctx, payload), during which task_stopping() asks check() (at most every
    tick_every_s seconds) whether the task should stop."""
    global _cancel_check, _tick_every_s, _last_tick, _stopping
    _cancel_check, _tick_every_s, _last_tick, _stopping = check, tick_every_s, time.monotonic(), False
    try:
        return handler(ctx, payload)
    finally:
        _cancel_check, _stopping = None, False
