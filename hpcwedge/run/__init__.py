"""One run of a scene: the pipeline and the records of its stages.

- pipeline.py: scene -> model -> condensation -> enumeration -> mu^c -> Result.
- stages.py: the records each stage returns.
"""

__all__ = ["pipeline", "stages"]
