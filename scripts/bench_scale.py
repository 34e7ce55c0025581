#!/usr/bin/env python3
"""The engine itself at many ranks, measured and modelled (issue 42).

Measured: synthetic jobs (scripts/scale_workload.py: TaskJob / TreeJob tasks that sleep for
durations recorded from real runs, results/task_durations.json by
scripts/record_durations.py) run by the real engine under `mpirun --oversubscribe` at 3, 9,
17, 33, 65 (and 129) ranks on this machine: sleeping workers leave the cores to the master,
so what is measured is the master's throughput and the workers' idle time. One launch per
rank count runs the three workloads in turn, each sized to about SECONDS_PER_WORKER[workload]
x workers worker-seconds (more for the workloads whose longest tasks take seconds). Per run: tasks, tasks per second, the master's busy fraction (its
wall time outside mpi.wait_any's waits), efficiency = the sum of the task seconds / (workers
x wall), wall from the first task sent to the last result merged (start-up excluded); the
master is busy when it is not asleep (its waits sleep between bursts of probes).

Modelled: parallel.model.simulate on the same jobs with costs fitted to the measured runs:
the master's busy seconds = a_workload x messages + p x probes (non-negative least squares
over every measured run; the probes are the model's count of the master's wake-ups while it
waits: with tasks of a second most of its busy time at 65 ranks), a message's cost half to
send and half to merge; then each workload's latency (send to start) from LATENCY_GRID, the
one whose worst |model_error| over its runs is least (one number per workload, fitted, not
predicted), then one idle-probe delay for all workloads from IDLE_PROBE_GRID (MasterCosts.
idle_probe_s: where 129 ranks share 2 cores, a send waits longer the more workers idle and
probe, as in a tree's ramp-up and tail), then the latencies again; "model_error" = modelled
minus measured efficiency of each measured run. --refit JSON redoes the fit and the model
from a previous run's "measured_detail" without mpirun.
Predictions use the same fit to the master's CPU seconds: on 2 cores the master's probes and
sends wait for a core (Open MPI yields it when oversubscribed: a probe took 1.9 ms of wall
and ~0.1 ms of CPU at 33 ranks, cProfile), which a rank with a core of its own does not;
then 256, 1,024 and 4,096 ranks with MODEL_SECONDS_PER_WORKER[ranks] x workers worker-seconds
("sized": "job": a job of two minutes at 256 and 1,024 ranks, 30 s at 4,096, where the model
runs the tree's nodes for minutes; --quick a quarter of it), and 1,024 ranks with the issue's
floor of MIN_WORKER_SECONDS ("sized": "floor": 2 s per worker). The predictions set the
idle-probe delay to 0 and an idle worker's sleep cap to mpi.POLL_MAX_OWN_CORE (a rank with a
core of its own: mpi.worker_poll_max). "floor": per workload at 1,024 ranks,
the smallest of FLOOR_SEARCH's job sizes modelled at >= 0.9, the longest task and a worker's
share of the floor, what a free one-level schedule could reach on the floor's job
(free_schedule), and why the floor is missed where it is.

Writes results/bench_scale.json ("measured", "modelled", the costs, the load) and
results/bench_scale.png (efficiency against ranks).

    PYTHONPATH=. .venv/bin/python scripts/bench_scale.py [--quick] [--ranks 3 9 ...] [--seconds S]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import traceback
from concurrent.futures import ProcessPoolExecutor

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from harness import RESULTS, mpirun_command, python_command, write_json  # noqa: E402
import scale_workload  # noqa: E402
from scale_workload import GRAIN, load_durations, make_job, task_seconds  # noqa: E402

from hpcwedge.parallel import mpi  # noqa: E402
from hpcwedge.parallel.mpi import POLL_MAX  # noqa: E402

WORKLOADS = ("subtree", "mu_c", "face")
RANKS, QUICK_RANKS, MODEL_RANKS = (3, 9, 17, 33, 65, 129), (3, 9, 17, 33, 65), (256, 1024, 4096)
#: rank counts measured again with the tree through four hubs (workers per hub), to validate
#: the hub model (parallel.model.simulate_hubs) where the engine would not use hubs by itself
HUB_RUNS, QUICK_HUB_RUNS = {33: 7, 65: 15, 129: 31}, {65: 15}
#: measured runs: worker-seconds per worker; modelled runs: the same, at least MIN_WORKER_SECONDS
SECONDS_PER_WORKER = {"subtree": 24.0, "mu_c": 8.0, "face": 24.0}
MODEL_SECONDS_PER_WORKER = {256: 120.0, 1024: 120.0, 4096: 30.0}
#: the issue's floor: a workload of this many worker-seconds should keep 1,024 ranks busy
MIN_WORKER_SECONDS = 2000.0
#: the job sizes (worker-seconds) tried at 1,024 ranks for the smallest one modelled at >= 0.9
FLOOR_SEARCH = tuple(MIN_WORKER_SECONDS * 2 ** k for k in range(6))
#: --quick models jobs of MODEL_SECONDS_PER_WORKER / QUICK_MODEL_DIVISOR (the tree's nodes take minutes)
QUICK_MODEL_DIVISOR = 4
#: the latencies (seconds from a task's send to its start) tried in the fit
LATENCY_GRID = tuple(k * 2.5e-4 for k in range(25))
#: the idle-probe delays tried in the fit (seconds per idle worker per worker, MasterCosts.idle_probe_s)
IDLE_PROBE_GRID = tuple(k * 1e-5 for k in range(7))


def rank_run(durations_path: str, out: str, specs) -> None:
    """Under mpirun: rank 0 runs each workload's job as the engine's master, the others serve
    (hubs where $HPCWEDGE_HUB_WORKERS asks for them: parallel/hub.py)."""
    from hpcwedge.parallel import mpi
    from hpcwedge.parallel.engine import Engine
    from hpcwedge.parallel.hub import layout
    from hpcwedge.parallel.worker import serve
    comm = mpi.world()
    if comm.rank != 0:
        comm.Barrier()
        serve(comm)
        return
    durations = load_durations(durations_path)
    engine = Engine(comm)
    waited = [0.0]
    real_sleep = time.sleep

    def timed_sleep(seconds):           # the master's idle time: its sleeps while it waits
        t0 = time.perf_counter()
        real_sleep(seconds)
        waited[0] += time.perf_counter() - t0
    time.sleep = timed_sleep            # rank 0 runs no task: every sleep of it is a wait
    sent = [0]
    real_send = engine.master.send_task

    def counted_send(*args, **kwargs):  # messages (tasks or batches of tasks) sent
        sent[0] += 1
        real_send(*args, **kwargs)
    engine.master.send_task = counted_send
    comm.Barrier()                      # every rank is up: start-up ends here
    try:
        rows = _run_workloads(engine, comm.size - 1, durations, specs, waited, sent, layout(comm.size))
    except BaseException:
        traceback.print_exc()
        comm.Abort(1)                   # the workers would wait for a task forever
    engine.close()
    with open(out, "w") as f:
        json.dump(rows, f)


def _run_workloads(engine, ranks_1: int, durations: dict, specs, waited: list, sent: list, groups) -> list[dict]:
    """The master's side of rank_run: each workload's job in turn ("workload=seconds per
    worker"), timed; a tree through hubs (`groups`, hub.layout) on the hubs' workers."""
    rows = []
    for seed, spec in enumerate(specs):
        workload, seconds = spec.split("=")
        seconds = float(seconds)
        hubs = len(groups) if groups and workload == "subtree" else 0
        workers = sum(len(ws) for _, ws in groups) if hubs else ranks_1
        job = make_job(workload, durations, seconds * workers, seed, sleep=True)
        waited[0] = sent[0] = 0
        t0, c0 = time.perf_counter(), time.process_time()
        engine.run(job)
        wall = time.perf_counter() - t0
        task_s = (sum(r["seconds"] for r in job.output()) if workload != "subtree"
                  else job.counters["seconds"])
        rows.append({"ranks": ranks_1 + 1, "workers": workers, "hubs": hubs, "workload": workload, "seed": seed,
                     "tasks": job.counters["tasks"], "messages": sent[0],
                     "wall_s": wall, "task_s": task_s, "busy_s": wall - waited[0],
                     "cpu_s": time.process_time() - c0, "worker_seconds_asked": seconds * workers})
    return rows


def measure(ranks: int, durations_path: str, seconds: dict, workloads, hub_workers: int = 0) -> list[dict]:
    """One mpirun launch at `ranks` (hubs of hub_workers workers for the tree; 0: none): its
    rows, with tasks_per_s, master_busy, efficiency (over the workers that run tasks)."""
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1",
               OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               HPCWEDGE_HUB_WORKERS=str(hub_workers))
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "rows.json")
        cmd = mpirun_command(ranks, os.path.abspath(__file__), "--rank-run", durations_path, out,
                             *[f"{w}={seconds[w]}" for w in workloads], env=env)
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
                 efficiency=r["task_s"] / (r["workers"] * r["wall_s"]), launch_s=launch, load_before=load,
                 hub_workers=hub_workers if r["hubs"] else 0)
        print(f"{ranks:4d} ranks {r['workload']:8s} {r['tasks']:6d} tasks {r['tasks_per_s']:8.1f}/s "
              f"busy {r['master_busy']:.3f} efficiency {r['efficiency']:.3f}", flush=True)
    return rows


def model_run(workload: str, durations: dict, ranks: int, worker_seconds: float, seed: int, costs,
              hub_workers: int | None = None):
    """The engine's schedule of the workload at `ranks` in the model: one level, or for a tree
    through hubs where the engine would use them (hub.layout, with hub_workers workers per hub
    when given; the hubs cost what the master does). A model.Simulated (its workers: those
    that run tasks)."""
    from hpcwedge.parallel.hub import layout
    from hpcwedge.parallel.model import Simulated, simulate, simulate_hubs
    job = make_job(workload, durations, worker_seconds, seed, sleep=False)
    groups = layout(ranks, "" if hub_workers is None else str(hub_workers)) if workload == "subtree" else None
    if not groups:
        return simulate(job, ranks - 1, costs, task_seconds)
    r = simulate_hubs(job, [len(ws) for _, ws in groups], costs, task_seconds)
    return Simulated(r["workers"], r["wall_s"], r["task_s"], r["tasks"], r["master_busy"] * r["wall_s"],
                     r["messages"], 0, r["longest_s"])


def free_schedule(workload: str, durations: dict, seed: int, ranks: int = 1024,
                  worker_seconds: float = MIN_WORKER_SECONDS) -> float:
    """The efficiency a one-level schedule could reach at most on a job (the floor's): the model
    with every master cost, latency and wake-up 0 and the finest tasks the workload has (a
    tree: one synthetic node a task); the ramp-up and tail of the job itself."""
    from hpcwedge.parallel.model import FREE, simulate
    job = make_job(workload, durations, worker_seconds, seed, sleep=False, budget=GRAIN)
    job.max_scale = 1
    return simulate(job, ranks - 1, FREE, task_seconds).efficiency


def at_grain(grain: int, workload: str, durations: dict, ranks: int, worker_seconds: float, seed: int, costs):
    """model_run with the tree's synthetic nodes standing for `grain` real nodes (1: the real
    nodes of the recorded durations, scale_workload.GRAIN) instead of GRAIN."""
    old, scale_workload.GRAIN = scale_workload.GRAIN, grain
    try:
        return model_run(workload, durations, ranks, worker_seconds, seed, costs)
    finally:
        scale_workload.GRAIN = old


def floor_search(workload: str, durations: dict, seed: int, costs, ranks: int = 1024) -> dict:
    """At `ranks`: the smallest of FLOOR_SEARCH's job sizes modelled at efficiency >= 0.9 (None:
    none of them), each size's efficiency, the workload's longest task (the largest of the
    recorded durations drawn, or the tree's longest task under the engine's budgets, at the
    floor's size) and a worker's share of the
    floor; the floor is met when the floor's own size reaches 0.9. The engine's schedule: a
    tree through hubs where it uses them. real_grain_efficiency: a tree's floor with one real
    node a synthetic node (at_grain 1)."""
    tried, smallest, longest, workers = [], None, 0.0, 0
    for ws in FLOOR_SEARCH:
        sim = model_run(workload, durations, ranks, ws, seed, costs)
        workers = workers or sim.workers
        tried.append({"worker_seconds": sim.task_s, "efficiency": sim.efficiency, "master_busy": sim.master_busy})
        longest = longest or sim.longest_s     # at the floor's size
        if sim.efficiency >= 0.9:
            smallest = sim.task_s
            break
    share = MIN_WORKER_SECONDS / workers
    met = tried[0]["efficiency"] >= 0.9
    busy = tried[0]["master_busy"]
    free = free_schedule(workload, durations, seed, ranks)
    cap = ("" if met or free >= 0.9 else
           f"no one-level schedule reaches 0.9 on this job ({free:.3f} with a free master and one node "
           "a task: its ramp-up and tail); ")
    real = (at_grain(1, workload, durations, ranks, MIN_WORKER_SECONDS, seed, costs).efficiency
            if workload == "subtree" else None)
    cap += ("" if met or real is None else
            f"the same tree at its real grain (a synthetic node one real node, not {GRAIN}) reaches "
            f"{real:.3f} on the engine's schedule; ")
    why = ("met" if met else cap + (
           f"the master is busy {busy:.0%} of the time: tasks short enough for the tail are more than "
           "one master serves" if busy >= 0.9 else
           f"its longest task ({longest:.2f} s) is {longest / share:.0%} of a worker's share of the floor "
           f"({share:.2f} s): the schedule's tail alone leaves workers idle" if longest > 0.25 * share else
           "the ramp-up and tail of the schedule, not the task lengths"))
    return {"workload": workload, "ranks": ranks, "floor_worker_seconds": MIN_WORKER_SECONDS,
            "meets_floor": met, "real_grain_efficiency": real, "free_schedule_efficiency": free, "smallest_worker_seconds_at_0.9": smallest, "tried": tried,
            "longest_task_s": longest, "share_at_floor_s": share, "why": why}


def master_costs(measured: list[dict], durations: dict, mapper=map) -> tuple[dict, dict]:
    """({workload: MasterCosts} fitted to the measured runs' busy wall seconds (the model's
    validation), the same with the master's CPU seconds (its predictions); see the module's
    docstring). mapper: map, or an executor's, over the grids' model runs (the same fit)."""
    from scipy.optimize import nnls

    from hpcwedge.parallel.model import MasterCosts
    measured = [r for r in measured if not r.get("hubs")]     # runs through hubs validate, not fit
    workloads = sorted({r["workload"] for r in measured})
    rows = []                           # messages by workload, and the model's probes, per run
    for r in measured:
        sim = model_run(r["workload"], durations, r["ranks"], r["worker_seconds_asked"], r["seed"],
                        MasterCosts(0.0, 0.0))
        rows.append([r["messages"] * (w == r["workload"]) for w in workloads] + [sim.probes])
    wall, _ = nnls(np.array(rows, dtype=float), np.array([r["busy_s"] for r in measured]))
    cpu, _ = nnls(np.array(rows, dtype=float), np.array([r["cpu_s"] for r in measured]))

    def worst(pairs):                   # [(workload, MasterCosts)] -> the worst |model_error| of each
        return list(mapper(_worst, [runs[w] for w, _ in pairs], [durations] * len(pairs), [c for _, c in pairs]))

    def fit_latencies(idle_probe):      # per workload, the latency whose worst |model_error| is least
        grid = [(w, _costs(wall, i, lat, idle_probe)) for i, w in enumerate(workloads) for lat in LATENCY_GRID]
        errs = worst(grid)
        n = len(LATENCY_GRID)
        return {w: LATENCY_GRID[int(np.argmin(errs[i * n:(i + 1) * n]))] for i, w in enumerate(workloads)}
    runs = {w: [r for r in measured if r["workload"] == w] for w in workloads}
    latency = fit_latencies(0.0)
    errs = worst([(w, _costs(wall, i, latency[w], k)) for k in IDLE_PROBE_GRID for i, w in enumerate(workloads)])
    n = len(workloads)
    idle_probe = IDLE_PROBE_GRID[int(np.argmin([max(errs[j * n:(j + 1) * n]) for j in range(len(IDLE_PROBE_GRID))]))]
    latency = fit_latencies(idle_probe)
    validated = {w: _costs(wall, i, latency[w], idle_probe) for i, w in enumerate(workloads)}
    predicting = {w: _costs(cpu, i, latency[w], 0.0, mpi.POLL_MAX_OWN_CORE) for i, w in enumerate(workloads)}
    return validated, predicting


def _costs(fitted, i: int, latency: float, idle_probe: float, worker_poll_max: float = POLL_MAX):
    """Workload i's MasterCosts from an nnls fit [per-message costs..., probe]: half to send, half to merge."""
    from hpcwedge.parallel.model import MasterCosts
    return MasterCosts(float(fitted[i]) / 2, float(fitted[i]) / 2, latency, probe_s=float(fitted[-1]),
                       idle_probe_s=idle_probe, worker_poll_max_s=worker_poll_max)


def _worst(runs: list[dict], durations: dict, costs) -> float:
    """The largest |modelled - measured efficiency| over `runs` with `costs`."""
    return max(abs(model_run(r["workload"], durations, r["ranks"], r["worker_seconds_asked"], r["seed"], costs).efficiency
                   - r["efficiency"]) for r in runs)


def plot(measured: list[dict], modelled: list[dict], path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for i, w in enumerate(WORKLOADS):
        meas = [r for r in measured if r["workload"] == w]
        mod = sorted([(r["ranks"], r["efficiency"] + r["model_error"]) for r in meas]
                     + [(r["ranks"], r["efficiency"]) for r in modelled if r["workload"] == w and r["sized"] == "job"])
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
    ax.legend(fontsize=8, loc="lower left")
    ax.text(0.99, 0.02, "model to 129 ranks: this machine's costs, the measured jobs;\n"
            "from 256: the master's CPU costs, jobs of 2 min (30 s at 4,096)", transform=ax.transAxes,
            ha="right", va="bottom", fontsize=7)
    ax.set_title("hpcwedge engine: measured (2 cores, oversubscribed) and modelled")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="stop at 65 ranks")
    ap.add_argument("--ranks", type=int, nargs="+")
    ap.add_argument("--seconds", type=float, help="worker-seconds per worker, every workload "
                    f"(default {SECONDS_PER_WORKER})")
    ap.add_argument("--durations", default=os.path.join(RESULTS, "task_durations.json"))
    ap.add_argument("--workloads", nargs="+", default=list(WORKLOADS), choices=WORKLOADS)
    ap.add_argument("--out", default=os.path.join(RESULTS, "bench_scale"))
    ap.add_argument("--refit", metavar="JSON", help="no mpirun: refit and remodel a previous run's "
                    "measured_detail")
    ap.add_argument("--rank-run", nargs="+", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.rank_run:
        path, out, *specs = a.rank_run
        return rank_run(path, out, specs)
    ranks = a.ranks or (QUICK_RANKS if a.quick else RANKS)
    durations = load_durations(a.durations)
    t0 = time.perf_counter()
    seconds = {w: a.seconds or SECONDS_PER_WORKER[w] for w in WORKLOADS}
    if a.refit:
        with open(a.refit) as f:
            measured = [r for r in json.load(f)["measured_detail"] if r["workload"] in a.workloads]
    else:
        hub_runs = QUICK_HUB_RUNS if a.quick else HUB_RUNS
        measured = [r for n in ranks for r in measure(n, a.durations, seconds, a.workloads)
                    + (measure(n, a.durations, seconds, ["subtree"], hub_runs[n])
                       if n in hub_runs and "subtree" in a.workloads else [])]
    with ProcessPoolExecutor(2) as pool:        # the fit's grids: ~900 model runs
        costs, predicting = master_costs(measured, durations, pool.map)
    for r in measured:
        sim = model_run(r["workload"], durations, r["ranks"], r["worker_seconds_asked"], r["seed"],
                        costs[r["workload"]], r.get("hub_workers", 0))
        r["model_error"] = sim.efficiency - r["efficiency"]
    per_worker = {n: v / (QUICK_MODEL_DIVISOR if a.quick else 1) for n, v in MODEL_SECONDS_PER_WORKER.items()}
    specs = [(w, n, ws, seed, sized) for n in MODEL_RANKS for seed, w in enumerate(a.workloads)
             for ws, sized in [(per_worker[n] * (n - 1), "job")]
             + ([(MIN_WORKER_SECONDS, "floor")] if n == 1024 else [])]
    with ProcessPoolExecutor(2) as pool:        # the tree's nodes: minutes of model at 1,024 ranks
        sims = list(pool.map(model_run, *zip(*[(w, durations, n, ws, seed, predicting[w]) for w, n, ws, seed, _ in specs])))
        floors = list(pool.map(floor_search, a.workloads, [durations] * len(a.workloads),
                               range(len(a.workloads)), [predicting[w] for w in a.workloads]))
    modelled = []
    for (w, n, _, _, sized), sim in zip(specs, sims):
        modelled.append({"workload": w, "ranks": n, "worker_seconds": sim.task_s, "efficiency": sim.efficiency,
                         "sized": sized, "workers": sim.workers, "hubs": n - 1 - sim.workers,
                         "seconds_per_worker": sim.task_s / sim.workers, "tasks": sim.tasks,
                         "messages": sim.messages, "master_busy": sim.master_busy, "wall_s": sim.wall_s})
        print(f"model {n:5d} ranks {w:8s} {sim.task_s:9.0f} worker-s efficiency {sim.efficiency:.3f} "
              f"busy {sim.master_busy:.3f}", flush=True)
    for f in floors:
        print(f"floor {f['workload']:8s} at 1,024 ranks: {f['tried'][0]['efficiency']:.3f}; 0.9 from "
              f"{f['smallest_worker_seconds_at_0.9']} worker-s; longest task {f['longest_task_s']:.2f} s", flush=True)
    keys = ("ranks", "workload", "tasks", "tasks_per_s", "master_busy", "efficiency", "model_error")
    write_json(a.out + ".json", {
        "measured": [{**{k: r[k] for k in keys}, "hubs": r.get("hubs", 0)} for r in measured], "modelled": modelled,
        "floor": floors, "measured_detail": measured, "costs": {w: vars(c) for w, c in costs.items()},
        "costs_predicting": {w: vars(c) for w, c in predicting.items()}, "seconds_per_worker": seconds,
        "model_seconds_per_worker": per_worker,
        "machine": f"{os.cpu_count()} cores, shared", "bench_seconds": time.perf_counter() - t0,
        "command": " ".join(python_command(*sys.argv))})
    plot(measured, modelled, a.out + ".png")


if __name__ == "__main__":
    main()
