#!/usr/bin/env python3
"""Distributed condensation (issue 5): block2d on 1 and 2 MPI ranks.

block2d(rows=5, cols=2, refine=f): m = 12 contact nodes; the body has
2 (5f+1)(2f+1) DOFs (f = 224: 1.0e6; --quick f = 71: 1.0e5). For each rank
count the script starts itself under mpirun (`--worker`): every rank builds the
model (mesh and element data; K is not assembled), then `condense_distributed`
runs collectively over MPI.COMM_WORLD: each rank assembles its share of the K_ii
rows (and the contact rows) from the elements incident to their nodes, into an
MPIAIJ matrix factored by parallel MUMPS (LDL^T). Per rank: the model build time,
the condensation time (after a barrier, up to the allreduced result; includes the
rank's assembly), the peak resident memory (getrusage ru_maxrss, after the build
and at the end) and how the stiffness was assembled (full_assemblies: times the
whole K was built, 0 expected; row_elements: elements assembled for the rank's
rows), gathered to rank 0. Checks that the K_local of every rank count agree (relative
max-difference), and writes results/bench_condense{,_quick}.{json,csv}.

    .venv/bin/python scripts/bench_condense.py [--quick] [--refine F] [--ranks 1 2]
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "results")
ROWS, COLS = 5, 2


def n_dofs(refine: int) -> int:
    return 2 * (ROWS * refine + 1) * (COLS * refine + 1)


def worker(refine: int, out: str) -> None:
    """One rank of the mpirun run: build, condense collectively, gather the measurements."""
    import resource

    import numpy as np
    from mpi4py import MPI

    sys.path.insert(0, ROOT)
    from hpcwedge.contact.condense import condense_distributed
    from hpcwedge.models import block2d

    comm = MPI.COMM_WORLD
    t = time.perf_counter()
    model = block2d(ROWS, COLS, refine)
    build_s = time.perf_counter() - t
    rss_build = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    comm.Barrier()
    t = time.perf_counter()
    K, _ = condense_distributed(model, comm)
    condense_s = time.perf_counter() - t
    rss_end = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    asm = model.assembly
    rows = comm.gather({"rank": comm.rank, "build_s": build_s, "condense_s": condense_s,
                        "maxrss_after_build_mb": rss_build, "maxrss_mb": rss_end,
                        "full_assemblies": asm.full_assemblies, "row_elements": asm.row_elements,
                        "n_elements": len(model.cells["quad"])}, root=0)
    if comm.rank == 0:
        np.save(out, K)
        with open(out + ".json", "w") as f:
            json.dump({"ranks": comm.size, "n_dofs": model.n_dofs, "m": model.m, "per_rank": rows}, f)


def run(ranks: int, refine: int, out: str) -> dict:
    env = dict(os.environ, PYTHONPATH=ROOT, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    extra = ["--allow-run-as-root"] if os.geteuid() == 0 else []
    cmd = [shutil.which("mpirun"), *extra, "--oversubscribe", "-n", str(ranks), "-x", "PYTHONPATH",
           "-x", "OMP_NUM_THREADS", "-x", "OPENBLAS_NUM_THREADS",
           sys.executable, os.path.abspath(__file__), "--worker", "--refine", str(refine), "--out", out]
    t = time.perf_counter()
    subprocess.run(cmd, check=True, env=env)
    wall = time.perf_counter() - t
    with open(out + ".json") as f:
        d = json.load(f)
    d["wall_s"] = wall
    return d


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="refine 71 (~1e5 DOFs) instead of 224 (~1e6)")
    ap.add_argument("--refine", type=int, help="block2d refine (overrides --quick)")
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--out", help=argparse.SUPPRESS)
    a = ap.parse_args()
    refine = a.refine or (71 if a.quick else 224)
    if a.worker:
        worker(refine, a.out)
        return
    import numpy as np
    rows, Ks = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for ranks in a.ranks:
            out = os.path.join(tmp, f"K{ranks}.npy")
            d = run(ranks, refine, out)
            Ks[ranks] = np.load(out)
            pr = d["per_rank"]
            row = {"ranks": ranks, "n_dofs": d["n_dofs"], "m": d["m"], "refine": refine,
                   "condense_s": max(r["condense_s"] for r in pr), "build_s": max(r["build_s"] for r in pr),
                   "wall_s": d["wall_s"], "maxrss_mb_per_rank": [r["maxrss_mb"] for r in pr],
                   "maxrss_after_build_mb_per_rank": [r["maxrss_after_build_mb"] for r in pr],
                   "per_rank": pr}
            rows.append(row)
            print(f"{ranks} rank(s), {d['n_dofs']} DOFs: condense {row['condense_s']:.2f} s, build "
                  f"{row['build_s']:.2f} s, peak RSS per rank {[round(x) for x in row['maxrss_mb_per_rank']]} MB"
                  f" (after build {[round(x) for x in row['maxrss_after_build_mb_per_rank']]}), elements "
                  f"assembled per rank {[r['row_elements'] for r in pr]} of {pr[0]['n_elements']}, whole K "
                  f"assembled {[r['full_assemblies'] for r in pr]} times")
    K1 = Ks[a.ranks[0]]
    for row in rows:
        row["rel_diff_vs_first"] = float(np.abs(Ks[row["ranks"]] - K1).max() / np.abs(K1).max())
    from hpcwedge.contact.condense import solver_name
    from hpcwedge.environment import environment
    solver_name()                       # PETSc initialised the way the product does it
    from petsc4py import PETSc
    res = {"model": f"block2d(rows={ROWS}, cols={COLS}, refine={refine})", "machine_cores": os.cpu_count(),
           "python": platform.python_version(), "petsc": ".".join(map(str, PETSc.Sys.getVersion())),
           "solver": "MUMPS LDL^T (parallel), reference BLAS", "rows": rows, "environment": environment()}
    stem = os.path.join(OUT, "bench_condense" + ("_quick" if refine == 71 and a.quick else ""))
    os.makedirs(OUT, exist_ok=True)
    with open(stem + ".json", "w") as f:
        json.dump(res, f, indent=1)
    with open(stem + ".csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["ranks", "n_dofs", "condense_s", "build_s", "wall_s", "max_maxrss_mb", "sum_maxrss_mb",
                    "rel_diff_vs_first"])
        for r in rows:
            w.writerow([r["ranks"], r["n_dofs"], f"{r['condense_s']:.3f}", f"{r['build_s']:.3f}", f"{r['wall_s']:.3f}",
                        f"{max(r['maxrss_mb_per_rank']):.0f}", f"{sum(r['maxrss_mb_per_rank']):.0f}",
                        f"{r['rel_diff_vs_first']:.2e}"])
    print(f"wrote {stem}.json, {stem}.csv")


if __name__ == "__main__":
    sys.path.insert(0, ROOT)
    main()
