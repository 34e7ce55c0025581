#!/usr/bin/env python3
"""What it costs to make a long condensation stoppable: the serial condensation of block2d
(rows 5, cols 2, refine f; 12 contact nodes) in the process itself, in a forked child
(forked.in_child: a serial run) and in a spawned interpreter (forked.in_spawned: the master of
an MPI run), each in a fresh interpreter of its own, and whether the three give K_local bit for bit.

    PYTHONPATH=. .venv/bin/python scripts/bench_condense_routes.py [--refine 40 80 120 160]
                                                                 [--repeat 2] [--out results/bench_condense_routes]

Per (refine, route), the best of --repeat runs of condense.condense (wall seconds, the model
already built; the spawned route's interpreter start, imports and pickling included). The
thresholds condense.CHILD_MIN_DOFS and SPAWN_MIN_DOFS are set so that the route is taken. Seconds
are wall clock on a shared machine (read them as +-30 %); the bits are exact. Writes
<out>.json and <out>.csv and prints the table.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ROUTES = ("here", "forked", "spawned")
ROWS, COLS = 5, 2


def one(route: str, refine: int, repeat: int) -> dict:
    """The route's best time and K_local digest (run in a fresh interpreter: `--one`)."""
    import time

    from hpcwedge.contact import condense as C
    from hpcwedge.models import block2d
    model = block2d(ROWS, COLS, refine)
    C.CHILD_MIN_DOFS = 0 if route == "forked" else 10 ** 12
    C.SPAWN_MIN_DOFS = 0 if route == "spawned" else 10 ** 12
    if route != "forked":
        C.petsc()                       # PETSc started here: no fork (as in an MPI run's master)
    best, K = float("inf"), None
    for _ in range(repeat):
        t = time.perf_counter()
        K, _ = C.condense(model)
        best = min(best, time.perf_counter() - t)
    return {"route": route, "refine": refine, "n_dofs": model.n_dofs, "seconds": round(best, 3),
            "k_local_sha256": hashlib.sha256(K.tobytes()).hexdigest()[:16]}


def measure(refine: int, repeat: int) -> list[dict]:
    """The three routes at one refinement, each in its own interpreter."""
    out = []
    for route in ROUTES:
        p = subprocess.run([sys.executable, os.path.abspath(__file__), "--one", route, str(refine), str(repeat)],
                           capture_output=True, text=True, stdin=subprocess.DEVNULL, env=dict(os.environ))
        if p.returncode != 0:
            raise SystemExit(f"{route} refine {refine}: exit {p.returncode}\n{p.stderr[-2000:]}")
        out.append(json.loads(p.stdout.strip().splitlines()[-1]))
        print(json.dumps(out[-1]), flush=True)
    same = len({r["k_local_sha256"] for r in out}) == 1
    here = out[0]["seconds"]
    for r in out:
        r["same_bits"] = same
        r["over_here_s"] = round(r["seconds"] - here, 3)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--refine", type=int, nargs="+", default=[40, 80, 120, 160])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--out", default=os.path.join(ROOT, "results", "bench_condense_routes"))
    ap.add_argument("--one", nargs=3, metavar=("ROUTE", "REFINE", "REPEAT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        print(json.dumps(one(args.one[0], int(args.one[1]), int(args.one[2]))))
        return 0
    records = [r for f in args.refine for r in measure(f, args.repeat)]
    from hpcwedge.contact.condense import CHILD_MIN_DOFS, SPAWN_MIN_DOFS
    doc = {"machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                       "note": "shared with other jobs: seconds are noisy"},
           "child_min_dofs": CHILD_MIN_DOFS, "spawn_min_dofs": SPAWN_MIN_DOFS, "records": records}
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    with open(args.out + ".json", "w") as f:
        json.dump(doc, f, indent=1)
    cols = ("refine", "n_dofs", "route", "seconds", "over_here_s", "same_bits")
    with open(args.out + ".csv", "w") as f:
        f.write(",".join(cols) + "\n")
        for r in records:
            f.write(",".join(str(r[c]) for c in cols) + "\n")
    for r in records:
        print("  ".join(f"{c}={r[c]}" for c in cols))
    return 0 if all(r["same_bits"] for r in records) else 1


if __name__ == "__main__":
    sys.exit(main())
