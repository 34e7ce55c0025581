"""One run of a scene: the pipeline and its run-time checks.

- pipeline.py: scene -> model -> condensation -> enumeration -> mu^c -> Result.
- stages.py: the records each stage returns.
- numerics.py: run-time checks of the float decisions, and the exact fallback.
"""

__all__ = ["pipeline", "stages", "numerics"]
