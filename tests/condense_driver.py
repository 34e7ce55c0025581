"""Run under mpirun by test_condense.py: condense a library model collectively over
MPI.COMM_WORLD (condense_distributed) and, on rank 0, save K_local, N_local to OUT.npz.

    python tests/condense_driver.py OUT.npz KIND JSON_KWARGS
"""
import json
import sys

import numpy as np
from mpi4py import MPI

from hpcwedge import models
from hpcwedge.condense import condense_distributed


def main() -> None:
    out, kind, kwargs = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
    comm = MPI.COMM_WORLD
    K, N = condense_distributed(getattr(models, kind)(**kwargs), comm)
    same = comm.allreduce(float(np.abs(K - comm.bcast(K)).max()), op=MPI.MAX)
    if comm.rank == 0:
        np.savez(out, K=K, N=N, ranks=comm.size, spread=same)


if __name__ == "__main__":
    main()
