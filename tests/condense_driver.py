"""Run under mpirun by test_condense.py: condense a model (model_cases.make_model) collectively
over MPI.COMM_WORLD (condense_distributed) and, on rank 0, save to OUT.npz K_local, N_local
and, per rank, how the stiffness was assembled: full (times the whole K was assembled) and
row_elements (elements assembled for the rank's rows; -1 for a model without element data).

    python tests/condense_driver.py OUT.npz KIND JSON_KWARGS
"""
import json
import sys

import numpy as np
from model_cases import make_model
from mpi4py import MPI

from hpcwedge.contact.condense import condense_distributed


def main() -> None:
    out, kind, kwargs = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
    comm = MPI.COMM_WORLD
    model = make_model(kind, kwargs)
    K, N = condense_distributed(model, comm)
    same = comm.allreduce(float(np.abs(K - comm.bcast(K)).max()), op=MPI.MAX)
    asm = model.assembly
    full = comm.gather(-1 if asm is None else asm.full_assemblies, root=0)
    row_elements = comm.gather(-1 if asm is None else asm.row_elements, root=0)
    if comm.rank == 0:
        n_elements = sum(len(q) for q in model.cells.values())
        np.savez(out, K=K, N=N, ranks=comm.size, spread=same, full=full, row_elements=row_elements,
                 n_elements=n_elements)


if __name__ == "__main__":
    main()
