"""The contact problem: a Model condensed onto its contact DOFs.

Data go one way: scene.Scene -> models (the Model record: sparse K, contact nodes,
frames, rigid modes) -> build.py (the model stage and the raw-stiffness route) ->
condense.py (the Schur complement, PETSc; serial or distributed) -> problem.py
(`ContactProblem`: the block-ordered condensed K, the rigid modes, the (r, alpha)
parametrisation and the friction and u_n rows every engine uses).
"""

__all__ = ["build", "condense", "problem"]
