"""SIGTERM to jobs/wedge-mpirun.sh at many rank counts (issue 42): the exit status (75:
the checkpoint written and the run stopped) and the seconds from the signal to the exit.

    PYTHONPATH=. python scripts/bench_sigterm.py [--ranks 3 9 17 33 65] [--out results/bench_sigterm.json]

Each case runs plug3d 2 x 6 at two mu without its symmetry (tests/parallel/test_resume_ranks.py's
scene) under `jobs/wedge-mpirun.sh -n RANKS` (oversubscribed past the cores) and sends the
script SIGTERM once the first checkpoint is written. The tests cover 3, 9 and 17 ranks; this
script every count from 3 to 65 in one record (the larger take minutes on 2 cores).
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
sys.path.insert(0, os.path.join(ROOT, "tests"))

from mpi_helpers import STOP_SCENE as SCENE  # noqa: E402  (the test's scene)


def stop_once(ranks: int, folder: str) -> dict:
    """One case: {"ranks", "exit", "start_to_checkpoint_s", "signal_to_exit_s", "reason"}."""
    from hpcwedge.parallel.checkpoint import read_checkpoint
    scene = os.path.join(folder, f"scene-{ranks}.toml")
    out = os.path.join(folder, f"r-{ranks}.h5")
    with open(scene, "w") as f:
        f.write(SCENE)
    env = {**os.environ, "HPCWEDGE_PYTHON": sys.executable}
    t0 = time.monotonic()
    p = subprocess.Popen([os.path.join(ROOT, "jobs", "wedge-mpirun.sh"), "-n", str(ranks), scene, out],
                         env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    while not os.path.exists(out + ".ckpt"):
        if p.poll() is not None:
            return {"ranks": ranks, "exit": p.returncode, "error": "ended before a checkpoint",
                    "stderr": p.stderr.read()[-2000:]}
        time.sleep(0.05)
    t1 = time.monotonic()
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=600)
    t2 = time.monotonic()
    reason = read_checkpoint(out + ".ckpt")["attrs"]["reason"] if os.path.exists(out + ".ckpt") else None
    return {"ranks": ranks, "exit": p.returncode, "start_to_checkpoint_s": round(t1 - t0, 2),
            "signal_to_exit_s": round(t2 - t1, 2), "reason": reason,
            **({} if p.returncode == 75 else {"stderr": err[-2000:]})}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ranks", type=int, nargs="+", default=[3, 9, 17, 33, 65])
    ap.add_argument("--out", default=os.path.join(ROOT, "results", "bench_sigterm.json"))
    args = ap.parse_args()
    cases = []
    with tempfile.TemporaryDirectory() as folder:
        for n in args.ranks:
            cases.append(stop_once(n, folder))
            print(json.dumps(cases[-1]), flush=True)
    record = {"machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                          "note": "shared with other jobs: seconds are noisy"},
              "cases": cases}
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(record, f, indent=1)
    return 0 if all(c["exit"] == 75 for c in cases) else 1


if __name__ == "__main__":
    sys.exit(main())
