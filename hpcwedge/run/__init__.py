"""One run of a scene: the pipeline, the records of its stages, and a batch run's lifecycle.

- pipeline.py: scene -> model -> condensation -> enumeration -> mu^c -> Result.
- stages.py: the records each stage returns.
- batch.py: one batch run (`hpcwedge run`) around the pipeline: which rank serves, the
  output's lock, resume, the collective start-up under mpirun, the result written, stops.
"""

__all__ = ["pipeline", "stages", "batch"]
