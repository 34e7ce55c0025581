"""The scene's shared vocabulary: its error, the defaults of [compute] and [run] (from the
table of keys, keys.py), and the checks of plain values that the parser and the table
builders both use."""
from __future__ import annotations

import numpy as np

from hpcwedge.errors import UserError
from hpcwedge.scene.keys import defaults

COMPUTE_DEFAULTS = defaults("compute")
RUN_DEFAULTS = defaults("run")


class SceneError(UserError):
    """Bad input: the message is one line naming the key and the reason."""


#: the types of plain numbers in a table (bool, a subclass of int, is not one)
NUMBER_TYPES = frozenset({int, float})


def array(value, key: str, ndim: int | None = None) -> np.ndarray:
    """A finite float array from a scene value, or a SceneError naming key."""
    from hpcwedge.models.record import as_float_array
    try:
        return as_float_array(value, key, ndim)
    except ValueError as e:
        raise SceneError(str(e)) from None


def one_edit_apart(a: str, b: str) -> bool:
    """Whether `b` is `a` with one character inserted, deleted, replaced, or two neighbours
    swapped (a != b)."""
    if a == b or abs(len(a) - len(b)) > 1:
        return False
    if len(a) == len(b):
        diff = [i for i, (x, y) in enumerate(zip(a, b)) if x != y]
        return len(diff) == 1 or (len(diff) == 2 and diff[1] == diff[0] + 1
                                  and a[diff[0]] == b[diff[1]] and a[diff[1]] == b[diff[0]])
    short, long_ = sorted((a, b), key=len)
    i = next((i for i, (x, y) in enumerate(zip(short, long_)) if x != y), len(short))
    return short[i:] == long_[i + 1:]


def near_misses(key: str, known) -> list[str]:
    """The names of `known` one edit away from `key` (one_edit_apart), sorted."""
    return sorted(k for k in known if isinstance(k, str) and one_edit_apart(key, k))


def did_you_mean(key: str, known) -> str:
    """'; did you mean `x`?' for the near misses of `key` among `known` ('' for none)."""
    near = near_misses(key, known)
    return f"; did you mean {' or '.join(f'`{k}`' for k in near)}?" if near else ""
