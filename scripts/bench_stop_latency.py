#!/usr/bin/env python3
"""SIGTERM at many moments of one global mu^c run or one long condensation (issue 41): the exit
status (75: the checkpoint written, the run stopped) and the seconds from the signal to the exit.

    python scripts/bench_stop_latency.py [--quick] [--cases plug2d-r640 ...] [--stops 12]
                                         [--out results/bench_stop_latency]

Per case: one uninterrupted `hpcwedge run` (serially, or through jobs/wedge-mpirun.sh -n 2, which
passes a SIGTERM on to every rank as SLURM does) (its seconds T and mu^c), then one run per moment
i T / (N + 1), i = 1 .. N (N = --stops), each sent SIGTERM at that moment, and the last of them
resumed (`--resume`, from its checkpoint when it wrote one; a stop during start-up writes
none) to the end: its mu^c must be the uninterrupted one's. A run that ended before its moment
is not a row; one the signal reached while it wrote its result ends 0 with it
(a signal after the answer does not fail a run) and counts as served. Counts: the worst and the
median latency and how many stops took more than the target of 2 s. Seconds are wall clock
on a shared machine (read them as +-30 %). Writes <out>.json and <out>.csv; prints the table.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
HPCWEDGE = [sys.executable, "-m", "hpcwedge"]
MPIRUN_SCRIPT = os.path.join(ROOT, "jobs", "wedge-mpirun.sh")
#: block2d refine 160: 514,242 DOFs, 12 contact nodes; ~15-30 s of condensation on 2 cores
CONDENSED = {"kind": "block2d", "rows": 5, "cols": 2, "refine": 160}
#: name -> (dim, model table, ranks (None: serial), run table): the global runs of issue 41's
#: targets and one beyond (m = 1,280); then a long condensation (enumeration at mu 0.65, no
#: mu^c) serially (a forked child factors K_ii), under mpirun with the master condensing alone
#: (a spawned child) and collectively over the ranks (MUMPS called through ctypes)
CASES = {
    "plug2d-r320": (2, {"kind": "plug2d", "rows": 320}, None, {}),          # m = 640
    "block2d-r159": (2, {"kind": "block2d", "rows": 159}, None, {}),        # m = 320
    "plug3d-8x16": (3, {"kind": "plug3d", "levels": 8, "ring": 16}, None, {}),   # m = 128
    "plug2d-r640": (2, {"kind": "plug2d", "rows": 640}, None, {}),          # m = 1,280
    "condense-r160": (2, CONDENSED, None, {}),
    "condense-r160-mpi2": (2, CONDENSED, 2, {}),
    "condense-r160-mpi2-distributed": (2, CONDENSED, 2, {"condense": "distributed"}),
}
QUICK = ("block2d-r159",)
TARGET_S = 2.0


def scene_text(name: str, dim: int, model: dict, run_table: dict) -> str:
    """The case's scene: global mu^c only, symmetry off (as bench_global_scale's); for the
    condensation cases (CONDENSED) the enumeration at mu 0.65 instead."""
    body = "\n".join(f"{k} = {json.dumps(v)}" for k, v in model.items())
    run_body = "".join(f"{k} = {json.dumps(v)}\n" for k, v in {"symmetry": False, **run_table}.items())
    compute = ('[friction]\nmu = [0.65]\n[compute]\nmu_c = "none"\n' if model is CONDENSED else
               '[friction]\nmu = [0.01]\n[compute]\nenumerate = false\nmu_c = "global"\n')
    return f'name = "{name}"\ndim = {dim}\n[model]\n{body}\n{compute}[run]\n{run_body}'


def run(scene: str, out: str, stop_at: float | None = None, resume: bool = False,
        ranks: int | None = None) -> dict:
    """One `hpcwedge run` (quiet, stdin closed; ranks: through jobs/wedge-mpirun.sh -n ranks);
    with stop_at, SIGTERM that many seconds after the start: {"exit", "seconds" (start to
    exit), "latency_s" (signal to exit) or None}."""
    if ranks is None:
        cmd = HPCWEDGE + ["run", "-q", scene, "-o", out] + (["--resume"] if resume else [])
    else:
        cmd = ["bash", MPIRUN_SCRIPT, "-n", str(ranks)] + ([] if resume else ["--no-resume"]) + [scene, out]
    t0 = time.monotonic()
    # os.environ, not the C environment: an MPI started in this process (PETSc's singleton)
    # adds variables there that make a child's mpirun fail at once
    p = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                         env=dict(os.environ))
    sent = None
    if stop_at is not None:
        try:
            p.wait(timeout=stop_at)
        except subprocess.TimeoutExpired:
            sent = time.monotonic()
            p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=3600)
    end = time.monotonic()
    return {"exit": p.returncode, "seconds": round(end - t0, 3),
            "latency_s": None if sent is None else round(end - sent, 3), "stderr": err[-300:]}


def mu_c_of(path: str) -> float | None:
    """The result's global mu^c; None when it has none (not computed: stored as NaN)."""
    import math

    import h5py
    with h5py.File(path, "r") as f:
        v = f.attrs.get("mu_c")
        return None if v is None or math.isnan(float(v)) else float(v)


def measure(name: str, n_stops: int, folder: str) -> dict:
    """The case's record (module doc)."""
    dim, model, ranks, run_table = CASES[name]
    scene = os.path.join(folder, f"{name}.toml")
    with open(scene, "w") as f:
        f.write(scene_text(name, dim, model, run_table))
    full = run(scene, os.path.join(folder, f"{name}-full.h5"), ranks=ranks)
    rec = {"case": name, "ranks": ranks or 1, "full_s": full["seconds"], "full_exit": full["exit"]}
    if full["exit"] != 0:
        return {**rec, "error": full["stderr"]}
    rec["mu_c"] = mu_c_of(os.path.join(folder, f"{name}-full.h5"))
    rec["answer"] = answer_of(os.path.join(folder, f"{name}-full.h5"))
    stops, last = [], None
    for i in range(1, n_stops + 1):
        t = round(i * full["seconds"] / (n_stops + 1), 3)
        out = os.path.join(folder, f"{name}-stop{i}.h5")
        r = run(scene, out, stop_at=t, ranks=ranks)
        if r["latency_s"] is not None:
            stops.append({"at_s": t, "exit": r["exit"], "latency_s": r["latency_s"]})
            print(json.dumps({"case": name, **stops[-1]}), flush=True)
            last = out
    rec["stops"] = stops
    rec.update(summary(stops))
    if last is not None:
        rec["resume_from_checkpoint"] = os.path.exists(last + ".ckpt")   # else stopped before one: afresh
        r = run(scene, last, resume=True, ranks=ranks)
        rec["resume_exit"] = r["exit"]
        rec["resume_mu_c"] = mu_c_of(last) if r["exit"] == 0 else None
        rec["resume_same"] = (r["exit"] == 0 and rec["resume_mu_c"] == rec["mu_c"]
                              and answer_of(last) == rec["answer"])
    return rec


def answer_of(path: str) -> list:
    """What a run found beside mu^c: per mu, the count of wedged rays and cones (2D) or
    patterns (3D) in its result file."""
    import h5py
    with h5py.File(path, "r") as f:
        return [[k, {a: int(v) for a, v in g.attrs.items() if a.startswith("n_")}]
                for k, g in sorted(f.get("runs", {}).items())]


def summary(stops: list[dict]) -> dict:
    """The counts of a case's stops (module doc): worst and median latency, how many above
    TARGET_S, how many ended 75 and 0, and whether every one was served (75, or 0: finished)."""
    lat = sorted(s["latency_s"] for s in stops)
    return {"worst_latency_s": lat[-1] if lat else None, "median_latency_s": lat[len(lat) // 2] if lat else None,
            "over_target": sum(x > TARGET_S for x in lat), "exit_75": sum(s["exit"] == 75 for s in stops),
            "exit_0": sum(s["exit"] == 0 for s in stops), "all_served": all(s["exit"] in (0, 75) for s in stops)}


def kept_records(path: str, names: list[str]) -> list[dict]:
    """The records of <out>.json for the cases not measured now (a run of some cases keeps the
    others' last measurement), in CASES order."""
    try:
        with open(path) as f:
            old = json.load(f).get("records", [])
    except (OSError, ValueError):
        return []
    return [r for r in old if r.get("case") in CASES and r.get("case") not in names]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=f"only {', '.join(QUICK)}")
    ap.add_argument("--cases", nargs="+", choices=sorted(CASES),
                    help="the cases to run (default: all); the others' records in <out>.json are kept")
    ap.add_argument("--stops", type=int, default=12, help="stopped runs per case")
    ap.add_argument("--out", default=os.path.join(ROOT, "results", "bench_stop_latency"))
    args = ap.parse_args()
    names = list(QUICK) if args.quick else args.cases or list(CASES)
    with tempfile.TemporaryDirectory() as folder:
        records = [measure(n, args.stops, folder) for n in names]
    records = kept_records(args.out + ".json", names) + records
    doc = {"machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                       "note": "shared with other jobs: seconds are noisy"},
           "target_s": TARGET_S, "records": records}
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    with open(args.out + ".json", "w") as f:
        json.dump(doc, f, indent=1)
    cols = ("case", "ranks", "full_s", "mu_c", "worst_latency_s", "median_latency_s", "over_target", "exit_75", "exit_0",
            "resume_same")
    with open(args.out + ".csv", "w") as f:
        f.write(",".join(cols) + "\n")
        for r in records:
            f.write(",".join(str(r.get(c, "")) for c in cols) + "\n")
    for r in records:
        print("  ".join(f"{c}={r.get(c)}" for c in cols))
    return 0 if all(r.get("all_served") and r.get("resume_same", True) for r in records if r["case"] in names) else 1


if __name__ == "__main__":
    sys.exit(main())
