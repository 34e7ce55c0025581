#!/usr/bin/env python3
"""A stiffness assembled elsewhere (issue 43): a 10^6-DOF matrix in PETSc binary condensed under
mpirun -n 2 with run.condense = "distributed", beside the built-in route on the same body.

The body is block2d(rows=5, cols=2, refine=f) (m = 12 contact nodes, 2 (5f+1)(2f+1) DOFs:
f = 224 gives 1,006,658; --quick f = 71 gives 1.0e5). The parent assembles its K once and
writes it with PETSc's MatView as body.petsc (and the nodes as nodes.npy), then starts itself
under mpirun (`--worker`) twice:

    matrix    every rank builds the kind = "matrix" model of a scene naming body.petsc
              (contact/build.py: only the file's header is read) and condenses it through
              build.contact_problem collectively: each rank MatLoads its N/P rows of the file in
              parallel (condense._loaded_blocks), checks them, and the interior rows go to
              parallel MUMPS; whole_loads (times the whole K was loaded on the rank) must be 0
    builtin   every rank builds block2d and condenses it with condense_distributed (each
              rank assembles its own rows from the elements: scripts/bench_condense.py)

Per rank: the condensation time (after a barrier, to the allreduced result) and the peak
resident memory (getrusage ru_maxrss). The two K_local must agree (relative max-difference,
in the scene's units). Writes results/bench_matrix{,_quick}.{json,csv}.

    .venv/bin/python scripts/bench_matrix.py [--quick] [--refine F] [--ranks 2]
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


def write_body(refine: int, folder: str) -> dict:
    """block2d's K as folder/body.petsc (MatView), its nodes as nodes.npy, and a kind =
    "matrix" scene folder/matrix.toml; sizes and the write time."""
    import numpy as np
    from petsc4py import PETSc

    from hpcwedge.models import block2d
    model = block2d(ROWS, COLS, refine)
    t = time.perf_counter()
    K = model.K.tocsr()
    K.sort_indices()
    A = PETSc.Mat().createAIJ(size=K.shape, csr=(K.indptr.astype(PETSc.IntType), K.indices.astype(PETSc.IntType),
                                                 K.data), comm=PETSc.COMM_SELF)
    A.assemble()
    viewer = PETSc.Viewer().createBinary(os.path.join(folder, "body.petsc"), "w", comm=PETSc.COMM_SELF)
    A.view(viewer)
    viewer.destroy()
    A.destroy()
    np.save(os.path.join(folder, "nodes.npy"), model.coords)
    with open(os.path.join(folder, "matrix.toml"), "w") as f:
        f.write(f'name = "block2d as a matrix"\ndim = 2\n[model]\nkind = "matrix"\nK = "body.petsc"\n'
                f'nodes = "nodes.npy"\n[contact]\nnodes = {model.contact_nodes.tolist()}\n'
                f'normals = {model.normals.tolist()}\n[friction]\nmu = [0.5]\n[run]\ncondense = "distributed"\n')
    return {"n_dofs": model.n_dofs, "nnz": int(K.nnz), "m": model.m, "write_s": time.perf_counter() - t,
            "file_mb": os.path.getsize(os.path.join(folder, "body.petsc")) / 2 ** 20}


def worker(route: str, refine: int, folder: str, out: str) -> None:
    """One rank of one route: build, condense collectively, gather the measurements."""
    import resource

    import numpy as np
    from mpi4py import MPI

    sys.path.insert(0, ROOT)
    from hpcwedge.contact.build import build_model, contact_problem, stiffness_exponent
    from hpcwedge.contact.condense import condense_distributed
    from hpcwedge.models import block2d
    from hpcwedge.scene.parse import load_scene

    comm = MPI.COMM_WORLD
    t = time.perf_counter()
    if route == "matrix":
        scene = load_scene(os.path.join(folder, "matrix.toml"))
        model = build_model(scene)
    else:
        model = block2d(ROWS, COLS, refine)
    build_s = time.perf_counter() - t
    rss_build = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    comm.Barrier()
    t = time.perf_counter()
    if route == "matrix":
        K = np.ldexp(contact_problem(scene, model, comm).K, stiffness_exponent(scene))    # the scene's units
    else:
        K, _ = condense_distributed(model, comm)
    condense_s = time.perf_counter() - t
    rss_end = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    whole = model.assembly.full_assemblies
    rows = comm.gather({"rank": comm.rank, "build_s": build_s, "condense_s": condense_s,
                        "maxrss_after_build_mb": rss_build, "maxrss_mb": rss_end, "whole_loads": whole},
                       root=0)
    if comm.rank == 0:
        np.save(out, K)
        with open(out + ".json", "w") as f:
            json.dump({"ranks": comm.size, "n_dofs": model.n_dofs, "per_rank": rows}, f)


def run(route: str, ranks: int, refine: int, folder: str) -> dict:
    out = os.path.join(folder, f"K_{route}_{ranks}.npy")
    env = dict(os.environ, PYTHONPATH=ROOT, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    extra = ["--allow-run-as-root"] if os.geteuid() == 0 else []
    cmd = [shutil.which("mpirun"), *extra, "--oversubscribe", "-n", str(ranks), "-x", "PYTHONPATH",
           "-x", "OMP_NUM_THREADS", "-x", "OPENBLAS_NUM_THREADS", sys.executable, os.path.abspath(__file__),
           "--worker", route, "--refine", str(refine), "--folder", folder, "--out", out]
    t = time.perf_counter()
    subprocess.run(cmd, check=True, env=env)
    wall = time.perf_counter() - t
    with open(out + ".json") as f:
        d = json.load(f)
    import numpy as np
    d["K"] = np.load(out)
    d["wall_s"] = wall
    return d


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="refine 71 (~1e5 DOFs) instead of 224 (~1e6)")
    ap.add_argument("--refine", type=int, help="block2d refine (overrides --quick)")
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--worker", choices=("matrix", "builtin"), help=argparse.SUPPRESS)
    ap.add_argument("--folder", help=argparse.SUPPRESS)
    ap.add_argument("--out", help=argparse.SUPPRESS)
    a = ap.parse_args()
    refine = a.refine or (71 if a.quick else 224)
    if a.worker:
        worker(a.worker, refine, a.folder, a.out)
        return
    import numpy as np
    rows, Ks = [], {}
    with tempfile.TemporaryDirectory(dir=os.environ.get("TMPDIR")) as tmp:
        body = write_body(refine, tmp)
        print(f"block2d refine {refine}: {body['n_dofs']:,} DOFs, {body['nnz']:,} stored entries, body.petsc "
              f"{body['file_mb']:.0f} MB (written in {body['write_s']:.1f} s)")
        for route in ("matrix", "builtin"):
            d = run(route, a.ranks, refine, tmp)
            Ks[route] = d["K"]
            pr = d["per_rank"]
            row = {"route": route, "ranks": a.ranks, "n_dofs": d["n_dofs"], "refine": refine,
                   "condense_s": max(r["condense_s"] for r in pr), "build_s": max(r["build_s"] for r in pr),
                   "wall_s": d["wall_s"], "maxrss_mb_per_rank": [r["maxrss_mb"] for r in pr],
                   "whole_loads_per_rank": [r["whole_loads"] for r in pr], "per_rank": pr}
            rows.append(row)
            print(f"{route}: {a.ranks} ranks: condense {row['condense_s']:.2f} s, build {row['build_s']:.2f} s, "
                  f"peak RSS per rank {[round(x) for x in row['maxrss_mb_per_rank']]} MB, whole K loaded/assembled "
                  f"{row['whole_loads_per_rank']} times")
    diff = float(np.abs(Ks["matrix"] - Ks["builtin"]).max() / np.abs(Ks["builtin"]).max())
    print(f"K_local: matrix route against the built-in route, relative max-difference {diff:.2e}")
    from hpcwedge.contact.condense import solver_name
    from hpcwedge.environment import environment
    solver_name()
    from petsc4py import PETSc
    res = {"model": f"block2d(rows={ROWS}, cols={COLS}, refine={refine}) written as PETSc binary", "body": body,
           "machine_cores": os.cpu_count(), "python": platform.python_version(),
           "petsc": ".".join(map(str, PETSc.Sys.getVersion())), "solver": "MUMPS (parallel), reference BLAS",
           "rel_diff_matrix_vs_builtin": diff, "rows": rows, "environment": environment(),
           "note": "shared machine: timings are noisy"}
    stem = os.path.join(OUT, "bench_matrix" + ("_quick" if refine == 71 and a.quick else ""))
    os.makedirs(OUT, exist_ok=True)
    with open(stem + ".json", "w") as f:
        json.dump(res, f, indent=1)
    with open(stem + ".csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["route", "ranks", "n_dofs", "condense_s", "build_s", "wall_s", "max_maxrss_mb", "whole_loads"])
        for r in rows:
            w.writerow([r["route"], r["ranks"], r["n_dofs"], f"{r['condense_s']:.3f}", f"{r['build_s']:.3f}",
                        f"{r['wall_s']:.3f}", f"{max(r['maxrss_mb_per_rank']):.0f}", max(r["whole_loads_per_rank"])])
    print(f"wrote {stem}.json, {stem}.csv")


if __name__ == "__main__":
    sys.path.insert(0, ROOT)
    main()
