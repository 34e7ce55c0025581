#!/usr/bin/env python3
"""The global mu^c at meshed-body scale (issue 41's targets), through `hpcwedge run`.

Each case is a scene file written to a temporary directory and run by the product's entry
point (`python -m hpcwedge run scene.toml -o out.h5 -q`, serial, `run.symmetry = false`,
every other key at its default; compute.mu_c = "global", no enumeration, friction.mu [0.1]),
under a time limit (harness.run_command: an overrun is recorded as "timeout"). The answer and
counts are read back with `hpcwedge show --json`:

    case                  m     target
    plug3d 8 x 8          64    <= 10 s
    plug3d 8 x 16         128   <= 60 s
    plug2d rows 320       640   <= 30 s
    block2d rows 159      320   <= 30 s

(plug2d: m = 2 rows; block2d: m = 2 (rows + 1); plug3d: m = levels x ring.) Every one is a
free plug at a 10 deg taper, whose global mu^c is tan 10 deg (SPEC §6); the error is
against it. Written: results/bench_global_scale.{json,csv} (--quick: smaller bodies,
results/bench_global_scale_quick.*): seconds (wall, the command), program_seconds (the
result's timings.total, and its condense and mu_c stages), the global mu^c and its relative error, route, tree nodes, solves
(SOCPs in 3D, LPs in 2D), pyramid LPs, MILPs, bound solves and whether the certified bound
ended the search, undecided solves, unsettled patterns, the target and whether it was met.

--peers scip gurobi: each peer on each case too (scripts/peers_global.py: the feasibility
MILP / MISOCP with binary contact flags, bisection on mu to 1e-6), in its own process with
the same time limit (it stops its bisection at the limit; PEER_GRACE more before it is
killed), one row each (engine = the peer; ours: "ours"): status ("ok", "timeout", "too
large": the model exceeds Gurobi's size-limited licence, checked before it is built,
"missing": the package is not installed), seconds, mu_c and rel_error, the bracket
(mu_lo, mu_hi; the last one when it timed out), milp_solves, milp_nodes (the peer's
branch-and-bound nodes), undecided, the model's n_vars and n_cons. --skip-ours: only the
peers. The output keeps the rows of its earlier version whose case and engine this run does
not measure (rows without an engine are ours).

    .venv/bin/python scripts/bench_global_scale.py [--quick] [--limit 300] [--only plug3d-8x8 ...]
                                                   [--peers scip gurobi] [--skip-ours]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import tempfile

from harness import ERROR, OK, OVERRUN, python_command, run_command, write_records
from peers_global import PEERS

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "results")
TAPER_DEG = 10.0
#: seconds a peer's process gets beyond the limit (its bisection stops itself at the limit)
PEER_GRACE = 30.0

#: (name, dim, model table, m, target seconds)
CASES = [
    ("plug3d-8x8", 3, {"kind": "plug3d", "levels": 8, "ring": 8}, 64, 10.0),
    ("plug3d-8x16", 3, {"kind": "plug3d", "levels": 8, "ring": 16}, 128, 60.0),
    ("plug2d-r320", 2, {"kind": "plug2d", "rows": 320}, 640, 30.0),
    ("block2d-r159", 2, {"kind": "block2d", "rows": 159}, 320, 30.0),
]
QUICK = [
    ("plug3d-4x8", 3, {"kind": "plug3d", "levels": 4, "ring": 8}, 32, None),
    ("plug2d-r40", 2, {"kind": "plug2d", "rows": 40}, 80, None),
    ("block2d-r39", 2, {"kind": "block2d", "rows": 39}, 80, None),
]


def scene_text(name: str, dim: int, model: dict) -> str:
    """The scene file of a case: the global mu^c alone, no symmetry, defaults otherwise."""
    keys = "".join(f"{k} = {json.dumps(v)}\n" for k, v in {**model, "taper_deg": TAPER_DEG}.items())
    return (f'name = "{name}"\ndim = {dim}\n[model]\n{keys}[friction]\nmu = [0.1]\n'
            f'[compute]\nenumerate = false\nmu_c = "global"\n[run]\nsymmetry = false\n')


def run_case(tmp: str, name: str, dim: int, model: dict, m: int, target: float | None, limit: float) -> dict:
    """One case through `hpcwedge run` and `hpcwedge show --json`: its record."""
    scene, out = os.path.join(tmp, f"{name}.toml"), os.path.join(tmp, f"{name}.h5")
    with open(scene, "w") as f:
        f.write(scene_text(name, dim, model))
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    load = os.getloadavg()[0]               # the shared machine's 1-minute load before the run
    rec = run_command(python_command("-m", "hpcwedge", "run", scene, "-o", out, "-q"), limit=limit, env=env)
    row = {"case": name, "dim": dim, "m": m, "model": json.dumps(model), "engine": "ours", "status": rec["status"],
           "seconds": rec["seconds"], "target_seconds": target, "load_before": load}
    if rec["status"] == ERROR:
        row["error"] = rec["stderr"].strip().splitlines()[-1:] if rec["stderr"] else ""
    if rec["status"] != OK:
        return row
    js = json.loads(run_command(python_command("-m", "hpcwedge", "show", out, "--json"))["stdout"])
    bnb, want = js["stats"].get("bnb") or {}, math.tan(math.radians(TAPER_DEG))
    mu_c = js["mu_c"]
    row.update(m_result=js["m"], program_seconds=js["timings"]["total"],
               condense_seconds=js["timings"]["condense"], mu_c_seconds=js["timings"]["mu_c"], mu_c=mu_c, mu_c_status=js.get("mu_c_status"),
               rel_error=None if mu_c is None else abs(mu_c - want) / want, route=bnb.get("route"),
               nodes=bnb.get("nodes"), solves=bnb.get("solves"), lps=bnb.get("lps"),
               milp_solves=bnb.get("milp_solves"), bound_solves=bnb.get("bound_solves"),
               bound_certified=bnb.get("bound_certified"), undecided=bnb.get("undecided"),
               unsettled=bnb.get("unsettled"),
               target_met=None if target is None else rec["seconds"] <= target)
    return row


def run_peer(tmp: str, peer: str, name: str, dim: int, model: dict, m: int, limit: float) -> dict:
    """One peer on one case (scripts/peers_global.py in its own process): its record."""
    scene = os.path.join(tmp, f"{name}.toml")
    with open(scene, "w") as f:
        f.write(scene_text(name, dim, model))
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    load = os.getloadavg()[0]
    script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "peers_global.py")
    rec = run_command(python_command(script, peer, scene, "--limit", str(limit)), limit=limit + PEER_GRACE, env=env)
    row = {"case": name, "dim": dim, "m": m, "model": json.dumps(model), "engine": peer, "status": rec["status"],
           "seconds": rec["seconds"], "target_seconds": None, "load_before": load}
    if rec["status"] == ERROR:
        row["error"] = rec["stderr"].strip().splitlines()[-1:] if rec["stderr"] else ""
    if rec["status"] != OK:
        return row
    got = json.loads(rec["stdout"].strip().splitlines()[-1])
    mu_c, want = got.get("mu_c"), math.tan(math.radians(TAPER_DEG))
    row.update({k: got.get(k) for k in ("status", "mu_c", "mu_lo", "mu_hi", "milp_solves", "milp_nodes", "undecided",
                                        "n_vars", "n_cons")})
    row.update(rel_error=None if mu_c is None else abs(mu_c - want) / want, program_seconds=got.get("seconds"))
    return row


def peer_line(row: dict) -> str:
    """A peer's row, printed."""
    err = "" if row.get("rel_error") is None else f" err={row['rel_error']:.1e}"
    return (f"{row['case']:<14} m={row['m']:<4} {row['engine']:<7} {row['status']:<9} {row['seconds']:7.2f} s "
            f"mu_c={row.get('mu_c')!r}{err} bracket=[{row.get('mu_lo')}, {row.get('mu_hi')}] "
            f"milps={row.get('milp_solves')} nodes={row.get('milp_nodes')} size={row.get('n_vars')}x{row.get('n_cons')}")


def kept(base: str, rows: list[dict]) -> list[dict]:
    """The rows of an earlier base.json whose (case, engine) is not among `rows` (rows without
    an engine are ours), then `rows`: a run of some engines or cases keeps the others'."""
    try:
        with open(base + ".json") as f:
            before = [{**r, "engine": r.get("engine", "ours")} for r in json.load(f)["records"]]
    except FileNotFoundError:
        before = []
    done = {(r["case"], r["engine"]) for r in rows}
    return [r for r in before if (r["case"], r["engine"]) not in done] + rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller bodies (m = 32 / 80 / 80), no targets")
    ap.add_argument("--limit", type=float, default=300.0, help="seconds per case (default 300)")
    ap.add_argument("--only", nargs="*", help="case names to run (default: all)")
    ap.add_argument("--out", default=None, help="output base (default results/bench_global_scale[_quick])")
    ap.add_argument("--peers", nargs="*", default=[], choices=PEERS, help="peers to run on each case too")
    ap.add_argument("--skip-ours", action="store_true", help="peers only (the output keeps its earlier rows of the rest)")
    args = ap.parse_args()
    cases = [c for c in (QUICK if args.quick else CASES) if not args.only or c[0] in args.only]
    base = args.out or os.path.join(OUT, "bench_global_scale" + ("_quick" if args.quick else ""))
    tmp = tempfile.mkdtemp(prefix="bench_global_scale_")
    rows = []
    for name, dim, model, m, target in cases:
        for peer in args.peers:
            rows.append(run_peer(tmp, peer, name, dim, model, m, args.limit))
            print(peer_line(rows[-1]), flush=True)
        if args.skip_ours:
            continue
        row = run_case(tmp, name, dim, model, m, target, args.limit)
        rows.append(row)
        if row["status"] == OK:
            print(f"{name:<14} m={m:<4} {row['seconds']:7.2f} s  mu_c={row['mu_c']!r} err={row['rel_error']:.1e} "
                  f"route={row['route']} nodes={row['nodes']} solves={row['solves']} lps={row['lps']} "
                  f"milps={row['milp_solves']} bound={row['bound_solves']}/{row['bound_certified']} "
                  f"undecided={row['undecided']} target={target} met={row['target_met']}", flush=True)
        else:
            print(f"{name:<14} m={m:<4} {row['status']} after {row['seconds']:.1f} s {row.get('error', '')}",
                  flush=True)
    write_records(base, kept(base, rows), extra={"limit_seconds": args.limit, "taper_deg": TAPER_DEG,
                                     "command": "python -m hpcwedge run scene.toml -o out.h5 -q (serial)",
                                     "peers": "python scripts/peers_global.py PEER scene.toml --limit LIMIT",
                                     "peer_grace_seconds": PEER_GRACE})
    print(f"wrote {base}.json / .csv")
    return 0 if all(r["status"] in (OK, OVERRUN, "too large", "missing") for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
