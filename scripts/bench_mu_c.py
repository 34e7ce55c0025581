#!/usr/bin/env python3
"""Run time against error for mu^c (issue 4): scenes with analytic mu^c.

For each scene the critical cone (2D) or pattern (3D) — the one of least mu^c —
is found once; then its mu^c is recomputed by every method, repeated, and timed:

- "bisection tol=T": plain bisection on LP (2D, HiGHS) or SOCP (3D, Clarabel)
  feasibility to relative width T (T = 1e-2 ... 1e-12), the upper end returned;
  "tight bisection tol=T": the same with the solvers' feasibility (and Clarabel's
  gap) tolerances tightened from their defaults to 1e-10 (feasibility.SolverOptions);
- "accurate": 2D: bracket to 1e-7 then the verified pencil polish; 3D: scaled
  Dinkelbach iterations then the verified KKT Newton step (the default).

Analytic values: plug2d and plug3d tan(taper); the V-groove bar
tan θ + eps / (k sin 2θ); a single 3D node, 1 / ||K_tt^-1 K_tn|| (the least
||K_tt v|| / (K_nt . v): u = (0, v), r = K u).

Error = |mu^c - analytic| / analytic. Writes results/bench_mu_c.{csv,json,png}
and prints a summary: the worst error of each method and the time of
"accurate" relative to a 1e-6 bisection (issue 4 target: <= 1e-9 error at
<= 3x that time).

    .venv/bin/python scripts/bench_mu_c.py [--quick]
"""
from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np
from harness import write_csv, write_json

from hpcwedge.contact.problem import parametrize
from hpcwedge.mu_c.critical import mu_critical
from hpcwedge.run.pipeline import run_scene
from hpcwedge.scene.parse import parse_scene
from hpcwedge.solvers.feasibility import SolverOptions

OUT = os.path.join(os.path.dirname(__file__), "..", "results")
TOLS = [1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12]


def scenes(quick: bool) -> list[tuple[str, int, dict, float, float]]:
    """(label, dim, model table, listed mu, analytic mu^c)."""
    out = []
    for rows in ((2, 4) if quick else (2, 4, 6, 8)):
        for taper in (3.0, 10.0, 25.0):
            out.append((f"plug2d r{rows} taper {taper:g}", 2,
                        {"kind": "plug2d", "rows": rows, "taper_deg": taper},
                        1.5 * math.tan(math.radians(taper)) + 0.05, math.tan(math.radians(taper))))
    for theta, k, eps in ((20.0, 1.0, 0.0), (20.0, 1.0, 0.1), (35.0, 2.0, 0.3), (10.0, 0.5, 0.01)):
        th = math.radians(theta)
        want = math.tan(th) + eps / (k * math.sin(2 * th))
        model = {"kind": "vgroove_bar", "theta_deg": theta, "EA": 2 * k, "eps": eps}  # bar length 2
        out.append((f"vgroove theta {theta:g} k {k:g} eps {eps:g}", 2, model, 1.5 * want, want))
    for ring in ((4,) if quick else (4, 5)):
        for taper in (5.0, 10.0, 20.0):
            want = math.tan(math.radians(taper))
            out.append((f"plug3d 2x{ring} taper {taper:g}", 3,
                        {"kind": "plug3d", "ring": ring, "taper_deg": taper}, 1.5 * want + 0.05, want))
    rng = np.random.default_rng(3)
    for k in range(2 if quick else 4):
        G = rng.standard_normal((3, 3))
        K = G @ G.T + 0.5 * np.eye(3)
        want = 1.0 / np.linalg.norm(np.linalg.solve(K[1:, 1:], K[1:, 0]))
        out.append((f"node3d random K #{k}", 3, {"kind": "stiffness", "K": K.tolist()}, 1.5 * want, want))
    return out


def critical_pattern(dim: int, model: dict, mu: float):
    """(parametrisation, m, zero_u, zero_r) of the cone / pattern of least mu^c."""
    scene = parse_scene({"name": "bench", "dim": dim, "model": model, "friction": {"mu": [mu]},
                         "compute": {"enumerate": True, "mu_c": "cones"}})
    res = run_scene(scene)
    m = res.m
    if dim == 2:
        cone = min(res.runs[0].cones, key=lambda c: c.mu_c)
        zu, zr = np.isin(np.arange(m), cone.zero_u), np.isin(np.arange(m), cone.zero_r)
    else:
        pat = min(res.runs[0].patterns, key=lambda p: p.mu_c)
        zu = np.isin(np.arange(m), pat.contact)
        zr = ~zu
    return parametrize(res.problem), m, zu, zr


def timed(fn, repeat: int) -> tuple[float, object]:
    best, out = math.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default=OUT, help="output folder (default results/)")
    args = ap.parse_args()
    repeat = 3 if args.quick else 7
    methods = [(f"bisection tol={t:.0e}", "bisection", t, "default") for t in TOLS] + \
        [(f"tight bisection tol={t:.0e}", "bisection", t, "tight") for t in TOLS[::2]] + \
        [("accurate", "accurate", 1e-6, "default")]
    rows = []
    for label, dim, model, mu, want in scenes(args.quick):
        param, m, zu, zr = critical_pattern(dim, model, mu)
        for name, method, tol, tolerances in methods:
            options = SolverOptions(tolerances)
            sec, r = timed(lambda: mu_critical(param, m, zu, zr, mu_hi=mu, method=method, tol=tol,
                                               options=options), repeat)
            err = abs(r.mu_c - want) / want
            rows.append({"scene": label, "dim": dim, "m": m, "method": name, "tol": tol, "seconds": sec,
                         "lps": r.solves, "mu_c": r.mu_c, "analytic": want, "rel_error": err,
                         "polished": r.polished})
    write_csv(os.path.join(args.out, "bench_mu_c.csv"), rows, list(rows[0]))
    summary = {f"{d}d": summarise([r for r in rows if r["dim"] == d]) for d in (2, 3)}
    write_json(os.path.join(args.out, "bench_mu_c.json"), {"summary": summary, "rows": rows})
    plot(summary, args.out)
    for key, sm in summary.items():
        print(f"{key}: {'method':<22}{'worst rel. error':>18}{'mean time [ms]':>16}{'mean solves':>12}")
        for name, s in sm["methods"].items():
            print(f"    {name:<22}{s['worst_error']:>18.2e}{1e3 * s['mean_seconds']:>16.2f}{s['mean_lps']:>12.1f}")
        print(f"    accurate / bisection(1e-6) time: {sm['accurate_over_bisection_1e-6']:.2f}x "
              f"(worst over scenes {sm['worst_ratio']:.2f}x); accurate worst error "
              f"{sm['methods']['accurate']['worst_error']:.1e}")


def summarise(rows: list[dict]) -> dict:
    by = {}
    for r in rows:
        by.setdefault(r["method"], []).append(r)
    methods = {k: {"worst_error": max(r["rel_error"] for r in v),
                   "mean_seconds": float(np.mean([r["seconds"] for r in v])),
                   "mean_lps": float(np.mean([r["lps"] for r in v]))} for k, v in by.items()}
    ref = {r["scene"]: r["seconds"] for r in by["bisection tol=1e-06"]}
    ratios = [r["seconds"] / ref[r["scene"]] for r in by["accurate"]]
    return {"methods": methods,
            "accurate_over_bisection_1e-6": methods["accurate"]["mean_seconds"]
            / methods["bisection tol=1e-06"]["mean_seconds"],
            "worst_ratio": max(ratios)}


def plot(summary: dict, out: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 6))
    for (key, sm), color in zip(summary.items(), ("C0", "C1")):
        solver = "LP" if key == "2d" else "SOCP"
        for prefix, style, what in (("bisection", "o-", "default"), ("tight bisection", "s--", "tight")):
            bis = [(v["mean_seconds"], max(v["worst_error"], 1e-17)) for k, v in sm["methods"].items()
                   if k.startswith(prefix + " tol")]
            ax.loglog([1e3 * t for t, _ in bis], [e for _, e in bis], style, color=color, mfc="none",
                      label=f"{key.upper()}: {solver} bisection 1e-2 … 1e-12, {what} solver tol.")
        acc = sm["methods"]["accurate"]
        ax.loglog([1e3 * acc["mean_seconds"]], [max(acc["worst_error"], 1e-17)], "*", color=color, ms=15,
                  mec="k", label=f"{key.upper()}: " + ("bracket + pencil polish" if key == "2d"
                                                       else "Dinkelbach + KKT Newton"))
    ax.axhline(1e-9, color="grey", ls=":", lw=1)
    ax.set_xlabel("mean time per mu^c [ms]")
    ax.set_ylabel("worst relative error vs analytic")
    ax.set_title("mu^c: run time against error (analytic scenes)")
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "bench_mu_c.png"), dpi=120)


if __name__ == "__main__":
    main()
