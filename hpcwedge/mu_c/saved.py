"""What `show` says of the mu^c jobs a checkpoint holds (parallel.checkpoint.checkpoint_summary's
describe): the least certified mu^c found so far, an upper bound on the global mu^c."""
from __future__ import annotations

import numpy as np


def describe_saved(attrs, data) -> dict | None:
    """{"mu_c_at_most": value or None} of a saved job: "global_bracket" (global_search's
    bracket task): its best, the certified mu^c of a pattern (None while the bracket runs or
    when it found no pattern); "mu_c" (critical.run_mu_c): the least polished (certified),
    finite mu^c of its finished tasks (an unpolished or undecided value bounds nothing). None
    for other jobs."""
    if attrs["kind"] == "global_bracket":
        values = np.asarray(data.get("best", []), dtype=float)[:1]
    elif attrs["kind"] == "mu_c":
        values = np.asarray(data.get("mu_c", []), dtype=float)
        polished = np.asarray(data.get("polished", np.zeros(len(values))), dtype=bool)
        values = values[polished] if len(polished) == len(values) else values[:0]
    else:
        return None
    values = values[np.isfinite(values)]
    return {"mu_c_at_most": float(values.min()) if len(values) else None}
