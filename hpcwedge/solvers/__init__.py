"""The solvers of a pattern's feasibility problem, and the one decision policy.

- rows.py: the pattern problem as constraint rows, and the answers' vocabulary (`Status`).
- conic.py: one Clarabel solve (`ConicProblem`, settings, the status map).
- socp.py: the 3D pattern SOCP, its two forms and retry ladder.
- lp.py: LP feasibility by HiGHS (its status map; every HiGHS call, time-limited and
  interruptible; the 2D tree's warm LPs, `TreeLp`); milp.py: the 2D wedge MILP.
- screens.py: polyhedral LP screens (CLP, its status map) in front of the 3D tree's SOCPs.
- feasibility.py: `decide` -- is a pattern problem feasible at mu?

Each solver's statuses are read once, by its map into `Status` (conic.CLARABEL_STATUS,
lp.HIGHS_STATUS, screens.CLP_STATUS); everything else compares `Status` members. Clarabel's
own status name is kept beside it (`Solution.name`) as the key the stats count it under.

No module here loads h5py, mpi4py or petsc4py.
"""

__all__ = ["rows", "conic", "socp", "lp", "milp", "screens", "feasibility"]
