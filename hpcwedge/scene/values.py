"""The scene's shared vocabulary: its error, the defaults of [compute] and [run], and the
checks of plain values that the parser and the table builders both use (a leaf of scene/)."""
from __future__ import annotations

import numpy as np

from hpcwedge.errors import UserError

COMPUTE_DEFAULTS = {"enumerate": True, "mu_c": "cones", "mu_c_method": "accurate",
                    "mu_c_tol": 1e-6, "mu_max": 100.0, "exact": False,
                    "exact_fallback_max_m": 10}
RUN_DEFAULTS = {"checkpoint_every_s": 60.0, "task_budget": 64, "symmetry": True, "face_split": "auto",
                "condense": "auto", "max_memory_gb": "auto", "screens": False}


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
