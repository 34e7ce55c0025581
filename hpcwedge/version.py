"""The program's version (a leaf: the checkpoint and result writers stamp it)."""

__version__ = "0.1.0"
