"""contact/factor.py: K_ii factored by PETSc; a collective factorisation's long calls made
through ctypes in a thread (`_released`) give the bits and the errors of petsc4py's own calls."""
import json
import subprocess
import sys

from mpi_helpers import env


def test_released_calls_give_petsc4pys_bits_and_errors():
    """factored() over an MPI communicator (here MPI.COMM_SELF: KSPSetUp and MatMatSolve
    through ctypes) against PETSc.COMM_SELF (petsc4py's calls): K_ii^-1 B bit for bit, and a
    singular K_ii (plug3d, 1 level: a mechanism apart from its contact nodes) the same error.
    In a fresh interpreter: MPI is started there."""
    code = """
import json
import numpy as np
from mpi4py import MPI
from hpcwedge.contact import condense as C
from hpcwedge.contact import factor
from hpcwedge.models import block2d, plug3d
out = []
for comm in (None, MPI.COMM_SELF):
    row = []
    for model in (block2d(3, 2, 6), plug3d(1, 5)):
        _, Kic, Kii = C._blocks(model, C.split_dofs(model))
        B = Kic[:, :5].toarray()
        try:
            with factor.factored(Kii, None, probe=B[:, 0], comm=comm) as solve:
                row.append(solve(B).tobytes().hex())
        except ValueError as e:
            row.append(str(e))
    out.append(row)
print(json.dumps([out, factor._library() is not None, len(factor._IN_USE)]))
"""
    p = subprocess.run([sys.executable, "-c", code], env=env(), capture_output=True, text=True, timeout=300,
                       stdin=subprocess.DEVNULL)
    assert p.returncode == 0, p.stderr
    (petsc4py_calls, released), found, in_use = json.loads(p.stdout.strip().splitlines()[-1])
    assert found and in_use == 0
    assert petsc4py_calls == released
    assert released[1].startswith("condense: the stiffness of the non-contact DOFs (K_ii) is singular"), released[1]
    assert not released[0].startswith("condense:")
