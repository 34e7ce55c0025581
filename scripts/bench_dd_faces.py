#!/usr/bin/env python3
"""Single-process DD and face splitting (SPEC §5) on plug2d, the issue-2 target scene.

    scripts/bench_dd_faces.py [--m 16 18 20] [--nodes m-1 m-2,m-1 ...] [--no-full]
                              [--workers 2] [--mu 0.65] [--out results]

Scene: plug2d (cols 3, taper 10 deg, free body), m = 2*rows contact nodes, mu = 0.65.
For every m:

  full   one subprocess: parametrize + friction_rows_2d + complementary_rays (one process,
         no face) + maximal_cones; DD wall and CPU seconds, cones seconds, peak RSS.
  faces  for every --nodes set (node indices; "m-1" is the top right node, "m/2-1" the
         top left one): each of its 2^k faces in its own subprocess (wall, CPU, rays, peak
         live rays, peak RSS), then: sum of face times, the largest face, and the best
         2-worker makespan of the measured face times (exact, over all assignments).
  run    with --workers P: the whole enumerate stage as a P-rank run would do it, here
         with P worker processes on this machine: parametrize in the parent, the faces
         handed out on demand (largest measured first), merge_results, maximal_cones in
         the parent. Its wall time is the number to compare with the 60 s target.

The machine is shared: CPU seconds are reported next to wall seconds (wall time under
load from other users is inflated). Every process runs with one BLAS thread (unless
OPENBLAS_NUM_THREADS etc. are set). Writes results/bench_dd_faces.json.
"""
from __future__ import annotations

import argparse
import itertools
import json
import os
import resource
import subprocess
import sys
import time

# one BLAS thread per process: P worker processes on P cores, as P MPI ranks would run
for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
MARK = "BENCH_RESULT "
COLS, TAPER = 3, 10.0


def _rows(m: int, mu: float):
    import hpcwedge.rays.cones  # noqa: F401  (networkx imported before any clock starts)
    from hpcwedge.contact.condense import condense
    from hpcwedge.contact.problem import ContactProblem, friction_rows_2d, parametrize
    from hpcwedge.models.library import plug2d
    K, N = condense(plug2d(m // 2, COLS, TAPER))
    t = time.perf_counter()
    A = friction_rows_2d(parametrize(ContactProblem(2, K, N)), mu, m)
    return A, time.perf_counter() - t


def _cones(dd):
    from hpcwedge.rays.cones import maximal_cones
    zero = dd.zero
    return maximal_cones(~zero[:, 0::3], ~(zero[:, 1::3] & zero[:, 2::3]), dd.wedged())


def _rss_gb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


def worker(m: int, mu: float, face: str | None) -> dict:
    from hpcwedge.rays.dd import complementary_rays
    A, t_param = _rows(m, mu)
    f = json.loads(face) if face else None
    t, c = time.perf_counter(), time.process_time()
    dd = complementary_rays(A, m, face=f)
    out = {"wall": time.perf_counter() - t, "cpu": time.process_time() - c, "rays": len(dd.X),
           "max_rays": dd.stats["max_rays"], "parametrize": t_param}
    if f is None:
        t = time.perf_counter()
        cones = _cones(dd)
        out.update(cones_wall=time.perf_counter() - t, n_cones=len(cones),
                   wedged=int(dd.wedged().sum()))
    out["maxrss_gb"] = _rss_gb()
    return out


def run_sub(m: int, mu: float, face=None) -> dict:
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", "--m", str(m), "--mu", repr(mu)]
    if face is not None:
        cmd += ["--face", json.dumps(face)]
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=True).stdout
    return json.loads(next(l for l in reversed(out.splitlines()) if l.startswith(MARK))[len(MARK):])


def _node(text: str, m: int) -> int:
    """'5', 'm-1', 'm/2-1' -> a node index."""
    expr = text.strip().replace("m/2", str(m // 2)).replace("m", str(m))
    if not all(c in "0123456789+-" for c in expr):
        raise SystemExit(f"bad node {text!r}")
    return int(eval(expr))


def best_makespan(times: list[float], workers: int = 2) -> float:
    if len(times) > 16:                                   # LPT bound beyond 2^16 assignments
        loads = [0.0] * workers
        for t in sorted(times, reverse=True):
            loads[loads.index(min(loads))] += t
        return max(loads)
    best = float("inf")
    for assign in itertools.product(range(workers), repeat=len(times)):
        loads = [0.0] * workers
        for t, a in zip(times, assign):
            loads[a] += t
        best = min(best, max(loads))
    return best


_A = None


def _face_task(face):
    """One face in a worker; the rays go back through a /dev/shm file (a pickle of
    ~700 MB through the pool's pipe costs ~10 s at m = 20; an MPI layer would send
    the arrays as buffers)."""
    import tempfile

    import numpy as np

    from hpcwedge.rays.dd import complementary_rays
    t, c = time.perf_counter(), time.process_time()
    dd = complementary_rays(_A, _A.shape[0] // 3, face=face)
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    fd, path = tempfile.mkstemp(suffix=".npz", dir=SHM)
    with os.fdopen(fd, "wb") as f:
        np.savez(f, X=dd.X, zero=np.packbits(dd.zero, axis=1), n=dd.zero.shape[1])
    return face, path, dd.stats, wall, cpu


def _load_face(path, stats):
    import numpy as np

    from hpcwedge.rays.dd import DDResult
    with np.load(path) as f:
        X, zero = f["X"], np.unpackbits(f["zero"], axis=1, count=int(f["n"])).astype(bool)
    os.unlink(path)
    return DDResult(X=X, zero=zero, stats=stats)


SHM = "/dev/shm" if os.path.isdir("/dev/shm") else None


def parallel_run(m: int, mu: float, nodes: list[int], workers: int, cost: dict) -> dict:
    """The enumerate stage with the faces on `workers` processes (fork), largest first."""
    import multiprocessing as mp

    from hpcwedge.rays.faces import merge_results, split_faces
    global _A
    t0 = time.perf_counter()
    _A, t_param = _rows(m, mu)
    faces = sorted(split_faces(m, nodes), key=lambda f: -cost.get(json.dumps(f), 0.0))
    t1 = time.perf_counter()
    per_face = []
    with mp.get_context("fork").Pool(workers) as pool:
        results = []
        for face, path, stats, wall, cpu in pool.imap_unordered(_face_task, faces):
            results.append(_load_face(path, stats))
            per_face.append({"face": face, "wall": wall, "cpu": cpu, "done_at": time.perf_counter() - t1})
    t2 = time.perf_counter()
    dd = merge_results(results)
    t3 = time.perf_counter()
    cones = _cones(dd)
    t4 = time.perf_counter()
    return {"workers": workers, "nodes": nodes, "wall_total": t4 - t0, "parametrize": t_param,
            "faces_wall": t2 - t1, "merge": t3 - t2, "cones": t4 - t3, "wedged": int(dd.wedged().sum()),
            "rays": len(dd.X), "n_cones": len(cones), "per_face": per_face,
            "parent_maxrss_gb": _rss_gb(), "load": os.getloadavg()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--m", type=int, nargs="+", default=[16, 18, 20])
    ap.add_argument("--mu", type=float, default=0.65)
    ap.add_argument("--nodes", nargs="*", default=["m-1", "m-2,m-1"],
                    help="branching node sets, comma-separated indices, may use m (m-1: top right)")
    ap.add_argument("--no-full", action="store_true")
    ap.add_argument("--workers", type=int, default=0, help="also run the faces on P processes")
    ap.add_argument("--out", default=os.path.join(ROOT, "results"))
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--face", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print(MARK + json.dumps(worker(args.m[0], args.mu, args.face)), flush=True)
        return 0
    from hpcwedge.rays.faces import split_faces
    report = []
    for m in args.m:
        if not args.no_full:
            r = run_sub(m, args.mu)
            print(f"m={m} full: DD wall {r['wall']:.1f} s cpu {r['cpu']:.1f} s, cones {r['cones_wall']:.1f} s, "
                  f"parametrize {r['parametrize']:.2f} s, {r['wedged']} wedged rays, {r['n_cones']} cones, "
                  f"peak live rays {r['max_rays']}, peak RSS {r['maxrss_gb']:.2f} GB", flush=True)
            report.append({"m": m, "kind": "full", **r})
        for spec in args.nodes:
            nodes = sorted({_node(v, m) for v in spec.split(",")})
            faces = []
            for f in split_faces(m, nodes):
                r = run_sub(m, args.mu, f)
                faces.append({"face": f, **r})
                print(f"m={m} nodes {nodes} face {f}: wall {r['wall']:.1f} s cpu {r['cpu']:.1f} s, "
                      f"{r['rays']} rays, peak live {r['max_rays']}, RSS {r['maxrss_gb']:.2f} GB", flush=True)
            for key in ("wall", "cpu"):
                ts = [f[key] for f in faces]
                print(f"m={m} nodes {nodes} [{key}]: sum {sum(ts):.1f} s, max {max(ts):.1f} s, "
                      f"best 2-worker makespan {best_makespan(ts):.1f} s", flush=True)
            rec = {"m": m, "kind": "faces", "nodes": nodes, "faces": faces,
                   "sum_wall": sum(f["wall"] for f in faces), "max_wall": max(f["wall"] for f in faces),
                   "makespan2_wall": best_makespan([f["wall"] for f in faces]),
                   "sum_cpu": sum(f["cpu"] for f in faces), "max_cpu": max(f["cpu"] for f in faces),
                   "makespan2_cpu": best_makespan([f["cpu"] for f in faces])}
            report.append(rec)
            if args.workers:
                cost = {json.dumps(f["face"]): f["cpu"] for f in faces}
                r = parallel_run(m, args.mu, nodes, args.workers, cost)
                busy = [sum(f["cpu"] for f in r["per_face"])]
                print(f"m={m} nodes {nodes} on {args.workers} processes: enumerate stage wall "
                      f"{r['wall_total']:.1f} s (parametrize {r['parametrize']:.2f}, faces {r['faces_wall']:.1f}, "
                      f"merge {r['merge']:.1f}, cones {r['cones']:.1f}), {r['wedged']} wedged rays, "
                      f"{r['n_cones']} cones; faces cpu sum {busy[0]:.1f} s, largest "
                      f"{max(f['cpu'] for f in r['per_face']):.1f} s; load {r['load'][0]:.2f}", flush=True)
                report.append({"m": m, "kind": "parallel", **r})
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, "bench_dd_faces.json")
    from hpcwedge.environment import environment
    with open(path, "w") as f:
        json.dump({"scene": f"plug2d cols {COLS} taper {TAPER} mu {args.mu}", "load": os.getloadavg(),
                   "records": report, "environment": environment()}, f, indent=1, default=str)
    print("wrote", path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
