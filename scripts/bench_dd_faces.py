#!/usr/bin/env python3
"""The 2D double description whole and split over faces (SPEC §5) on plug2d, the issue-2
target scene, timed through the product: hpcwedge.solve with run.face_split, and
`hpcwedge run` under mpirun.

    scripts/bench_dd_faces.py [--m 16 18 20] [--nodes m-1 m-2,m-1 ...] [--no-full]
                              [--workers 2] [--mu 0.65] [--limit SECONDS] [--out results]

Scene: plug2d (cols 3, taper 10 deg, free body), m = 2*rows contact nodes, mu = 0.65, the
rays and cones only (compute.mu_c = "none"). For every m:

  full   run.face_split = 0: one solve in a child process; the DD's wall seconds
         (stats.dd), the case's CPU seconds, cones seconds (the rest of the enumerate
         stage), the condense stage ("parametrize"), peak live rays, peak RSS.
  faces  for every --nodes set (the product splits on the last k nodes, run.face_split = k:
         "m-1", "m-2,m-1", ...): one serial solve; each face's DD seconds (stats.dd
         face_seconds), their sum, the largest face, and the best 2-worker makespan of the
         measured face times (exact, over all assignments).
  run    with --workers P: `hpcwedge run` of the split scene under mpirun -n P+1 (P workers
         and the master); the wall time of the whole command is the number to compare with
         the 60 s target.

Same-answer checks (harness.Checks): every split and every mpirun run gives the full run's
counts and cones. Each case is bounded by --limit (an overrun is recorded, the script goes
on). The machine is shared: CPU seconds are reported next to wall seconds. Every process runs
with one BLAS thread. Writes results/bench_dd_faces.json; exit status 1 when a check failed.
"""
from __future__ import annotations

import argparse
import itertools
import json
import os
import resource
import sys
import tempfile

from harness import OK, RESULTS, Checks, answer, mpirun_command, python_command, run_call, run_command, write_json

import hpcwedge as hw

COLS, TAPER = 3, 10.0
# one BLAS thread per process: P worker processes on P cores, as P MPI ranks would run
THREADS = {v: "1" for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}


def table(m: int, mu: float, split: int) -> dict:
    """The scene table: plug2d with m contact nodes, its DD split on the last `split` nodes."""
    return {"name": f"plug2d-m{m}", "dim": 2, "friction": {"mu": [mu]},
            "model": {"kind": "plug2d", "rows": m // 2, "cols": COLS, "taper_deg": TAPER},
            "compute": {"mu_c": "none"}, "run": {"face_split": split, "checkpoint_every_s": 600.0}}


def scene_toml(t: dict) -> str:
    """A scene table of table() as TOML text (for `hpcwedge run`)."""
    def value(v):
        return json.dumps(v)
    lines = [f"name = {value(t['name'])}", f"dim = {t['dim']}"]
    for section in ("model", "friction", "compute", "run"):
        lines.append(f"[{section}]")
        lines += [f"{k} = {value(v)}" for k, v in t[section].items()]
    return "\n".join(lines) + "\n"


def solve_case(m: int, mu: float, split: int) -> dict:
    """A case: the scene solved in this (child) process; its DD stats, timings and answers."""
    r = hw.solve(hw.Scene.from_dict(table(m, mu, split)))
    dd = r.stats["dd"][0]
    return {"dd": dd, "timings": r.timings, "answer": answer(r),
            "maxrss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6}


def split_nodes(text: str, m: int) -> int:
    """'m-1' -> 1, 'm-2,m-1' -> 2: the node set as the product's split (its last k nodes)."""
    nodes = sorted({_node(v, m) for v in text.split(",")})
    k = len(nodes)
    if nodes != list(range(m - k, m)):
        raise SystemExit(f"nodes {text!r} = {nodes}: the product splits on the last k nodes "
                         f"(run.face_split = k), e.g. {','.join(f'm-{i}' for i in range(k, 0, -1))}")
    return k


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


def full_record(m: int, mu: float, limit: float | None) -> dict:
    rec = run_call(solve_case, m, mu, 0, limit=limit)
    if rec["status"] != OK:
        return {"m": m, "kind": "full", "status": rec["status"], "seconds": rec["seconds"]}
    v = rec["value"]
    dd, run = v["dd"], v["answer"]["runs"][0]
    return {"m": m, "kind": "full", "wall": dd["seconds"], "cpu": rec["cpu_seconds"],
            "rays": run["n_wedged_rays"] + run["n_trivial_rays"], "max_rays": dd["max_rays"],
            "parametrize": v["timings"]["condense"], "cones_wall": v["timings"]["enumerate"] - dd["seconds"],
            "n_cones": run["n_cones"], "wedged": run["n_wedged_rays"], "maxrss_gb": v["maxrss_gb"],
            "answer": v["answer"]}


def faces_record(m: int, mu: float, k: int, limit: float | None) -> dict:
    from hpcwedge.rays.faces import branching_nodes, split_faces
    nodes = branching_nodes(m, k)
    rec = run_call(solve_case, m, mu, k, limit=limit)
    if rec["status"] != OK:
        return {"m": m, "kind": "faces", "nodes": nodes, "status": rec["status"], "seconds": rec["seconds"]}
    v = rec["value"]
    # merge_results lists face_seconds in canonical face order
    order = sorted(tuple(map(tuple, f)) for f in split_faces(m, nodes))
    faces = [{"face": [list(c), list(g)], "wall": s} for (c, g), s in zip(order, v["dd"]["face_seconds"])]
    walls = [f["wall"] for f in faces]
    return {"m": m, "kind": "faces", "nodes": nodes, "faces": faces, "sum_wall": sum(walls),
            "max_wall": max(walls), "makespan2_wall": best_makespan(walls), "cpu": rec["cpu_seconds"],
            "max_rays": v["dd"]["max_rays"], "maxrss_gb": v["maxrss_gb"], "answer": v["answer"]}


def parallel_record(m: int, mu: float, k: int, workers: int, limit: float | None) -> dict:
    """`hpcwedge run` of the split scene under mpirun -n workers+1; its answers from `show --json`."""
    with tempfile.TemporaryDirectory() as tmp:
        path, out = os.path.join(tmp, "scene.toml"), os.path.join(tmp, "out.h5")
        with open(path, "w") as f:
            f.write(scene_toml(table(m, mu, k)))
        env = dict(os.environ, **THREADS)
        rec = run_command(mpirun_command(workers + 1, "-m", "hpcwedge", "run", path, "-o", out, "-q", env=env),
                          limit=limit, env=env)
        base = {"m": m, "kind": "parallel", "workers": workers, "nodes": list(range(m - k, m))}
        if rec["status"] != OK:
            return {**base, "status": rec["status"], "seconds": rec["seconds"], "stderr": rec["stderr"][-2000:]}
        shown = run_command(python_command("-m", "hpcwedge", "show", out, "--json"), env=env)
        d = json.loads(shown["stdout"])
    dd = d["stats"]["dd"][0]
    return {**base, "wall_total": rec["seconds"], "stages": d["timings"], "faces_seconds": dd["face_seconds"],
            "wedged": d["runs"][0]["n_wedged_rays"], "n_cones": d["runs"][0]["n_cones"],
            "parallel": d["stats"]["parallel"], "load": os.getloadavg(), "answer": answer(d)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--m", type=int, nargs="+", default=[16, 18, 20])
    ap.add_argument("--mu", type=float, default=0.65)
    ap.add_argument("--nodes", nargs="*", default=["m-1", "m-2,m-1"],
                    help="branching node sets: the last k nodes, comma-separated (m-1: top right)")
    ap.add_argument("--no-full", action="store_true")
    ap.add_argument("--workers", type=int, default=0, help="also run the split under mpirun with P workers")
    ap.add_argument("--limit", type=float, default=None, help="seconds per case (default: none)")
    ap.add_argument("--out", default=RESULTS)
    args = ap.parse_args(argv)
    os.environ.update({k: os.environ.get(k, v) for k, v in THREADS.items()})     # the solves in the cases too
    checks = Checks()
    report = []
    splits = {m: [split_nodes(spec, m) for spec in args.nodes] for m in args.m}     # bad sets stop here
    for m in args.m:
        want = None
        if not args.no_full:
            r = full_record(m, args.mu, args.limit)
            report.append(r)
            if "status" in r:
                print(f"m={m} full: {r['status']} after {r['seconds']} s", flush=True)
            else:
                want = r["answer"]
                print(f"m={m} full: DD wall {r['wall']:.1f} s, case cpu {r['cpu']:.1f} s, cones "
                      f"{r['cones_wall']:.1f} s, condense {r['parametrize']:.2f} s, {r['wedged']} wedged rays, "
                      f"{r['n_cones']} cones, peak live rays {r['max_rays']}, peak RSS {r['maxrss_gb']:.2f} GB",
                      flush=True)
        for k in splits[m]:
            r = faces_record(m, args.mu, k, args.limit)
            report.append(r)
            if "status" in r:
                print(f"m={m} nodes {r['nodes']}: {r['status']} after {r['seconds']} s", flush=True)
            else:
                for f in r["faces"]:
                    print(f"m={m} nodes {r['nodes']} face {f['face']}: wall {f['wall']:.1f} s", flush=True)
                print(f"m={m} nodes {r['nodes']}: sum {r['sum_wall']:.1f} s, max {r['max_wall']:.1f} s, "
                      f"best 2-worker makespan {r['makespan2_wall']:.1f} s, case cpu {r['cpu']:.1f} s", flush=True)
                want = want or r["answer"]
                checks.compare(f"m={m} split on {r['nodes']} against the whole DD", r["answer"], want)
            if args.workers:
                r = parallel_record(m, args.mu, k, args.workers, args.limit)
                report.append(r)
                if "status" in r:
                    print(f"m={m} nodes {r['nodes']} under mpirun: {r['status']} after {r['seconds']} s", flush=True)
                    continue
                print(f"m={m} nodes {r['nodes']} on {args.workers} workers (mpirun): wall {r['wall_total']:.1f} s "
                      f"(condense {r['stages']['condense']:.2f}, enumerate {r['stages']['enumerate']:.1f}), "
                      f"{r['wedged']} wedged rays, {r['n_cones']} cones; faces sum "
                      f"{sum(r['faces_seconds']):.1f} s, largest {max(r['faces_seconds']):.1f} s; "
                      f"load {r['load'][0]:.2f}", flush=True)
                want = want or r["answer"]
                checks.compare(f"m={m} split on {r['nodes']} under mpirun against the whole DD", r["answer"], want)
    path = write_json(os.path.join(args.out, "bench_dd_faces.json"),
                      {"scene": f"plug2d cols {COLS} taper {TAPER} mu {args.mu}", "load": os.getloadavg(),
                       "records": report, "same_answers": checks.ok})
    print("wrote", path)
    return checks.exit_status()


if __name__ == "__main__":
    sys.exit(main())
