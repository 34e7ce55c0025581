"""What a solve found, and its file (SPEC §4).

- record.py: `Cone` and `Pattern` (a run's items), `Run` (the answers at one mu), `Result`
  (every answer of a solve; `to_dict()`: the `show --json` object), `StoredModel`, stats.
- hdf5.py: the result file's HDF5 layout, its writer and its reader (the Result written).
"""

__all__ = ["record", "hdf5"]
