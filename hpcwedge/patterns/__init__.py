"""3D: every feasible sign pattern, by branch and bound over SOCP feasibility problems.

- tree.py: `PatternTree`, a serial, resumable search over subtrees (the parallel
  engine only moves subtrees around), and `run_patterns`.
- symmetry.py: node symmetries and the orbits of patterns under them.
"""

__all__ = ["tree", "symmetry"]
