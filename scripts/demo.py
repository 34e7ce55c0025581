#!/usr/bin/env python3
"""The demo suite (make demo): the seed-style 2D examples, the 3D plug and the Gmsh bodies.

Writes results/demo/<scene>.toml, <scene>.h5, <scene>.png and table.md, and
prints the tables: wedged rays, cones and mu^c per 2D scene; feasible sign
patterns per mu and the global mu^c of plug3d (m = 10), run under mpirun
with --ranks ranks (default 3: a master and 2 workers, oversubscribed if the machine has fewer cores);
the committed Gmsh example bodies (scripts/examples/, built by scripts/make_examples.py) run in
process into gmsh_<name>.h5, with a plot of one 2D configuration (gmsh_cork2d.png) and the whole
body of one configuration per example as VTU (gmsh_cork2d_cone0.vtu, gmsh_plug3d_pattern0.vtu).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from hpcwedge.progress import Progress  # noqa: E402
from hpcwedge.results.hdf5 import write_result  # noqa: E402
from hpcwedge.run.pipeline import run_scene  # noqa: E402
from hpcwedge.scene.parse import load_scene  # noqa: E402

sys.path.insert(0, os.path.join(ROOT, "scripts"))
import make_examples  # noqa: E402  (the example parameters; gmsh is not needed to import it)

SCENES = {f"plug2d_r{r}": f'''# plug2d, {r} rows x 3 columns, walls 10 degrees from vertical (m = {2 * r}); global mu^c = tan 10 deg
name = "plug2d-r{r}"
dim = 2
[model]
kind = "plug2d"
rows = {r}
cols = 3
taper_deg = 10.0
[friction]
mu = [0.65]
[compute]
enumerate = true
mu_c = "cones"
''' for r in range(2, 7)}
SCENES["block2d_r5"] = '''# plane-stress Q4 plug, 5 x 2 elements, 12 contact nodes
name = "block2d-r5"
dim = 2
[model]
kind = "block2d"
rows = 5
[friction]
mu = [1.5]
[compute]
enumerate = true
mu_c = "cones"
'''
SCENES["vgroove_bar"] = '''# one bar in a V-groove, walls 30 degrees from vertical, free; mu^c = tan 30 deg
name = "vgroove-bar"
dim = 2
[model]
kind = "vgroove_bar"
theta_deg = 30.0
[friction]
mu = [0.65]
[compute]
enumerate = true
mu_c = "cones"
'''

PLUG3D = '''# plug3d: 2 rings of 5 nodes in a conical hole, 10 degrees from the axis (m = 10); global mu^c = tan 10 deg
name = "plug3d"
dim = 3
[model]
kind = "plug3d"
levels = 2
ring = 5
taper_deg = 10.0
[friction]
mu = [0.55, 0.60, 0.65, 0.70, 1.00]
[compute]
enumerate = true
mu_c = "cones"
[run]
checkpoint_every_s = 30
'''


def run_plug3d(out: str, ranks: int) -> str:
    """plug3d under mpirun (the analogue of the seed's 3D table); returns a markdown table."""
    path = os.path.join(out, "plug3d.toml")
    with open(path, "w") as f:
        f.write(PLUG3D)
    h5 = os.path.join(out, "plug3d.h5")
    if os.path.exists(h5):
        os.remove(h5)
    cmd = [sys.executable, "-m", "hpcwedge", "run", path, "-o", h5, "-q"]
    mpirun = shutil.which("mpirun")
    if mpirun and ranks > 1:
        extra = ["--allow-run-as-root"] if os.geteuid() == 0 else []
        if ranks > (os.cpu_count() or 1):
            extra.append("--oversubscribe")
        cmd = [mpirun, *extra, "-n", str(ranks), "-x", "PYTHONPATH"] + cmd
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    t = time.perf_counter()
    subprocess.run(cmd, check=True, env=env)
    wall = time.perf_counter() - t
    js = json.loads(subprocess.run([sys.executable, "-m", "hpcwedge", "show", h5, "--json"], env=env,
                                   check=True, capture_output=True, text=True).stdout)
    head = ("mu", "feasible patterns", "mu^c of the patterns (least … largest)")
    lines = [f"plug3d (m = {js['m']}), {ranks} MPI rank(s), {wall:.1f} s; global mu^c = "
             + ("null" if js["mu_c"] is None else f"{js['mu_c']:.12f}"), "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for run in js["runs"]:
        vals = [p["mu_c"] for p in run["patterns"] or [] if p.get("mu_c") is not None]
        lines.append(f"| {run['mu']:.2f} | {run['n_patterns']} | {min(vals):.9f} … {max(vals):.9f} |" if vals
                     else f"| {run['mu']:.2f} | {run['n_patterns']} | - |")
    return "\n".join(lines)


def run_gmsh_examples(out: str, only=None) -> str:
    """Run the committed Gmsh example scenes (scripts/examples/<name>.toml) into
    out/gmsh_<name>.h5; plot the first wedged ray of cork2d and export cone 0 of cork2d
    and pattern 0 (at the last mu) of plug3d as VTU. Returns a markdown table."""
    from hpcwedge.post.export import write_vtu
    from hpcwedge.post.plot import plot_result
    from hpcwedge.post.recovery import load_configuration
    taper = {"cork2d": make_examples.TAPER_2D_DEG, "plug3d": make_examples.TAPER_3D_DEG}
    head = ("scene", "dim", "m", "mu", "wedged rays", "cones", "patterns", "global mu^c", "tan(taper)", "seconds")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, (dim, _) in make_examples.BUILDERS.items():
        key = "gmsh_" + name
        if only and key not in only:
            continue
        t = time.perf_counter()
        res = run_scene(load_scene(os.path.join(make_examples.EXAMPLES, name + ".toml")), Progress(every=30))
        wall = time.perf_counter() - t
        h5 = os.path.join(out, key + ".h5")
        write_result(h5, res)
        if dim == 2:
            plot_result(h5, os.path.join(out, key + ".png"))
            item, vtu = {"cone": 0}, key + "_cone0.vtu"
        else:
            item, vtu = {"pattern": 0}, key + "_pattern0.vtu"
        write_vtu(load_configuration(h5, run=-1, **item), os.path.join(out, vtu))
        mu_c = "null" if res.mu_c is None else f"{res.mu_c:.12f}"
        for run in res.runs:
            lines.append("| " + " | ".join(str("-" if v is None else v) for v in (
                res.scene.name, dim, res.m, run.mu, run.n_wedged_rays, run.n_cones, run.n_patterns, mu_c,
                f"{math.tan(math.radians(taper[name])):.12f}", f"{wall:.2f}")) + " |")
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", default=os.path.join(ROOT, "results", "demo"))
    ap.add_argument("--only", nargs="*", help="scene names to run (default: all; plug3d, gmsh_cork2d, gmsh_plug3d are some)")
    ap.add_argument("--ranks", type=int, default=3, help="MPI ranks for plug3d (1: no mpirun)")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    rows = []
    for key, text in SCENES.items():
        if args.only and key not in args.only:
            continue
        path = os.path.join(args.out, key + ".toml")
        with open(path, "w") as f:
            f.write(text)
        scene = load_scene(path)
        t = time.perf_counter()
        res = run_scene(scene, Progress(every=30))
        h5 = os.path.join(args.out, key + ".h5")
        write_result(h5, res)
        try:
            from hpcwedge.post.plot import plot_result
            plot_result(h5, os.path.join(args.out, key + ".png"))
        except ImportError:
            pass
        for run in res.runs:
            cmu = sorted(c.mu_c for c in run.cones if c.mu_c is not None)
            cones_mu = ", ".join(f"{v:.6f}" for v in cmu[:4]) + (" ..." if len(cmu) > 4 else "")
            rows.append((scene.name, res.m, run.mu, run.n_wedged_rays, run.n_trivial_rays,
                         run.n_cones, cones_mu or "-",
                         "null" if res.mu_c is None else f"{res.mu_c:.12f}",
                         f"{time.perf_counter() - t:.2f}"))
    head = ("scene", "m", "mu", "wedged rays", "trivial rays", "cones", "mu^c of cones", "global mu^c", "seconds")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    table = "\n".join(lines)
    table3 = run_plug3d(args.out, args.ranks) if not args.only or "plug3d" in args.only else ""
    table_g = run_gmsh_examples(args.out, args.only)
    with open(os.path.join(args.out, "table.md"), "w") as f:
        f.write("# hpcwedge demo: seed-style 2D examples\n\n" + table + "\n\n## 3D\n\n" + table3
                + "\n\n## Gmsh example bodies (scripts/make_examples.py)\n\n" + table_g + "\n")
    print(table)
    print()
    print(table3)
    print()
    print(table_g)
    return 0


if __name__ == "__main__":
    sys.exit(main())
