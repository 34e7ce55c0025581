"""The solvers of a pattern's feasibility problem, and the one decision policy.

- rows.py: the pattern problem as constraint rows, and the answers' vocabulary (`Status`).
- conic.py: one Clarabel solve (`ConicProblem`, settings, the status map).
- socp.py: the 3D pattern SOCP, its two forms and retry ladder.
- lp.py: LP feasibility by HiGHS; milp.py: the 2D wedge MILP.
- screens.py: polyhedral LP screens (CLP) in front of the 3D tree's SOCPs.
- feasibility.py: `decide` -- is a pattern problem feasible at mu?

No module here loads h5py, mpi4py or petsc4py.
"""

__all__ = ["rows", "conic", "socp", "lp", "milp", "screens", "feasibility"]
