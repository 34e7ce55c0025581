#!/usr/bin/env python3
"""The engine itself at many ranks, measured and modelled (issue 42).

Measured: synthetic jobs (scripts/scale_workload.py: TaskJob / TreeJob tasks that sleep for
durations recorded from real runs, results/task_durations.json by
scripts/record_durations.py) run by the real engine under `mpirun --oversubscribe` at 3, 9,
17, 33, 65 (and 129) ranks on this machine: sleeping workers leave the cores to the master,
so what is measured is the master's throughput and the workers' idle time. One launch per
rank count runs the three workloads in turn, each sized to about SECONDS_PER_WORKER x
workers worker-seconds. Per run: tasks, tasks per second, the master's busy fraction (its
wall time outside mpi.wait_any's waits), efficiency = the sum of the task seconds / (workers
x wall), wall from the first task sent to the last result merged (start-up excluded).

Modelled: parallel.model.simulate on the same jobs with the master's costs measured here
(the median over the measured runs of the master's busy seconds per task, half to send and
half to merge); "model_error" = modelled minus measured efficiency of each measured run;
then 256, 1,024 and 4,096 ranks with max(MIN_WORKER_SECONDS, MODEL_SECONDS_PER_WORKER x
workers) worker-seconds.

Writes results/bench_scale.json ("measured", "modelled", the costs, the load) and
results/bench_scale.png (efficiency against ranks).

    PYTHONPATH=. .venv/bin/python scripts/bench_scale.py [--quick] [--ranks 3 9 ...] [--seconds 8]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from harness import RESULTS, mpirun_command, python_command, write_json  # noqa: E402
from scale_workload import load_durations, make_job, task_seconds  # noqa: E402

WORKLOADS = ("subtree", "mu_c", "face")
RANKS, QUICK_RANKS, MODEL_RANKS = (3, 9, 17, 33, 65, 129), (3, 9, 17, 33, 65), (256, 1024, 4096)
#: measured runs: worker-seconds per worker; modelled runs: the same, at least MIN_WORKER_SECONDS
SECONDS_PER_WORKER = 8.0
MODEL_SECONDS_PER_WORKER = 6.0
MIN_WORKER_SECONDS = 2000.0
#: the wire and a worker's wake-up before its task starts (the measured ~0.2 ms round trip)
LATENCY_S = 2e-4


def rank_run(durations_path: str, seconds: float, out: str, workloads) -> None:
    """Under mpirun: rank 0 runs each workload's job as the engine's master, the others serve."""
    from hpcwedge.parallel import mpi
    from hpcwedge.parallel.engine import Engine
    from hpcwedge.parallel.worker import serve
    comm = mpi.world()
    if comm.rank != 0:
        comm.Barrier()
        serve(comm)
        return
    durations = load_durations(durations_path)
    engine = Engine(comm)
    waited = [0.0]
    real_wait = mpi.wait_any

    def timed_wait(*args):              # the master's idle time: its waits for a result
        t0 = time.perf_counter()
        try:
            return real_wait(*args)
        finally:
            waited[0] += time.perf_counter() - t0
    mpi.wait_any = timed_wait
    comm.Barrier()                      # every rank is up: start-up ends here
    rows = []
    workers = comm.size - 1
    for seed, workload in enumerate(workloads):
        job = make_job(workload, durations, seconds * workers, seed, sleep=True)
        waited[0] = 0.0
        t0, c0 = time.perf_counter(), time.process_time()
        engine.run(job)
        wall = time.perf_counter() - t0
        task_s = (sum(r["seconds"] for r in job.output()) if workload != "subtree"
                  else job.counters["seconds"])
        rows.append({"ranks": comm.size, "workload": workload, "seed": seed, "tasks": job.counters["tasks"],
                     "wall_s": wall, "task_s": task_s, "busy_s": wall - waited[0],
                     "cpu_s": time.process_time() - c0, "worker_seconds_asked": seconds * workers})
    engine.close()
    with open(out, "w") as f:
        json.dump(rows, f)


def measure(ranks: int, durations_path: str, seconds: float, workloads) -> list[dict]:
    """One mpirun launch at `ranks`: its rows, with tasks_per_s, master_busy, efficiency."""
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1",
               OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "rows.json")
        cmd = mpirun_command(ranks, os.path.abspath(__file__), "--rank-run", durations_path, str(seconds), out,
                             *workloads, env=env)
        load = os.getloadavg()[0]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)}: exit {proc.returncode}\n{proc.stderr[-3000:]}")
        with open(out) as f:
            rows = json.load(f)
    launch = time.perf_counter() - t0
    for r in rows:
        r.update(tasks_per_s=r["tasks"] / r["wall_s"], master_busy=r["busy_s"] / r["wall_s"],
                 efficiency=r["task_s"] / ((ranks - 1) * r["wall_s"]), launch_s=launch, load_before=load)
        print(f"{ranks:4d} ranks {r['workload']:8s} {r['tasks']:6d} tasks {r['tasks_per_s']:8.1f}/s "
              f"busy {r['master_busy']:.3f} efficiency {r['efficiency']:.3f}", flush=True)
    return rows


def model_run(workload: str, durations: dict, ranks: int, worker_seconds: float, seed: int, costs):
    from hpcwedge.parallel.model import simulate
    job = make_job(workload, durations, worker_seconds, seed, sleep=False)
    return simulate(job, ranks - 1, costs, task_seconds)


def master_costs(measured: list[dict]):
    """MasterCosts from the measured runs: the median busy seconds per task, half each way."""
    from hpcwedge.parallel.model import MasterCosts
    per_task = statistics.median(r["busy_s"] / r["tasks"] for r in measured)
    return MasterCosts(send_s=per_task / 2, merge_s=per_task / 2, latency_s=LATENCY_S)


def plot(measured: list[dict], modelled: list[dict], path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for i, w in enumerate(WORKLOADS):
        meas = [r for r in measured if r["workload"] == w]
        mod = sorted([(r["ranks"], r["efficiency"] + r["model_error"]) for r in meas]
                     + [(r["ranks"], r["efficiency"]) for r in modelled if r["workload"] == w])
        if not meas:
            continue
        ax.plot([r["ranks"] for r in meas], [r["efficiency"] for r in meas], "o", color=f"C{i}",
                label=f"{w} measured")
        ax.plot(*zip(*mod), "--", color=f"C{i}", label=f"{w} model")
    ax.set_xscale("log", base=2)
    ax.set_xlabel("MPI ranks (1 master + workers)")
    ax.set_ylabel("efficiency (task time / workers x wall)")
    ax.set_ylim(0, 1.05)
    ax.axhline(0.9, color="grey", lw=0.5)
    ax.legend(fontsize=8)
    ax.set_title("hpcwedge engine: measured (2 cores, oversubscribed) and modelled")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="stop at 65 ranks")
    ap.add_argument("--ranks", type=int, nargs="+")
    ap.add_argument("--seconds", type=float, default=SECONDS_PER_WORKER, help="worker-seconds per worker")
    ap.add_argument("--durations", default=os.path.join(RESULTS, "task_durations.json"))
    ap.add_argument("--workloads", nargs="+", default=list(WORKLOADS), choices=WORKLOADS)
    ap.add_argument("--out", default=os.path.join(RESULTS, "bench_scale"))
    ap.add_argument("--rank-run", nargs="+", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.rank_run:
        path, seconds, out, *workloads = a.rank_run
        return rank_run(path, float(seconds), out, workloads)
    ranks = a.ranks or (QUICK_RANKS if a.quick else RANKS)
    durations = load_durations(a.durations)
    t0 = time.perf_counter()
    measured = [r for n in ranks for r in measure(n, a.durations, a.seconds, a.workloads)]
    costs = master_costs(measured)
    for r in measured:
        sim = model_run(r["workload"], durations, r["ranks"], r["worker_seconds_asked"], r["seed"], costs)
        r["model_error"] = sim.efficiency - r["efficiency"]
    modelled = []
    for n in MODEL_RANKS:
        for seed, w in enumerate(a.workloads):
            ws = max(MIN_WORKER_SECONDS, MODEL_SECONDS_PER_WORKER * (n - 1))
            sim = model_run(w, durations, n, ws, seed, costs)
            modelled.append({"workload": w, "ranks": n, "worker_seconds": sim.task_s, "efficiency": sim.efficiency,
                             "tasks": sim.tasks, "master_busy": sim.master_busy, "wall_s": sim.wall_s})
            print(f"model {n:5d} ranks {w:8s} {sim.task_s:9.0f} worker-s efficiency {sim.efficiency:.3f} "
                  f"busy {sim.master_busy:.3f}", flush=True)
    keys = ("ranks", "workload", "tasks", "tasks_per_s", "master_busy", "efficiency", "model_error")
    write_json(a.out + ".json", {
        "measured": [{k: r[k] for k in keys} for r in measured], "modelled": modelled,
        "measured_detail": measured, "costs": vars(costs), "seconds_per_worker": a.seconds,
        "machine": f"{os.cpu_count()} cores, shared", "bench_seconds": time.perf_counter() - t0,
        "command": " ".join(python_command(*sys.argv))})
    plot(measured, modelled, a.out + ".png")


if __name__ == "__main__":
    main()
