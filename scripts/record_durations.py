#!/usr/bin/env python3
"""Task durations of real hpcwedge runs, for the engine's scaling benchmark (issue 42).

Runs three scenes in this process with an engine that times every task (wall seconds of
the handler, one BLAS thread) and writes results/task_durations.json:
  "subtree": plug3d 4 x 6, mu 0.65, no symmetry, patterns only (m = 24): per subtree task
             its seconds, its budget and the tree nodes it visited;
  "mu_c":    3D mu^c tasks: plug3d 3 x 6, mu 1.0, its node symmetry (m = 18): the "mu_c"
             job (one mu^c per pattern found; the global search's "global_mu_c" job is
             the same kind of task, but one task on plug3d 4 x 8);
  "face":    2D faces: plug2d m = 16 split on its last 5 nodes (32 faces; the face with
             every split node in contact holds about half the work, at m = 18 as at 16).
scripts/bench_scale.py replays them with time.sleep.

    PYTHONPATH=. .venv/bin/python scripts/record_durations.py [--out results/task_durations.json]
"""
from __future__ import annotations

import argparse
import json
import os
import time

from harness import RESULTS, environment, write_json

import hpcwedge as hw
from hpcwedge.parallel.engine import Engine
from hpcwedge.run.pipeline import run_scene

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

SCENES = {
    "subtree": {"name": "plug3d-4x6", "dim": 3, "model": {"kind": "plug3d", "levels": 4, "ring": 6},
                "friction": {"mu": [0.65]}, "compute": {"enumerate": True, "mu_c": "none"},
                "run": {"symmetry": False}},
    "mu_c": {"name": "plug3d-3x6", "dim": 3, "model": {"kind": "plug3d", "levels": 3, "ring": 6},
             "friction": {"mu": [1.0]}, "compute": {"enumerate": True, "mu_c": "cones"},
             "run": {"symmetry": True}},
    "face": {"name": "plug2d-m16", "dim": 2, "model": {"kind": "plug2d", "rows": 8, "cols": 3, "taper_deg": 10.0},
             "friction": {"mu": [0.5]}, "compute": {"mu_c": "none"}, "run": {"face_split": 5}},
}
#: the job of each scene whose tasks are recorded
JOBS = {"subtree": "patterns", "mu_c": "mu_c", "face": "rays"}


class TimingEngine(Engine):
    """An in-process Engine that records every task of every job: {job name: [record]}."""

    def __init__(self):
        super().__init__()
        self.records: dict = {}

    def run(self, job):
        handler, log = job.handler, self.records.setdefault(job.name, [])

        def timed(ctx, payload):
            t0 = time.perf_counter()
            out = handler(ctx, payload)
            rec = {"seconds": time.perf_counter() - t0}
            if job.kind == "subtree":
                rec.update(budget=int(payload[2]), nodes=int(out[2].get("nodes", 0)), opened=len(out[1]))
            log.append(rec)
            return out
        job.handler = timed
        return super().run(job)


def record(kind: str) -> dict:
    engine = TimingEngine()
    t0 = time.perf_counter()
    run_scene(hw.Scene.from_dict(SCENES[kind]), engine=engine)
    recs = engine.records[JOBS[kind]]
    return {"scene": SCENES[kind], "job": JOBS[kind], "run_seconds": time.perf_counter() - t0,
            "tasks": len(recs), "task_seconds": sum(r["seconds"] for r in recs), "records": recs}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(RESULTS, "task_durations.json"))
    ap.add_argument("--kinds", nargs="+", default=list(SCENES), choices=list(SCENES))
    a = ap.parse_args()
    out = {}
    if os.path.exists(a.out):                 # re-record some kinds, keep the others
        with open(a.out) as f:
            out = json.load(f)
    out.update(environment=environment(), load_before=os.getloadavg()[0])
    for kind in a.kinds:
        out[kind] = record(kind)
        print(f"{kind}: {out[kind]['tasks']} tasks, {out[kind]['task_seconds']:.1f} s", flush=True)
    write_json(a.out, out)


if __name__ == "__main__":
    main()
