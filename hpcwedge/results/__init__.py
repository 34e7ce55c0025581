"""What a solve found, and its file (SPEC §4).

- record.py: `Run` (the answers at one mu), `Result` (every answer of a solve), stats.
- hdf5.py: the result file's HDF5 layout, its writer and its one reader.
"""

__all__ = ["record", "hdf5"]
