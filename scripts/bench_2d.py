#!/usr/bin/env python3
"""Benchmark of the 2D pipeline (issue "2D pipeline", SPEC §7).

    scripts/bench_2d.py [--quick] [--budget SECONDS] [--profile-m M]

Scene: plug2d (cols 3, taper 10 deg, free body), rows 2..10 (m = 2*rows = 4..20), mu = 0.65.
Engines, run in the same invocation on the same condensed stiffness:

  ours_enumerate  our float engine, the enumerate stage only, as `hpcwedge run` runs it:
                  run_scene() with mu_c = "none", seconds = the run's own timings.enumerate
                  (DD in balanced coordinates, whole or over faces, the run-time judgement
                  and its exact fallback, the cones)
  ours_run_scene  the whole pipeline, run_scene() with mu_c = "global" (model, PETSc
                  condensation, enumeration, cones, every cone's mu^c, global mu^c)
  ours_mpirun     the whole run through the command line on both cores: `mpirun -n 3 hpcwedge
                  run` (master + 2 workers sharing the DD faces, SPEC §5, and the mu^c tasks);
                  seconds = the program's timings.total (scene to result, as ours_run_scene),
                  the wall time with MPI start-up and the result file write beside it
  ours_exact      the same with compute.exact = true (exact rational arithmetic),
                  for the sizes it finishes within --exact-limit (default 60 s)
  cdd_exact       the peer: a full double description with cddlib in exact arithmetic
                  (pycddlib, number_type 'fraction' = GMP rationals) of the cone
                  P = {x : A x >= 0}, then a complementarity filter and a clique search
                  (networkx find_cliques via hpcwedge.rays.cones.maximal_cones)

The peer's A is friction_rows_2d() of *our* parametrisation (SPEC §1): lineality-free, the
rigid modes of the free body factored out exactly. We hand it the exact rows (primitive
integer vectors from the rational parametrisation, the same cone that ours_exact sees),
not the float rows converted to fractions: rounding the float rows breaks the degenerate
vertices of P (at m = 6 cddlib finds 1044 instead of 990 extreme rays on the rounded rows).

Every engine runs in a subprocess with a time limit, one size after the other; an engine's
sizes stop growing once it times out. The peer shares one budget (--budget, default 600 s,
--quick: 60 s) over its sizes. Model building and condensation are outside every time
except ours_run_scene's; the peer's time is cddlib + filter + cliques (building the exact
rows is reported apart, as "setup").

Writes results/bench_2d.csv, results/bench_2d.png and results/bench_2d.json (per-stage
breakdown); prints a summary. Exit status 1 (and MISMATCH on stderr) if two engines that
both finished disagree on the wedged-ray or cone counts, or on the zero sets.

peer_cdd (also with cddlib's float arithmetic; the routes are hpcwedge.reference's) takes any
2D ContactProblem, enumerate_ours any 2D scene's tables: scripts/bench_peers.py runs them on
other scenes.

The peer needs pycddlib (GPL, benchmark only):
    apt-get install -y libcdd-dev libgmp-dev
    .venv/bin/pip install "pycddlib<3"          # or: scripts/setup.sh bench
"""
from __future__ import annotations

import argparse
import csv
import hashlib
import json
import math
import os
import subprocess
import sys
import time

import harness
from harness import OVERRUN, python_command, run_command

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MARK = "BENCH_RESULT "
COLS, TAPER = 3, 10.0
ENGINES = ("ours_enumerate", "ours_run_scene", "ours_mpirun", "ours_exact", "cdd_exact")
CDD_HELP = ("pycddlib is not installed (needed for the cdd_exact peer). Install it with\n"
            "    apt-get install -y libcdd-dev libgmp-dev\n"
            f"    {sys.executable} -m pip install \"pycddlib<3\"\n"
            "or run scripts/setup.sh bench; or skip the peer with --no-peer.")


# --------------------------------------------------------------------------- workers

def _tables(rows: int) -> dict:
    """The scene tables of plug2d at `rows` (cols COLS, taper TAPER)."""
    return {"model": {"kind": "plug2d", "rows": rows, "cols": COLS, "taper_deg": TAPER}}


def _problem(rows: int):
    import hpcwedge.rays.cones  # noqa: F401  (networkx: imported before any clock starts)
    from hpcwedge.contact.condense import condense
    from hpcwedge.contact.problem import ContactProblem
    from hpcwedge.models.library import plug2d
    K, N = condense(plug2d(rows, COLS, TAPER))
    return ContactProblem(2, K, N)


def _fingerprint(zero_wedged, cone_keys) -> str:
    """Order-independent digest of the wedged rays' zero sets and the cones' zero sets."""
    import numpy as np
    h = hashlib.sha1()
    packed = np.packbits(np.asarray(zero_wedged, dtype=bool), axis=1)
    for r in sorted(row.tobytes() for row in packed):
        h.update(r)
    h.update(repr(sorted((tuple(map(int, zu)), tuple(map(int, zr))) for zu, zr in cone_keys)).encode())
    return h.hexdigest()[:16]


def _cones_of(zero, wedged):
    """maximal_cones on complementary rays given by their (R, 3m) zero flags."""
    from hpcwedge.rays.cones import maximal_cones
    gap = ~zero[:, 0::3]
    load = ~(zero[:, 1::3] & zero[:, 2::3])
    return maximal_cones(gap, load, wedged)


def _run_scene(tables: dict, mu: float, mu_c: str, exact: bool = False):
    """(Result, wall seconds) of pipeline.run_scene on a 2D scene (tables: its model / contact
    tables) at one mu, enumerate = true, the given compute.mu_c and compute.exact."""
    import hpcwedge.rays.cones  # noqa: F401  (networkx: imported before any clock starts)
    from hpcwedge.contact.condense import solver_name
    from hpcwedge.run.pipeline import run_scene
    from hpcwedge.scene.parse import parse_scene
    solver_name()      # imports and initialises petsc4py before the clock starts
    scene = parse_scene({"name": "bench", "dim": 2, **tables, "friction": {"mu": [mu]},
                         "compute": {"enumerate": True, "mu_c": mu_c, "exact": exact}})
    t0 = time.perf_counter()
    res = run_scene(scene)
    return res, time.perf_counter() - t0


def _counts(res) -> dict:
    """Counts, fingerprint and the run's own stage timings of a one-mu 2D Result."""
    run = res.runs[0]
    keys = [(c.zero_u, c.zero_r) for c in run.cones]
    return {"m": res.m, "n_wedged_rays": run.n_wedged_rays, "n_cones": run.n_cones,
            "n_trivial_rays": run.n_trivial_rays, "fingerprint": _fingerprint(run.ray_zero, keys),
            "breakdown": {k: float(v) for k, v in res.timings.items()}}


def worker_ours(rows: int, mu: float, exact: bool) -> dict:
    out = enumerate_ours(_tables(rows), mu, exact)
    del out["ray_zero"]
    return out


def enumerate_ours(tables: dict, mu: float, exact: bool) -> dict:
    """Our enumerate stage on a 2D scene (tables: its model / contact tables) as `hpcwedge run`
    runs it: pipeline.run_scene with mu_c = "none" (the DD in balanced coordinates, whole or
    over faces, the run-time judgement and its exact fallback, the cones). seconds: the run's
    own timings["enumerate"] (condensation outside); counts, fingerprint, the run's timings
    (breakdown), DD stats and numerics record, and the wedged rays' zero flags (ray_zero)."""
    res, _ = _run_scene(tables, mu, "none", exact)
    run = res.runs[0]
    return {"seconds": res.timings["enumerate"], **_counts(res), "dd_stats": res.stats["dd"][0],
            "numerics": res.stats["numerics"]["runs"][0], "ray_zero": run.ray_zero}


def worker_scene(rows: int, mu: float) -> dict:
    res, sec = _run_scene(_tables(rows), mu, "global")
    return {"seconds": sec, **_counts(res), "mu_c": res.mu_c, "mu_c_status": res.mu_c_status,
            "mu_c_rel_err": (abs(res.mu_c - math.tan(math.radians(TAPER))) / math.tan(math.radians(TAPER))
                             if res.mu_c is not None else None),
            "lp_solves": res.stats.get("lp_solves")}


def worker_mpirun(rows: int, mu: float, workers: int = 2) -> dict:
    import shutil
    import tempfile

    import h5py

    from hpcwedge.results.hdf5 import read_result
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        raise SystemExit(3)
    with tempfile.TemporaryDirectory() as tmp:
        scene = os.path.join(tmp, "scene.toml")
        with open(scene, "w") as f:
            f.write(f'name = "plug2d-r{rows}"\ndim = 2\n[model]\nkind = "plug2d"\nrows = {rows}\n'
                    f'cols = {COLS}\ntaper_deg = {TAPER}\n[friction]\nmu = [{mu!r}]\n'
                    '[compute]\nenumerate = true\nmu_c = "global"\n')
        out = os.path.join(tmp, "r.h5")
        extra = ["--allow-run-as-root"] if os.geteuid() == 0 else []
        t0 = time.perf_counter()
        subprocess.run([mpirun, *extra, "--oversubscribe", "-n", str(workers + 1), "-x", "PYTHONPATH",
                        sys.executable, "-m", "hpcwedge", "run", scene, "-o", out, "-q"], check=True,
                       env=dict(os.environ))     # Python's environment: a PETSc started here adds OMPI_* to C's
        wall = time.perf_counter() - t0
        res = read_result(out, with_rays=False).to_dict(with_rays=False)
        with h5py.File(out, "r") as f:
            zero = f["runs/000/ray_zero"][()]
    run = res["runs"][0]
    keys = [(c["zero_u"], c["zero_r"]) for c in run["cones"]]
    return {"seconds": res["timings"]["total"], "wall_with_startup_and_write": wall,
            "n_wedged_rays": run["n_wedged_rays"], "n_cones": run["n_cones"],
            "n_trivial_rays": run["n_trivial_rays"], "fingerprint": _fingerprint(zero, keys),
            "breakdown": {k: float(v) for k, v in res["timings"].items()},
            "workers": workers, "mu_c": res["mu_c"]}


def worker_peer(rows: int, mu: float) -> dict:
    return peer_cdd(_problem(rows), mu)


def peer_cdd(problem, mu: float, number_type: str = "fraction") -> dict:
    """The peer on a 2D ContactProblem: cddlib's full double description of P = {x : A x >= 0},
    A = friction_rows_2d of our parametrisation, then the complementarity filter and the clique
    search (reference.cdd_generators, cdd_zero, complementary_filter). number_type "fraction":
    the exact integer rows, exact arithmetic; "float": the float rows (what a float user hands
    it), cddlib's float arithmetic, zero test |a.x| <= dd.FLOAT_ZERO_TOL on unit rows and rays.
    Raises RuntimeError when cddlib returns lines (a cone it takes for not pointed) or a
    generator outside P; exits with status 3 (CDD_HELP) without pycddlib."""
    from hpcwedge.contact.problem import friction_rows_2d, parametrize
    from hpcwedge.rays.dd import FLOAT_ZERO_TOL
    from hpcwedge.reference import cdd_generators, cdd_zero, complementary_filter
    m = problem.m
    exact = number_type == "fraction"
    t0 = time.perf_counter()
    param = parametrize(problem, exact=exact)
    A = friction_rows_2d(param, mu, m, exact=exact)           # exact: (3m, d) primitive integer rows
    rows = [[int(v) for v in row] for row in A] if exact else A.tolist()
    t_setup = time.perf_counter() - t0
    try:
        import cdd  # noqa: F401  (imported before the clock starts)
    except ImportError:
        print(CDD_HELP, file=sys.stderr)
        raise SystemExit(3)
    t0 = time.perf_counter()
    gens, lin, version = cdd_generators([[0] + row for row in rows], number_type)
    t1 = time.perf_counter()
    if lin:
        raise RuntimeError(f"cddlib found {len(lin)} lines: the cone is not pointed")
    zero = cdd_zero(rows if exact else A, gens, exact, FLOAT_ZERO_TOL)
    R = len(zero)
    zero, wedged, n_comp = complementary_filter(zero)
    t2 = time.perf_counter()
    cones = _cones_of(zero, wedged)
    t3 = time.perf_counter()
    out = {"seconds": t3 - t0, "n_wedged_rays": int(wedged.sum()), "n_cones": len(cones),
           "n_trivial_rays": int((~wedged).sum()),
           "fingerprint": _fingerprint(zero[wedged], [c.key() for c in cones]),
           "breakdown": {"setup_exact_rows" if exact else "setup_rows": t_setup, "cdd_dd": t1 - t0,
                         "filter": t2 - t1, "cliques": t3 - t2},
           "n_extreme_rays_P": R, "n_complementary": n_comp, "cdd": version}
    if exact:
        out["max_row_bits"] = max(abs(v).bit_length() for row in rows for v in row)
    return out


def worker_main(kind: str, rows: int, mu: float) -> None:
    if kind == "ours":
        out = worker_ours(rows, mu, exact=False)
    elif kind == "exact":
        out = worker_ours(rows, mu, exact=True)
    elif kind == "scene":
        out = worker_scene(rows, mu)
    elif kind == "peer":
        out = worker_peer(rows, mu)
    elif kind == "mpirun":
        out = worker_mpirun(rows, mu)
    else:
        raise SystemExit(f"unknown worker {kind}")
    print(MARK + json.dumps(out), flush=True)


# --------------------------------------------------------------------------- driver

def run_worker(kind: str, rows: int, mu: float, limit: float) -> tuple[str, dict | None, float, str]:
    """(status, result, wall seconds, stderr tail) of one worker subprocess, killed at `limit`."""
    return run_script(os.path.abspath(__file__), ["--worker", kind, "--rows", str(rows), "--mu", repr(mu)], limit)


def run_script(script: str, argv: list[str], limit: float) -> tuple[str, dict | None, float, str]:
    """(status, result, wall seconds, stderr tail) of `python script argv` under harness.run_command
    (its own process group, killed at `limit`: status "timeout"); the result is the JSON on the
    last MARK line of its stdout; exit status 3: "missing" (a peer not installed)."""
    rec = run_command(python_command(script, *argv), limit=max(limit, 0.1))
    if rec["status"] == OVERRUN:
        return OVERRUN, None, rec["seconds"], ""
    for line in reversed(rec["stdout"].splitlines()):
        if line.startswith(MARK):
            return "ok", json.loads(line[len(MARK):]), rec["seconds"], ""
    if rec["returncode"] == 3:
        return "missing", None, rec["seconds"], rec["stderr"].strip()
    return "error", None, rec["seconds"], "\n".join(rec["stderr"].strip().splitlines()[-5:])


def run_record(script: str, argv: list[str], limit: float, **rec) -> dict:
    """`rec` with what run_script(script, argv, limit) gave: status, wall, the result's keys,
    and "error" (the stderr tail) where there is one."""
    status, res, wall, err = run_script(script, argv, limit)
    rec.update(status=status, wall=wall, **(res or {}))
    if err:
        rec["error"] = err
    return rec


def fields(r: dict, keys: tuple[str, ...], digits: int = 3) -> str:
    """`key=value` of the keys a record has (floats to `digits` significant digits)."""
    return "  ".join(f"{k}={r[k]:.{digits}g}" if isinstance(r.get(k), float) else f"{k}={r[k]}"
                     for k in keys if r.get(k) is not None)


def write_records(out: str, records: list[dict], meta: dict, cols: list[str]) -> None:
    """<out>.json (meta, the records, the environment record) and <out>.csv (`cols` of each
    record), for the benchmarks that run their engines through run_script (harness.write_records)."""
    harness.write_records(out, records, cols, extra=meta)
    print(f"wrote {out}.csv and {out}.json")


def fmt_s(v) -> str:
    if v is None:
        return "-"
    return f"{v:.4f}" if v < 1 else f"{v:.2f}" if v < 100 else f"{v:.0f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="rows 2..5 (m <= 10) and a 60 s peer budget")
    ap.add_argument("--budget", type=float, default=None,
                    help="total seconds for the cddlib peer over all sizes (default 600, --quick 60)")
    ap.add_argument("--mu", type=float, default=0.65)
    ap.add_argument("--max-rows", type=int, default=None, help="largest rows (default 10, --quick 5)")
    ap.add_argument("--ours-limit", type=float, default=1800.0,
                    help="seconds per size for ours_enumerate and ours_run_scene (default 1800)")
    ap.add_argument("--exact-limit", type=float, default=60.0, help="seconds per size for ours_exact")
    ap.add_argument("--no-peer", action="store_true", help="skip the cddlib peer")
    ap.add_argument("--no-mpirun", action="store_true", help="skip ours_mpirun (mpirun -n 3)")
    ap.add_argument("--out", default=os.path.join(ROOT, "results"), help="output directory")
    ap.add_argument("--profile-m", type=int, default=None,
                    help="also profile ours_enumerate's run_scene at this m with pyinstrument "
                         "(writes results/bench_2d_profile_m<M>.txt)")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--rows", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        worker_main(args.worker, args.rows, args.mu)
        return 0

    budget = args.budget if args.budget is not None else (60.0 if args.quick else 600.0)
    max_rows = args.max_rows or (5 if args.quick else 10)
    sizes = list(range(2, max_rows + 1))
    mu = args.mu
    os.makedirs(args.out, exist_ok=True)
    print(f"bench_2d: plug2d (cols {COLS}, taper {TAPER:g} deg, free body), mu = {mu:g}, "
          f"mu/mu^c = {mu / math.tan(math.radians(TAPER)):.2f}, m = {2 * sizes[0]}..{2 * sizes[-1]}")
    print("peer: full double description with cddlib in exact arithmetic of P = {x : A x >= 0}, "
          "A = friction_rows_2d of OUR parametrisation (same lineality-free cone, rigid modes of the "
          "free body factored out exactly; exact integer rows), then complementarity filter + "
          f"networkx clique search. Peer budget {budget:g} s in total.")
    if not args.no_peer:
        try:
            import cdd  # noqa: F401  (lazy check only, the peer runs in a subprocess)
        except ImportError:
            print(CDD_HELP, file=sys.stderr)
            return 3

    records: dict[tuple[str, int], dict] = {}
    stopped = {e: False for e in ENGINES}
    peer_used = 0.0
    limits = {"ours_enumerate": ("ours", args.ours_limit), "ours_run_scene": ("scene", args.ours_limit),
              "ours_mpirun": ("mpirun", args.ours_limit), "ours_exact": ("exact", args.exact_limit)}
    for rows in sizes:
        m = 2 * rows
        plan = [(e, *limits[e]) for e in ("ours_enumerate", "ours_run_scene", "ours_mpirun", "ours_exact")
                if e != "ours_mpirun" or not args.no_mpirun]
        if not args.no_peer:
            plan.append(("cdd_exact", "peer", budget - peer_used))
        for engine, kind, limit in plan:
            rec = {"m": m, "rows": rows, "mu": mu, "engine": engine}
            if stopped[engine] or limit <= 0.5:
                rec["status"] = "not_run" if stopped[engine] else "budget_exhausted"
                stopped[engine] = True
                records[(engine, m)] = rec
                continue
            status, res, wall, err = run_worker(kind, rows, mu, limit)
            if engine == "cdd_exact":
                peer_used += wall
            rec["status"] = status
            if status == "ok":
                rec.update(res)
                rec["rays_per_second"] = res["n_wedged_rays"] / res["seconds"] if res["seconds"] > 0 else None
            elif status == "timeout":
                rec["seconds_lower_bound"] = wall
                stopped[engine] = True
            else:
                stopped[engine] = True
                rec["error"] = err
                print(f"  {engine} m={m}: {status}: {err}", file=sys.stderr)
            records[(engine, m)] = rec
            extra = ""
            if status == "ok" and "breakdown" in res:
                extra = "  [" + ", ".join(f"{k} {fmt_s(v)}" for k, v in res["breakdown"].items()) + "]"
            shown = fmt_s(res["seconds"]) if status == "ok" else f">{wall:.0f}" if status == "timeout" else "-"
            counts = f"{res['n_wedged_rays']} rays, {res['n_cones']} cones" if status == "ok" else status
            print(f"  m={m:2d} {engine:15s} {shown:>8s} s  {counts}{extra}", flush=True)

    # ----------------------------------------------------------------- checks
    mismatches = []
    for rows in sizes:
        m = 2 * rows
        done = [(e, records[(e, m)]) for e in ENGINES if records.get((e, m), {}).get("status") == "ok"]
        if not done:
            continue
        ref_e, ref = done[0]
        for e, r in done[1:]:
            for key in ("n_wedged_rays", "n_cones", "fingerprint"):
                if r[key] != ref[key]:
                    mismatches.append(f"m={m}: {key}: {ref_e} {ref[key]} != {e} {r[key]}")

    # ----------------------------------------------------------------- outputs
    csv_path = os.path.join(args.out, "bench_2d.csv")
    with open(csv_path + ".tmp", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["m", "rows", "mu", "engine", "seconds", "n_wedged_rays", "n_cones",
                    "rays_per_second", "status"])
        for rows in sizes:
            for e in ENGINES:
                r = records.get((e, 2 * rows))
                if r is None:
                    continue
                sec = r.get("seconds", r.get("seconds_lower_bound"))
                w.writerow([r["m"], r["rows"], r["mu"], e,
                            "" if sec is None else f"{sec:.6g}",
                            r.get("n_wedged_rays", ""), r.get("n_cones", ""),
                            "" if r.get("rays_per_second") is None else f"{r['rays_per_second']:.6g}",
                            r["status"]])
    os.replace(csv_path + ".tmp", csv_path)
    from hpcwedge.environment import environment
    with open(os.path.join(args.out, "bench_2d.json"), "w") as f:
        json.dump({"scene": {"model": "plug2d", "cols": COLS, "taper_deg": TAPER, "mu": mu},
                   "peer_budget_s": budget, "peer_used_s": peer_used, "quick": args.quick,
                   "records": [records[k] for k in sorted(records, key=lambda k: (k[1], ENGINES.index(k[0])))],
                   "mismatches": mismatches, "environment": environment()}, f, indent=1, default=str)
    plot(records, sizes, budget, os.path.join(args.out, "bench_2d.png"), mu)

    # ----------------------------------------------------------------- summary
    print()
    hdr = (f"{'m':>3} {'wedged':>8} {'cones':>5} | {'ours enum s':>11} {'rays/s':>9} | "
           f"{'run_scene s':>11} | {'mpirun 2w s':>11} | {'ours exact s':>12} | {'cdd exact s':>11} | {'peer/ours':>9}")
    print(hdr)
    print("-" * len(hdr))
    for rows in sizes:
        m = 2 * rows
        r = {e: records.get((e, m), {}) for e in ENGINES}

        def cell(e, width):
            x = r[e]
            if x.get("status") == "ok":
                return f"{fmt_s(x['seconds']):>{width}}"
            if x.get("status") == "timeout":
                return f"{'>' + format(x['seconds_lower_bound'], '.0f'):>{width}}"
            return f"{x.get('status', '-'):>{width}}"
        o = r["ours_enumerate"]
        nw = next((x["n_wedged_rays"] for x in r.values() if x.get("status") == "ok"), None)
        nc = next((x["n_cones"] for x in r.values() if x.get("status") == "ok"), None)
        ratio = speedup(r)
        print(f"{m:>3} {nw if nw is not None else '-':>8} {nc if nc is not None else '-':>5} | "
              f"{cell('ours_enumerate', 11)} "
              f"{(format(o['rays_per_second'], '.3g') if o.get('rays_per_second') else '-'):>9} | "
              f"{cell('ours_run_scene', 11)} | {cell('ours_mpirun', 11)} | {cell('ours_exact', 12)} | {cell('cdd_exact', 11)} | "
              f"{ratio or '-':>9}")
    print()
    ok_m = [2 * rows for rows in sizes if records.get(("ours_enumerate", 2 * rows), {}).get("status") == "ok"]
    if ok_m:
        big = records[("ours_enumerate", max(ok_m))]
        sc = records.get(("ours_run_scene", max(ok_m)), {})
        print(f"largest m finished by ours: m = {max(ok_m)}: enumerate {fmt_s(big['seconds'])} s "
              f"({big['n_wedged_rays']} wedged rays, {big['rays_per_second']:.3g} rays/s); "
              f"run_scene {fmt_s(sc.get('seconds')) if sc.get('status') == 'ok' else sc.get('status')} s")
    ex_m = [2 * rows for rows in sizes if records.get(("ours_exact", 2 * rows), {}).get("status") == "ok"]
    if ex_m:
        print(f"largest m finished by ours_exact within {args.exact_limit:g} s: m = {max(ex_m)} "
              f"({fmt_s(records[('ours_exact', max(ex_m))]['seconds'])} s)")
    pe_m = [2 * rows for rows in sizes if records.get(("cdd_exact", 2 * rows), {}).get("status") == "ok"]
    if pe_m:
        print(f"largest m finished by the cddlib peer (budget {budget:g} s, used {peer_used:.0f} s): "
              f"m = {max(pe_m)} ({fmt_s(records[('cdd_exact', max(pe_m))]['seconds'])} s)")
    sc_mu = [records[("ours_run_scene", mm)] for mm in ok_m if records.get(("ours_run_scene", mm), {}).get("status") == "ok"]
    if sc_mu:
        errs = [x["mu_c_rel_err"] for x in sc_mu if x.get("mu_c_rel_err") is not None]
        if errs:
            print(f"global mu^c vs tan(taper) = {math.tan(math.radians(TAPER)):.15g}: "
                  f"max relative error {max(errs):.2e} over m = {', '.join(str(x['m']) for x in sc_mu)}")
    print("targets:")
    r8 = {e: records.get((e, 8), {}) for e in ENGINES}
    s8 = speedup(r8)
    if s8 is None:
        print("  m = 8, >= 100x faster than the peer: not measured")
    else:
        val = float(s8.lstrip(">").rstrip("x"))
        print(f"  m = 8, >= 100x faster than the peer: {s8} -> {'MET' if val >= 100 else 'NOT MET'}"
              + (" (lower bound: the peer timed out)" if s8.startswith(">") else ""))
    r20 = records.get(("ours_enumerate", 20), {})
    s20 = records.get(("ours_run_scene", 20), {})
    p20 = records.get(("ours_mpirun", 20), {})
    if not r20:
        print("  m = 20 within 60 s: not measured (run without --quick)")
    else:
        for name, x in (("enumerate, 1 core", r20), ("run_scene, 1 core", s20),
                        ("mpirun -n 3, 2 workers on the 2 cores", p20)):
            if x.get("status") == "ok":
                print(f"  m = 20 within 60 s ({name}): {fmt_s(x['seconds'])} s -> "
                      f"{'MET' if x['seconds'] <= 60 else 'NOT MET'}")
            elif x:
                lb = x.get("seconds_lower_bound")
                print(f"  m = 20 within 60 s ({name}): {x['status']}"
                      + (f" after {lb:.0f} s" if lb else "") + " -> NOT MET")
    print(f"wrote {csv_path}, {os.path.join(args.out, 'bench_2d.png')}, {os.path.join(args.out, 'bench_2d.json')}")

    if args.profile_m:
        profile(args.profile_m, mu, args.out)

    if mismatches:
        print("\n" + "!" * 72, file=sys.stderr)
        for s in mismatches:
            print(f"MISMATCH {s}", file=sys.stderr)
        print("!" * 72, file=sys.stderr)
        return 1
    print("counts and zero sets agree wherever two or more engines finished")
    return 0


def speedup(r: dict) -> str | None:
    """peer / ours_enumerate as text ('>N x' when the peer timed out), or None."""
    o, p = r.get("ours_enumerate", {}), r.get("cdd_exact", {})
    if o.get("status") != "ok":
        return None
    if p.get("status") == "ok":
        return f"{p['seconds'] / o['seconds']:.0f}x"
    if p.get("status") == "timeout":
        return f">{p['seconds_lower_bound'] / o['seconds']:.0f}x"
    return None


def plot(records, sizes, budget, path, mu) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(10, 4.8))
    style = {"ours_enumerate": ("o-", "ours, enumerate (float)"),
             "ours_run_scene": ("s-", "ours, run_scene (mu_c global)"),
             "ours_mpirun": ("v-", "ours, mpirun -n 3 (2 workers), timings.total"),
             "ours_exact": ("^-", "ours, exact arithmetic"),
             "cdd_exact": ("D-", "cddlib exact DD + filter + cliques")}
    for e in ENGINES:
        ms, ts, lm, lt = [], [], [], []
        for rows in sizes:
            r = records.get((e, 2 * rows), {})
            if r.get("status") == "ok":
                ms.append(2 * rows)
                ts.append(max(r["seconds"], 1e-5))
            elif r.get("status") == "timeout":
                lm.append(2 * rows)
                lt.append(r["seconds_lower_bound"])
        if not ms and not lm:
            continue
        mk, label = style[e]
        line, = ax.plot(ms, ts, mk, label=label)
        if lm:
            ax.plot(lm, lt, linestyle="none", marker="$\\uparrow$", color=line.get_color(),
                    markersize=14, label=f"{label}: timed out (lower bound)")
    ax.axhline(60, color="grey", lw=0.8, ls=":")
    ax.text(2 * sizes[0], 60 * 1.15, "60 s", color="grey", fontsize=8)
    ax.set_yscale("log")
    ax.set_xlabel("m (contact nodes)")
    ax.set_ylabel("seconds")
    ax.set_title(f"plug2d (cols {COLS}, taper {TAPER:g}°), mu = {mu:g}")
    ax.set_xticks([2 * r for r in sizes])
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def profile(m: int, mu: float, out: str) -> None:
    try:
        from pyinstrument import Profiler
    except ImportError:
        print("pyinstrument is not installed: pip install pyinstrument", file=sys.stderr)
        return
    prof = Profiler(interval=0.005)
    prof.start()
    _run_scene(_tables(m // 2), mu, "none")         # ours_enumerate's run (condensation included)
    prof.stop()
    text = prof.output_text(unicode=False, color=False, show_all=False)
    path = os.path.join(out, f"bench_2d_profile_m{m}.txt")
    with open(path, "w") as f:
        f.write(text)
    print(f"profile of ours_enumerate at m = {m}: {path}")
    print("\n".join(text.splitlines()[:40]))


if __name__ == "__main__":
    sys.exit(main())
