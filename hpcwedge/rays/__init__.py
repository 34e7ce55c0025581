"""2D: the complementary extreme rays of the polyhedral cone, and its solution cones.

- dd.py: complementarity-pruned double description (float and exact), with
  adjacency.py's combinatorial test.
- faces.py: the DD split over faces (SPEC §5), one task per face.
- cones.py: the cross-complementarity graph, its maximal cliques (the cones), zero sets.
- numerics.py: run-time checks of the float decisions, and the exact fallback.
"""

__all__ = ["adjacency", "dd", "faces", "cones", "numerics"]
