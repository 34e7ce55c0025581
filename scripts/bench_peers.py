#!/usr/bin/env python3
"""Peers side by side (issue 4, item 4): every engine on the same scenes, in one run.

    PYTHONPATH=. python scripts/bench_peers.py [--quick] [--out results/bench_peers]

2D scenes (friction rows of SPEC §1's parametrisation; m = contact nodes):
  plug2d r2..r5      free body, cols 3, taper 10 deg, mu 0.65 (m = 4..10; --quick: r2..r4)
  plug2d taper 1/0.1 free body, rows 3 taper 1 and 0.1, rows 4 taper 0.1 (--quick: rows 3,
                     taper 0.1), mu = 1.5 tan(taper)
  plug truss ground  the plug2d truss held by three ground bars of EA 1 (stress.plug_truss):
                     a supported body, rows 4 (m = 8; --quick: rows 3)
  vgroove eps 0/0.1  the V-groove bar, free (eps 0) and supported (eps 0.1), mu 1.5 mu^c
2D engines, each in its own subprocess with a time limit (bench_2d.run_script):
  ours_float   our enumerate stage in float as `hpcwedge run` runs it (bench_2d.enumerate_ours:
               run_scene's timings.enumerate)                        <- the reference time
  ours_exact   the same with compute.exact = true (exact rational arithmetic)
  cdd_exact    cddlib's full double description of P = {x : A x >= 0} in exact arithmetic
               (GMP rationals) on the exact integer rows, then the complementarity filter
               and the clique search (bench_2d.peer_cdd)
  cdd_float    the same peer in cddlib's float arithmetic on the float rows (what a float
               user hands it), zero test |a.x| <= dd.FLOAT_ZERO_TOL on unit rows and rays
  brute_lp     one LP per sign pattern, all 2^m of them (reference.brute_force_patterns: HiGHS
               via feasibility.decide), compared with the pattern set the exact rays imply
               (cones.implied_patterns, SPEC §2)
mu^c: bench_mu_c's analytic scenes (its --quick list; --quick here: every other one): the
  critical cone / pattern once (bench_mu_c.critical_pattern), then plain bisection (LP in
  2D, SOCP in 3D) to relative width 1e-6 and 1e-9 against our accurate mu^c (2D bracket +
  pencil polish, 3D Dinkelbach + KKT Newton), best of 3, error against the analytic value.
3D: plug3d levels 2, ring 4..6 (m = 8..12; --quick: ring 4, 5), mu 1.0
  (bench_growth.worker_3d): ours = PatternTree branch and bound with plug3d's symmetry
  ("bnb_sym", as `hpcwedge run`) and without ("bnb"); peer = brute force, one SOCP per
  partition (2^m). Ratios of time and of SOCP count.

Agreement. Counts and zero-set fingerprints of ours_float, ours_exact and cdd_exact must
agree; brute_lp's pattern set must equal the one our exact rays imply (our float rays'
where the exact run did not finish); 3D pattern sets of bnb_sym, bnb and brute must agree.
mu^c: ours must be within 1e-9 of the analytic value; bisection's error above its
tolerance (the solvers' default tolerances cap it, 3D SOCPs near 1e-6..1e-5) is recorded
as "off", not fatal. Any other disagreement is a MISMATCH (exit status 1). cdd_float is compared with the
exact answer and its failures are the expected ones (recorded, never fatal): "aborted"
(cddlib stops with "Numerical inconsistency is found", or returns lines or a generator
outside P) or "miscount". An engine that did not finish in its time limit is "timeout";
a ratio against it is a lower bound (">").

Time limits (seconds per point; an engine stops growing along the plug2d series after a
timeout): ours 120, exact 60, cdd_exact 120, cdd_float 60, brute 60, mu^c 60 per scene,
3D 120 (--quick: 30 for the peers, cdd_exact 20). Full run ~10 min, --quick ~2 min.
Writes <out>.csv, <out>.json and <out>.png; prints the table of times, ratios and agreement.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import bench_2d  # noqa: E402  (run_script, enumerate_ours, peer_cdd, MARK)

ROOT = bench_2d.ROOT
ENGINES_2D = ("ours_float", "ours_exact", "cdd_exact", "cdd_float", "brute_lp")
ENGINES_3D = ("bnb_sym", "bnb", "brute")
MUC_METHODS = (("bisection 1e-6", "bisection", 1e-6), ("bisection 1e-9", "bisection", 1e-9),
               ("accurate", "accurate", 1e-6))
MU_PLUG = 0.65


# --------------------------------------------------------------------------- scenes

def scenes_2d(quick: bool) -> list[dict]:
    """[{label, series, size, dim 2 scene tables (model/contact), mu}]: see the module doc."""
    import stress
    tan = stress.tan
    out = []
    for rows in ((2, 3, 4) if quick else (2, 3, 4, 5)):
        out.append({"label": f"plug2d r{rows}", "series": "plug2d", "size": rows,
                    "spec": {"model": {"kind": "plug2d", "rows": rows, "cols": 3, "taper_deg": 10.0}},
                    "mu": MU_PLUG})
    for rows, taper in (((3, 0.1),) if quick else ((3, 1.0), (3, 0.1), (4, 0.1))):
        out.append({"label": f"plug2d r{rows} taper {taper:g}", "series": None, "size": rows,
                    "spec": {"model": {"kind": "plug2d", "rows": rows, "cols": 3, "taper_deg": taper}},
                    "mu": 1.5 * tan(taper)})
    rows = 3 if quick else 4
    out.append({"label": f"plug truss r{rows} ground", "series": None, "size": rows,
                "spec": stress.plug_truss(rows, ground=1.0), "mu": MU_PLUG})
    for eps in (0.0, 0.1):
        th, k = 20.0, 1.0
        want = tan(th) + eps / (k * math.sin(2 * math.radians(th)))
        out.append({"label": f"vgroove eps {eps:g}", "series": None, "size": 1,
                    "spec": {"model": {"kind": "vgroove_bar", "theta_deg": th, "EA": 2 * k, "eps": eps}},
                    "mu": 1.5 * want})
    return out


def _problem(spec: dict, mu: float):
    import hpcwedge.rays.cones  # noqa: F401  (networkx imported before any clock starts)
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.scene.parse import parse_scene
    return contact_problem(parse_scene({"name": "peers", "dim": 2, **spec, "friction": {"mu": [mu]}}))


def _bits(patterns) -> list[int]:
    """Contact sets (tuples of nodes) as sorted bit integers."""
    return sorted(sum(1 << i for i in c) for c in patterns)


# --------------------------------------------------------------------------- workers (subprocess)

def worker_2d(engine: str, spec: dict, mu: float) -> dict:
    if engine in ("ours_float", "ours_exact"):
        from hpcwedge.rays.cones import implied_patterns
        out = bench_2d.enumerate_ours(spec, mu, exact=engine == "ours_exact")
        out["patterns"] = _bits(implied_patterns(out.pop("ray_zero"), out["m"]))
        return {**out, "n_patterns": len(out["patterns"])}
    problem = _problem(spec, mu)
    m = problem.m
    if engine in ("cdd_exact", "cdd_float"):
        out = bench_2d.peer_cdd(problem, mu, "fraction" if engine == "cdd_exact" else "float")
    elif engine == "brute_lp":
        from hpcwedge.contact.problem import parametrize
        from hpcwedge.reference import brute_force_patterns
        t0 = time.perf_counter()
        param = parametrize(problem)
        found = brute_force_patterns(param, m, mu)
        out = {"seconds": time.perf_counter() - t0, "patterns": sorted(found), "lps": 2 ** m}
    else:
        raise SystemExit(f"unknown 2D engine {engine}")
    out["m"] = m
    if "patterns" in out:
        out["n_patterns"] = len(out["patterns"])
    return out


def worker_muc(index: int, quick: bool) -> dict:
    import bench_mu_c

    from hpcwedge.mu_c.critical import mu_critical
    label, dim, model, mu, want = muc_scenes(quick)[index]
    param, m, zu, zr = bench_mu_c.critical_pattern(dim, model, mu)
    out = {"label": label, "dim": dim, "m": m, "analytic": want, "methods": {}}
    for name, method, tol in MUC_METHODS:
        sec, r = bench_mu_c.timed(lambda: mu_critical(param, m, zu, zr, mu_hi=mu, method=method, tol=tol), 3)
        out["methods"][name] = {"seconds": sec, "mu_c": r.mu_c, "solves": r.solves,
                                "rel_error": abs(r.mu_c - want) / want if r.mu_c is not None else None}
    return out


def muc_scenes(quick: bool) -> list:
    import bench_mu_c
    sc = bench_mu_c.scenes(True)
    return sc[::2] if quick else sc


def worker_main(argv: list[str]) -> None:
    kind = argv[0]
    if kind == "2d":
        out = worker_2d(argv[1], json.loads(argv[2]), float(argv[3]))
    elif kind == "muc":
        out = worker_muc(int(argv[1]), argv[2] == "quick")
    elif kind == "3d":
        import bench_growth
        out = bench_growth.worker_3d(argv[1], int(argv[2]))
    else:
        raise SystemExit(f"unknown worker {kind}")
    print(bench_2d.MARK + json.dumps(out), flush=True)


# --------------------------------------------------------------------------- driver

def limits(quick: bool) -> dict:
    peer = 30.0 if quick else 60.0
    return {"ours_float": 120.0, "ours_exact": 60.0, "cdd_exact": 20.0 if quick else 120.0,
            "cdd_float": peer, "brute_lp": peer, "muc": 60.0, "3d": 30.0 if quick else 120.0}


def run(argv: list[str], limit: float) -> dict:
    return bench_2d.run_record(os.path.abspath(__file__), ["--worker", *argv], limit)


def measure_2d(quick: bool, lim: dict) -> list[dict]:
    recs, stopped = [], set()
    for sc in scenes_2d(quick):
        for e in ENGINES_2D:
            if sc["series"] and (sc["series"], e) in stopped:
                rec = {"status": "not_run"}
            else:
                rec = run(["2d", e, json.dumps(sc["spec"]), repr(sc["mu"])], lim[e])
                if rec["status"] == "timeout" and sc["series"]:
                    stopped.add((sc["series"], e))
            rec.update(section="2d", scene=sc["label"], engine=e, mu=sc["mu"])
            recs.append(rec)
            print_rec(rec)
    return recs


def measure_muc(quick: bool, lim: dict) -> list[dict]:
    recs = []
    for i, (label, dim, _, _, _) in enumerate(muc_scenes(quick)):
        r = run(["muc", str(i), "quick" if quick else "full"], lim["muc"])
        for name, _, _ in MUC_METHODS:
            rec = {"section": "mu_c", "scene": label, "engine": name, "status": r["status"],
                   "m": r.get("m"), "dim": dim}
            if r["status"] == "ok":
                rec.update(r["methods"][name])
            recs.append(rec)
            print_rec(rec)
    return recs


def measure_3d(quick: bool, lim: dict) -> list[dict]:
    recs, stopped = [], set()
    for ring in ((4, 5) if quick else (4, 5, 6)):
        for e in ENGINES_3D:
            rec = {"status": "not_run"} if e in stopped else run(["3d", e, str(ring)], lim["3d"])
            if rec["status"] == "timeout":
                stopped.add(e)
            rec.update(section="3d", scene=f"plug3d 2x{ring}", engine=e)
            recs.append(rec)
            print_rec(rec)
    return recs


# --------------------------------------------------------------------------- judging

def _time(r: dict) -> tuple[float | None, bool]:
    """(seconds, is a lower bound) of a record: its time, or the wall time it was cut at."""
    if r.get("status") == "ok":
        return r["seconds"], False
    if r.get("status") == "timeout":
        return r["wall"], True
    return None, False


def ratio(peer: dict, ours: dict) -> str:
    """peer time / our time as text ('>' when the peer timed out), '' when not defined."""
    tp, lower = _time(peer)
    to, _ = _time(ours)
    if tp is None or not to or ours.get("status") != "ok":
        return ""
    return f"{'>' if lower else ''}{tp / to:.3g}"


def judge(recs: list[dict]) -> list[str]:
    """Set rec["agree"] ("yes", "no", "aborted", "expected: ...", "-") and rec["ratio"] on
    every record; return the mismatches (disagreements that are not the float peer's)."""
    mismatches = []
    by = {}
    for r in recs:
        by.setdefault((r["section"], r["scene"]), {})[r["engine"]] = r
    for (section, scene), g in by.items():
        if section == "2d":
            ref_e = next((e for e in ("ours_exact", "cdd_exact", "ours_float") if g[e]["status"] == "ok"), None)
            ref = g.get(ref_e, {})
            pat_ref = next((g[e]["patterns"] for e in ("ours_exact", "ours_float") if g[e]["status"] == "ok"), None)
            for e, r in g.items():
                r["ratio"] = ratio(r, g["ours_float"]) if e != "ours_float" else "1"
                if r["status"] != "ok":
                    r["agree"] = "aborted" if r["status"] == "error" else "-"
                    if e == "cdd_float" and r["status"] == "error":
                        r["agree"] = "aborted (expected: float peer)"
                    elif r["status"] == "error":
                        mismatches.append(f"{scene}: {e} failed: {r.get('error', '')}")
                    continue
                if e == "brute_lp":
                    same = pat_ref is not None and r["patterns"] == pat_ref
                    r["agree"] = "-" if pat_ref is None else "yes" if same else "no"
                    if pat_ref is not None and not same:
                        mismatches.append(f"{scene}: brute_lp {len(r['patterns'])} patterns != the rays' "
                                          f"{len(pat_ref)}")
                    continue
                if ref_e is None or e == ref_e:
                    r["agree"] = "yes (reference)" if e == ref_e else "-"
                    continue
                diff = [k for k in ("n_wedged_rays", "n_cones", "fingerprint") if r[k] != ref[k]]
                if not diff:
                    r["agree"] = "yes"
                elif e == "cdd_float":
                    r["agree"] = "miscount (expected: float peer)"
                else:
                    r["agree"] = "no"
                    mismatches.append(f"{scene}: {e} != {ref_e} in {', '.join(diff)}")
        elif section == "3d":
            ref = next((g[e] for e in ("brute", "bnb", "bnb_sym") if g[e]["status"] == "ok"), None)
            for e, r in g.items():
                r["ratio"] = ratio(r, g["bnb_sym"]) if e != "bnb_sym" else "1"
                if r["status"] == "ok" and g["bnb_sym"].get("status") == "ok":
                    r["socp_ratio"] = f"{r['socps'] / max(g['bnb_sym']['socps'], 1):.3g}"
                if r["status"] != "ok":
                    r["agree"] = "-"
                    if r["status"] == "error":
                        mismatches.append(f"{scene}: {e} failed: {r.get('error', '')}")
                    continue
                same = r["patterns_digest"] == ref["patterns_digest"]
                r["agree"] = ("yes (reference)" if r is ref else "yes") if same else "no"
                if not same:
                    mismatches.append(f"{scene}: {e} {r['patterns']} patterns != {ref['engine']} {ref['patterns']}")
        else:       # mu^c: agreement = within its tolerance of the analytic value
            acc = g["accurate"]
            for e, r in g.items():
                r["ratio"] = ratio(r, acc) if e != "accurate" else "1"
                if r["status"] != "ok":
                    r["agree"] = "-"
                    if r["status"] == "error":
                        mismatches.append(f"mu^c {scene}: failed")
                    continue
                tol = 1e-9 if e == "accurate" else float(e.split()[-1])
                ok = r["rel_error"] is not None and r["rel_error"] <= tol
                if e == "accurate":
                    r["agree"] = "yes" if ok else "no"
                    if not ok:
                        mismatches.append(f"mu^c {scene}: accurate error {r['rel_error']} > 1e-9")
                else:       # the peer: whether bisection meets its own tolerance is its result
                    r["agree"] = "yes" if ok else "off (expected: peer error above its tol)"
    return mismatches


# --------------------------------------------------------------------------- output

def fmt(v) -> str:
    if v is None or v == "":
        return "-"
    return f"{v:.4f}" if v < 1 else f"{v:.2f}" if v < 100 else f"{v:.0f}"


def print_rec(r: dict) -> None:
    t, lower = _time(r)
    sec = (">" if lower else "") + fmt(t) + " s" if t is not None else r["status"]
    what = ""
    if r.get("status") == "ok":
        if r["section"] == "2d":
            what = (f"{r['n_wedged_rays']} rays, {r['n_cones']} cones" if "n_cones" in r
                    else f"{r['n_patterns']} patterns of {r['lps']}")
        elif r["section"] == "3d":
            what = f"{r['patterns']} patterns, {r['socps']} SOCPs"
        else:
            what = f"rel. error {r['rel_error']:.1e}, {r['solves']} solves"
    elif r.get("error"):
        what = r["error"].splitlines()[-1][:90]
    print(f"  {r['section']:>4} {r['scene']:<28} {r['engine']:<15} {sec:>11}  {what}", flush=True)


COLUMNS = ["section", "scene", "m", "engine", "status", "seconds", "ratio", "agree", "n_wedged_rays",
           "n_cones", "n_patterns", "socps", "socp_ratio", "rel_error", "mu", "note"]


def write(recs: list[dict], mismatches: list[str], out: str, meta: dict) -> None:
    os.makedirs(os.path.dirname(out) or ".", exist_ok=True)
    rows = []
    for r in recs:
        t, lower = _time(r)
        note = r.get("error", "").splitlines()[-1][:120] if r.get("error") else ""
        rows.append({**{k: r.get(k, "") for k in COLUMNS}, "seconds": "" if t is None else
                     (">" if lower else "") + f"{t:.6g}",
                     "n_patterns": r.get("n_patterns", r.get("patterns") if r["section"] == "3d" else ""),
                     "note": note})
    with open(out + ".csv", "w", newline="") as f:
        w = csv.DictWriter(f, COLUMNS)
        w.writeheader()
        w.writerows(rows)
    slim = [{k: v for k, v in r.items() if k != "patterns" or r["section"] == "3d"} for r in recs]
    from hpcwedge.environment import environment
    with open(out + ".json", "w") as f:
        json.dump({**meta, "mismatches": mismatches, "records": slim, "environment": environment()},
                  f, indent=1, default=str)


def table(recs: list[dict]) -> str:
    lines = []
    for section, engines, ref in (("2d", ENGINES_2D, "ours_float"), ("3d", ENGINES_3D, "bnb_sym"),
                                  ("mu_c", [n for n, _, _ in MUC_METHODS], "accurate")):
        rs = [r for r in recs if r["section"] == section]
        scenes = list(dict.fromkeys(r["scene"] for r in rs))
        lines.append(f"\n{section}: seconds (ratio = time / {ref}'s) [agreement]")
        w = 34 if section == "3d" else 24
        lines.append(f"{'scene':<30}{'m':>3} " + " ".join(f"{e:>{w}}" for e in engines))
        for s in scenes:
            g = {r["engine"]: r for r in rs if r["scene"] == s}
            m = next((r.get("m") for r in g.values() if r.get("m")), "")
            cells = []
            for e in engines:
                r = g.get(e, {})
                t, lower = _time(r)
                txt = (">" if lower else "") + fmt(t) if t is not None else r.get("status", "-")
                if r.get("ratio") and e != ref:
                    txt += f" ({r['ratio']}x)"
                if section == "3d" and r.get("socps"):
                    txt += f" {r['socps']} SOCPs"
                ag = r.get("agree", "-")
                txt += " " + {"yes": "Y", "yes (reference)": "R", "no": "N", "-": "-"}.get(ag, ag.split()[0][:5])
                cells.append(f"{txt:>{w}}")
            lines.append(f"{s:<30}{m!s:>3} " + " ".join(cells))
    lines.append("agreement: Y agrees, R the reference, N disagrees (a MISMATCH), abort / misco(unt) "
                 "the float peer's expected failures, - not compared")
    return "\n".join(lines)


def plot(recs: list[dict], path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.2), gridspec_kw={"width_ratios": [3, 1.2, 2.4]})
    marks = "osD^vP*X"
    for ax, (section, engines) in zip(axes, (("2d", ENGINES_2D), ("3d", ENGINES_3D),
                                            ("mu_c", [n for n, _, _ in MUC_METHODS]))):
        rs = [r for r in recs if r["section"] == section]
        scenes = list(dict.fromkeys(r["scene"] for r in rs))
        x = {s: i for i, s in enumerate(scenes)}
        for k, e in enumerate(engines):
            pts = [(x[r["scene"]], *_time(r)) for r in rs if r["engine"] == e]
            ok = [(i, t) for i, t, lb in pts if t is not None and not lb]
            cut = [(i, t) for i, t, lb in pts if t is not None and lb]
            bad = [x[r["scene"]] for r in rs if r["engine"] == e and r.get("status") == "error"]
            line, = ax.plot([p[0] for p in ok], [max(p[1], 1e-5) for p in ok], marks[k], ls="none",
                            label=e, alpha=0.85)
            if cut:
                ax.plot([p[0] for p in cut], [p[1] for p in cut], ls="none", marker="$\\uparrow$",
                        ms=13, color=line.get_color())
            if bad:
                ax.plot(bad, [1e-4] * len(bad), ls="none", marker="x", ms=10, color=line.get_color())
        ax.set_yscale("log")
        ax.set_xticks(range(len(scenes)))
        ax.set_xticklabels(scenes, rotation=60, ha="right", fontsize=7)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
        ax.set_ylabel("seconds")
    axes[0].set_title("2D enumeration (↑ timed out, × aborted at 1e-4 s)", fontsize=9)
    axes[1].set_title("3D patterns, mu = 1", fontsize=9)
    axes[2].set_title("one mu^c: bisection vs accurate (best of 3)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller scenes and limits (~2 min)")
    ap.add_argument("--out", default=None, help="prefix (default results/bench_peers, --quick: ..._quick)")
    ap.add_argument("--worker", nargs="+", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        worker_main(args.worker)
        return 0
    try:
        import cdd  # noqa: F401  (the peers run in subprocesses; check once here)
    except ImportError:
        print(bench_2d.CDD_HELP, file=sys.stderr)
        return 3
    out = args.out or os.path.join(ROOT, "results", "bench_peers_quick" if args.quick else "bench_peers")
    lim = limits(args.quick)
    t0 = time.perf_counter()
    print(f"bench_peers: {'quick' if args.quick else 'full'} run, limits {lim}")
    recs = measure_2d(args.quick, lim) + measure_3d(args.quick, lim) + measure_muc(args.quick, lim)
    mismatches = judge(recs)
    total = time.perf_counter() - t0
    write(recs, mismatches, out, {"quick": args.quick, "limits": lim, "total_seconds": total,
                                  "command": "PYTHONPATH=. python scripts/bench_peers.py"
                                  + (" --quick" if args.quick else "")})
    plot(recs, out + ".png")
    print(table(recs))
    print(f"\nwrote {out}.csv, {out}.json, {out}.png ({total:.0f} s)")
    if mismatches:
        print("\n" + "\n".join(f"MISMATCH {s}" for s in mismatches), file=sys.stderr)
        return 1
    print("every engine that must agree agrees")
    return 0


if __name__ == "__main__":
    sys.exit(main())
