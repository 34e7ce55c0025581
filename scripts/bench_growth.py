#!/usr/bin/env python3
"""Growth of cost with size (issue 4, deliverable 5): time and peak memory against m.

    PYTHONPATH=. python scripts/bench_growth.py [--quick] [--out results/bench_growth]

2D: plug2d (cols 3, taper 10 deg, free body), mu = 0.65, rows 2..9 (m = 4..18):
  ours        run_scene (enumerate + mu_c "global"); stages from result.timings
              (condense, enumerate, mu_c)
  ours_split  the enumerate stage alone, run_scene with mu_c "none" (bench_2d.worker_ours:
              time = the run's timings.enumerate)
  cdd_exact   the peer: cddlib exact full DD + complementarity filter + cliques
              (bench_2d.worker_peer), m <= 8, 120 s per point
3D: plug3d levels 2, ring 4..8 (m = 8..16), mu = 1.0, PatternTree branch and bound
  bnb_sym     with plug3d's node symmetry (as `hpcwedge run`), patterns expanded
  bnb         without a symmetry
  brute       the peer: one SOCP per partition (reference.brute_force_patterns), m <= 12
  3D: bnb_sym and bnb are the product's own runs (run_scene, mu_c "none", run.symmetry on /
  off); their stages and counters are the run's own (timings condense / enumerate, stats
  bnb: nodes, SOCPs, skipped, pruned, undecided); time = the enumerate stage.

Every point runs in a fresh subprocess (this script with --point), which reports its
peak RSS (getrusage ru_maxrss); memory growth is that peak above the same engine's
peak at its smallest m (interpreter + imported libraries + a trivial instance).
An engine's sizes stop growing after a timeout. Fit: least squares of ln(time) on m
over the points with time > 0.05 s, time ~ b^m (b per added node; ln 2 / ln b nodes
per doubling of cost); the same for memory growth (points > 5 MB).

--quick: m <= 12 in 2D (peer m <= 6), ring 4..6 in 3D (brute m <= 10); under 2 min.
Writes <out>.csv, <out>.json, <out>_2d.png, <out>_3d.png; prints a summary table.
"""
from __future__ import annotations

import argparse
import csv
import hashlib
import json
import math
import os
import resource
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_2d  # noqa: E402  (workers, subprocess runner conventions)

MARK = bench_2d.MARK
MU_2D, MU_3D, LEVELS = 0.65, 1.0, 2
MIN_FIT_SECONDS, MIN_FIT_MB = 0.05, 5.0
LABELS = {"ours": "ours (run_scene)", "ours_split": "ours (enumerate only)", "cdd_exact": "peer: cddlib exact DD",
          "bnb_sym": "ours (B&B, symmetry)", "bnb": "ours (B&B, no symmetry)",
          "brute": "peer: brute force (SOCP per partition)"}


# --------------------------------------------------------------------------- workers (in the subprocess)

def worker_3d(engine: str, ring: int) -> dict:
    """One 3D point, plug3d (levels LEVELS, ring) at MU_3D. bnb_sym / bnb: the product's own
    run (pipeline.run_scene, enumerate = true, mu_c = "none", run.symmetry on / off), its
    stages and counters its own (timings condense / enumerate, stats bnb); brute: one SOCP
    per partition (reference.brute_force_patterns), "condense" = model + parametrize."""
    if engine == "brute":
        from bench_socp_count import parametrized

        from hpcwedge.reference import brute_force_patterns
        t0 = time.perf_counter()
        p, m = parametrized(LEVELS, ring)
        t1 = time.perf_counter()
        found = brute_force_patterns(p, m, MU_3D)
        stages = {"condense": t1 - t0, "enumerate": time.perf_counter() - t1}
        counters = {"solves": 2 ** m}
    else:
        from hpcwedge.run.pipeline import run_scene
        from hpcwedge.scene.parse import parse_scene
        scene = parse_scene({"name": "growth", "dim": 3, "friction": {"mu": [MU_3D]},
                             "model": {"kind": "plug3d", "levels": LEVELS, "ring": ring, "taper_deg": 10.0},
                             "compute": {"enumerate": True, "mu_c": "none"},
                             "run": {"symmetry": engine == "bnb_sym"}})
        res = run_scene(scene)
        m = res.m
        found = [sum(1 << i for i in pat.contact) for pat in res.runs[0].patterns]
        stages = {k: res.timings[k] for k in ("condense", "enumerate")}
        counters = {k: res.stats["bnb"][k] for k in ("nodes", "solves", "skipped", "pruned", "undecided")}
    digest = hashlib.sha1(repr(sorted(found)).encode()).hexdigest()[:16]     # the pattern set
    return {"m": m, "seconds": stages["enumerate"], "patterns": len(found), "patterns_digest": digest,
            "socps": counters["solves"], "counters": counters, "stages": stages}


def worker_2d(engine: str, rows: int) -> dict:
    if engine in ("ours", "ours_split"):         # the run's own stage timings
        r = bench_2d.worker_scene(rows, MU_2D) if engine == "ours" else bench_2d.worker_ours(rows, MU_2D, False)
        stages = {k: v for k, v in r["breakdown"].items() if k != "total"}
    else:
        r = bench_2d.worker_peer(rows, MU_2D)
        stages = r["breakdown"]
    return {"m": 2 * rows, "seconds": r["seconds"], "rays": r["n_wedged_rays"], "cones": r["n_cones"],
            "stages": stages}


def point_main(dim: int, engine: str, size: int) -> None:
    if dim == 2:
        out = worker_2d(engine, size)
    else:
        out = worker_3d(engine, size)
    out["maxrss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0   # Linux: KiB
    print(MARK + json.dumps(out), flush=True)


# --------------------------------------------------------------------------- driver

def run_point(dim: int, engine: str, size: int, limit: float) -> dict:
    """One point in a fresh subprocess: its record with status ok / timeout / error."""
    argv = ["--point", str(dim), engine, str(size)]
    return bench_2d.run_record(os.path.abspath(__file__), argv, limit, dim=dim, engine=engine, size=size)


def plan(quick: bool) -> list[tuple[int, str, list[int], float]]:
    """(dim, engine, sizes, time limit per point): rows in 2D, ring in 3D."""
    rows = range(2, 7) if quick else range(2, 10)
    ring = range(4, 7) if quick else range(4, 9)
    return [(2, "ours", list(rows), 300.0), (2, "ours_split", list(rows), 300.0),
            (2, "cdd_exact", [r for r in rows if 2 * r <= (6 if quick else 8)], 120.0),
            (3, "bnb_sym", list(ring), 300.0), (3, "bnb", list(ring), 300.0),
            (3, "brute", [r for r in ring if 2 * r <= (10 if quick else 12)], 120.0)]


def measure(quick: bool) -> list[dict]:
    records = []
    for dim, engine, sizes, limit in plan(quick):
        base = None
        for size in sizes:
            rec = run_point(dim, engine, size, limit)
            rec.setdefault("m", 2 * size)
            if rec.get("maxrss_mb") is not None:
                base = rec["maxrss_mb"] if base is None else base
                rec["rss_above_first_mb"] = rec["maxrss_mb"] - base
            records.append(rec)
            print_row(rec)
            if rec["status"] != "ok":
                break
    return records


def fit(ms, ys, floor: float) -> dict | None:
    """Least squares ln y = a + m ln b over the points with y > floor."""
    pts = [(m, y) for m, y in zip(ms, ys) if y is not None and y > floor]
    if len(pts) < 2:
        return None
    slope, icpt = np.polyfit([p[0] for p in pts], [math.log(p[1]) for p in pts], 1)
    b = math.exp(slope)
    return {"b": b, "a": math.exp(icpt), "nodes_per_doubling": math.log(2) / slope if slope > 0 else None,
            "m_range": [pts[0][0], pts[-1][0]], "n_points": len(pts)}


def fits(records: list[dict]) -> dict:
    out = {}
    for dim, engine in sorted({(r["dim"], r["engine"]) for r in records}):
        ok = [r for r in records if r["dim"] == dim and r["engine"] == engine and r["status"] == "ok"]
        ms = [r["m"] for r in ok]
        out[f"{dim}d/{engine}"] = {"time": fit(ms, [r["seconds"] for r in ok], MIN_FIT_SECONDS),
                                   "memory": fit(ms, [r["rss_above_first_mb"] for r in ok], MIN_FIT_MB)}
    return out


# --------------------------------------------------------------------------- output

def print_row(r: dict) -> None:
    st = " ".join(f"{k}={v:.3g}" for k, v in r.get("stages", {}).items())
    sec = f"{r['seconds']:.3f}" if r["status"] == "ok" else r["status"]
    rss = f"{r['maxrss_mb']:.0f}" if r.get("maxrss_mb") else "-"
    print(f"{r['dim']}D {r['engine']:>10} m={r['m']:3d} {sec:>9} s  {rss:>5} MB  {st}", flush=True)


def print_summary(f: dict) -> None:
    print(f"\n{'engine':>14} {'time x/node':>11} {'nodes/2x':>8} {'m range':>8} "
          f"{'mem x/node':>10} {'nodes/2x':>8}")
    for key, v in f.items():
        t, mm = v["time"], v["memory"]
        cell = (lambda g: (f"{g['b']:.2f}", f"{g['nodes_per_doubling']:.1f}" if g["nodes_per_doubling"] else "-")
                if g else ("-", "-"))
        tb, td = cell(t)
        mb, md = cell(mm)
        rng = f"{t['m_range'][0]}-{t['m_range'][1]}" if t else "-"
        print(f"{key:>14} {tb:>11} {td:>8} {rng:>8} {mb:>10} {md:>8}")


def write(records, f, out: str) -> None:
    os.makedirs(os.path.dirname(out) or ".", exist_ok=True)
    from hpcwedge.environment import environment
    with open(out + ".json", "w") as fh:
        json.dump({"mu_2d": MU_2D, "mu_3d": MU_3D, "fits": f, "points": records, "environment": environment()},
                  fh, indent=1)
    stages = sorted({k for r in records for k in r.get("stages", {})})
    cols = ["dim", "engine", "m", "size", "status", "seconds", "wall", "maxrss_mb", "rss_above_first_mb"]
    with open(out + ".csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, cols + ["stage_" + s for s in stages], extrasaction="ignore", restval="")
        w.writeheader()
        for r in records:
            w.writerow({**r, **{"stage_" + k: round(v, 6) for k, v in r.get("stages", {}).items()}})


def plot(records, f, dim: int, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax_t, ax_m) = plt.subplots(1, 2, figsize=(11, 4.2))
    engines = [e for e in LABELS if any(r["dim"] == dim and r["engine"] == e for r in records)]
    for i, e in enumerate(engines):
        ok = [r for r in records if r["dim"] == dim and r["engine"] == e and r["status"] == "ok"]
        ms = np.array([r["m"] for r in ok])
        color, style = f"C{i}", "--" if e in ("cdd_exact", "brute") else "-"
        base = ok[0]["maxrss_mb"] if ok else 0.0
        for ax, key, kind, off in ((ax_t, "seconds", "time", 0.0), (ax_m, "maxrss_mb", "memory", base)):
            g = f[f"{dim}d/{e}"][kind]
            label = LABELS[e] + (f" ×{g['b']:.2f} per node" if g else "")
            ax.plot(ms, [r[key] for r in ok], "o", color=color, label=label)
            if g:
                mm = np.linspace(g["m_range"][0], g["m_range"][1], 20)
                ax.plot(mm, off + g["a"] * g["b"] ** mm, style, color=color, alpha=0.7)
    scene = (f"plug2d (cols 3, taper 10°), mu = {MU_2D:g}" if dim == 2
             else f"plug3d (levels {LEVELS}), mu = {MU_3D:g}")
    ax_t.set(yscale="log", xlabel="m (contact nodes)", ylabel="time (s)", title=f"{scene}: time")
    ax_m.set(yscale="log", xlabel="m (contact nodes)", ylabel="peak RSS (MB)",
           title="memory (fit: growth above the smallest m)")
    for ax in (ax_t, ax_m):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default=None, help="prefix (default results/bench_growth, --quick: ..._quick)")
    ap.add_argument("--point", nargs=3, metavar=("DIM", "ENGINE", "SIZE"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.point:
        point_main(int(args.point[0]), args.point[1], int(args.point[2]))
        return 0
    out = args.out or os.path.join(bench_2d.ROOT, "results", "bench_growth_quick" if args.quick else "bench_growth")
    t0 = time.perf_counter()
    records = measure(args.quick)
    f = fits(records)
    write(records, f, out)
    for dim in (2, 3):
        plot(records, f, dim, f"{out}_{dim}d.png")
    print_summary(f)
    print(f"\nwrote {out}.csv, {out}.json, {out}_2d.png, {out}_3d.png ({time.perf_counter() - t0:.0f} s)")
    failed = [r for r in records if r["status"] == "error"]
    for r in failed:
        print(f"error: {r['dim']}D {r['engine']} m = {r['m']}: {r.get('error', '')}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
