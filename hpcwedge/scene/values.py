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
