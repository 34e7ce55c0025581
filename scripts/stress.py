#!/usr/bin/env python3
"""Numerical stress grid (issue 4, deliverable 3; SPEC §7): float against exact arithmetic.

    scripts/stress.py [--quick] [--out DIR] [--family NAME ...]

Every case is one 2D scene at one mu, run through run_scene() three times:

  float     the default float pipeline (rays, cones, global mu^c), with whatever
            run-time checks and fallbacks it applies (stats["numerics"]);
  raw       the float pipeline with the exact fallback switched off
            (compute.exact_fallback_max_m = 0): shows what the float engine alone
            decides and whether its run-time detection flagged the case;
  exact     compute.exact = true: the double description in rational arithmetic
            on the same (float) stiffness, the reference for the counts;

and once more with enumerate = "patterns" (float LP branch and bound) for the sign
patterns, compared with the patterns the exact rays imply (SPEC §2: (C, G) is feasible
iff a wedged ray has supp(r_n) in C and supp(u_n) in G).

mu^c error: against the analytic value where there is one (any free body in the
plug's symmetric taper: tan(taper); the V groove: tan θ + eps / (k sin 2θ)), else
against the exact route's mu^c; "bracket" checks the float global mu^c with exact
arithmetic: no wedged ray at mu^c (1 - 1e-8), some at mu^c (1 + 1e-8).

Families (the varied parameter in brackets):
  contrast   plug truss, diagonals' EA against the other bars' (1e-8 .. 1e8); V groove bar
             against its ground springs (k / eps = 1 .. 1e8)
  taper      plug2d taper 10° .. 0.1° at mu = 1.5 tan(taper)
  block2d    plane-stress plug, each element refined 1 .. 32 times (PETSc condensation)
  near_mu_c  mu = mu^c (1 ± delta), delta = 1e-3 .. 1e-9, for the global critical cone
             (taper 10° and 1°) and for another cone
  support    free plug truss against the same truss held by three ground bars of EA
             1e-8 .. 1, and pinned
  size       plug2d m = 4 .. 10 (quick: .. 8) at mu = 0.65, random raw stiffness matrices
             (supported and free)
  rotation   the plug truss in a randomly rotated global frame (the answer must equal
             the unrotated exact answer)
  large      plug2d m = 12, 16 (quick: 12), taper 10° at mu = 0.65, 0.1° at 1.5 tan(taper), 1°
             at mu^c (1 + 1e-9): beyond compute.exact_fallback_max_m and beyond exact
             arithmetic's reach here, so no reference — shows what is flagged and reported

Writes DIR/stress.csv and DIR/stress.json (default DIR = results/), prints a summary.
Exit status 1 if any row has a problem (see `problems`): a count that differs from exact
arithmetic after the pipeline's own fallbacks, a raw float mismatch that went undetected,
a rotation that changes the answer, or a mu^c off by more than 1e-9 with no note.
"""
from __future__ import annotations

import argparse
import csv
import math
import os
import sys
import time
from dataclasses import dataclass, field

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [ROOT, os.path.join(ROOT, "tests")]

from harness import write_json  # noqa: E402
from instances import random_problem  # noqa: E402  (tests/)

from hpcwedge.contact.problem import friction_rows_2d, parametrize  # noqa: E402
from hpcwedge.models.library import plug2d  # noqa: E402
from hpcwedge.rays.cones import implied_patterns  # noqa: E402
from hpcwedge.rays.dd import complementary_rays  # noqa: E402
from hpcwedge.run.pipeline import run_scene  # noqa: E402
from hpcwedge.scene.parse import parse_scene  # noqa: E402

BRACKET_RTOL = 1e-8
MU = 0.65


@dataclass
class Case:
    """One stress case: a scene (without its compute table) at one mu.

    mu_c_ref: analytic global mu^c, or None (then the exact route's is the reference).
    same_as: label of a case whose exact answer this one must reproduce (rotations).
    exact: run the exact reference (false where m is too large for it: detection only)."""

    family: str
    param: str
    scene: dict
    mu: float
    mu_c_ref: float | None = None
    same_as: str | None = None
    bracket: bool = True
    exact: bool = True
    label: str = field(init=False)

    def __post_init__(self):
        self.label = f"{self.family}:{self.param}"


# ------------------------------------------------------------------ scenes

def plug_truss(rows: int, taper: float = 10.0, ea_diag: float = 1.0, angle_deg: float = 0.0,
               ground: float | None = None, pinned: bool = False, ea: float = 1.0) -> dict:
    """The plug2d truss (cols 3) as a `truss` scene: diagonals of EA ea * ea_diag, the other
    bars EA ea; optionally held by three ground bars of EA `ground` (supported ground nodes) or
    pinned (interior middle-column nodes supported), the whole frame rotated by angle_deg."""
    mdl = plug2d(rows, 3, taper)
    X = mdl.coords.copy()
    bars = mdl.cells["line"].tolist()
    n_axis = rows * 2 + (rows - 1) * 3            # row and column bars come first (_grid_bars)
    EA = [float(ea)] * n_axis + [float(ea * ea_diag)] * (len(bars) - n_axis)
    supports = []
    bottom, top = 1, (rows - 1) * 3 + 1           # middle-column nodes
    if ground is not None:
        g0 = len(X)
        X = np.vstack([X, [[0.0, -0.5], [-0.5, 1.0], [0.5, -0.3]]])    # below, left of top, right below
        bars += [[bottom, g0], [top, g0 + 1], [bottom, g0 + 2]]
        EA += [float(ea * ground)] * 3
        supports = [[g, c] for g in (g0, g0 + 1, g0 + 2) for c in (0, 1)]
    if pinned:
        supports = [[bottom, 0], [bottom, 1], [top, 0]]
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    Rot = np.array([[c, -s], [s, c]])
    model = {"kind": "truss", "nodes": (X @ Rot.T).tolist(), "bars": bars, "EA": EA,
             "supports": supports}
    contact = {"nodes": mdl.contact_nodes.tolist(), "normals": (mdl.normals @ Rot.T).tolist()}
    return {"model": model, "contact": contact}


def builtin(kind: str, **params) -> dict:
    """The model table of a built-in scene."""
    return {"model": {"kind": kind, **params}}


def raw_stiffness(seed: int, m: int, free: bool) -> dict:
    """A `stiffness` scene of the tests' random problem (tests/instances.py) for seed."""
    prob = random_problem(np.random.default_rng(seed), m, free)
    model = {"kind": "stiffness", "K": prob.K.tolist()}
    if free:
        model["null_space"] = prob.N.tolist()
    return {"model": model}


def tan(deg: float) -> float:
    """tan of an angle in degrees (the plug's analytic mu^c)."""
    return math.tan(math.radians(deg))


def cone_mu_c(spec: dict, mu: float) -> list[float]:
    """Sorted distinct mu^c of the cones found at mu (float pipeline)."""
    res = run_scene(_scene(spec, mu, {"mu_c": "cones"}))
    return sorted({c.mu_c for c in res.runs[0].cones if c.mu_c is not None})


def cases(quick: bool, families: set[str] | None = None) -> list[Case]:
    """The grid (quick: a subset, < 3 minutes in all)."""
    rows = 4                                           # m = 8: exact DD in ~1 s
    out: list[Case] = []
    want = (lambda f: families is None or f in families)
    if want("contrast"):
        exps = (-8, -4, 0, 4, 8) if quick else (-8, -6, -4, -2, 0, 2, 4, 6, 8)
        for e in exps:
            out.append(Case("contrast", f"plug truss EA_diag=1e{e}", plug_truss(rows, ea_diag=10.0 ** e),
                            MU, tan(10.0)))
        for e in ((0, 4, 8) if quick else (0, 2, 4, 6, 8)):
            eps, k, th = 10.0 ** -e, 0.5, 30.0
            want_mu = tan(th) + eps / (k * math.sin(2 * math.radians(th)))
            out.append(Case("contrast", f"vgroove k/eps=1e{e}", builtin("vgroove_bar", theta_deg=th, eps=eps),
                            1.2 * want_mu, want_mu))
    if want("taper"):
        for t in ((10.0, 1.0, 0.1) if quick else (10.0, 5.0, 3.0, 1.0, 0.3, 0.1)):
            out.append(Case("taper", f"taper={t:g}", builtin("plug2d", rows=rows, taper_deg=t),
                            1.5 * tan(t), tan(t)))
    if want("block2d"):
        for r in ((1, 4, 16) if quick else (1, 2, 4, 8, 16, 32)):
            out.append(Case("block2d", f"refine={r}", builtin("block2d", rows=3, cols=2, refine=r),
                            MU, tan(10.0)))
    if want("near_mu_c"):
        deltas = (1e-3, 1e-6, 1e-9) if quick else (1e-3, 1e-5, 1e-7, 1e-9)
        for t in ((1.0,) if quick else (10.0, 1.0)):
            spec = builtin("plug2d", rows=rows, taper_deg=t)
            for dl in deltas:
                for sign in (1, -1):
                    out.append(Case("near_mu_c", f"taper={t:g} global cone {sign * dl:+g}", spec,
                                    tan(t) * (1 + sign * dl), tan(t), bracket=False))
        spec = builtin("plug2d", rows=rows, taper_deg=10.0)
        others = [v for v in cone_mu_c(spec, MU) if v > 1.01 * tan(10.0)]
        if others:
            mc = others[-1]
            for dl in deltas:
                for sign in (1, -1):
                    out.append(Case("near_mu_c", f"taper=10 cone mu_c={mc:.6g} {sign * dl:+g}", spec,
                                    mc * (1 + sign * dl), tan(10.0), bracket=False))
    if want("support"):
        out.append(Case("support", "free", plug_truss(rows), MU, tan(10.0)))
        out.append(Case("support", "pinned", plug_truss(rows, pinned=True), MU))
        for e in ((0, -8) if quick else (0, -2, -4, -6, -8)):
            out.append(Case("support", f"ground EA=1e{e}", plug_truss(rows, ground=10.0 ** e), MU))
    if want("size"):
        for r in ((2, 3, 4) if quick else (2, 3, 4, 5)):
            out.append(Case("size", f"plug2d m={2 * r}", builtin("plug2d", rows=r), MU, tan(10.0)))
        for seed in ((0, 1) if quick else (0, 1, 2, 3)):
            for free in (False, True):
                out.append(Case("size", f"random m=5 {'free' if free else 'supported'} seed={seed}",
                                raw_stiffness(seed, 5, free), 0.8, bracket=False))
    if want("large"):          # beyond the exact fallback (m > 10): detection only, no reference
        for r in ((6,) if quick else (6, 8)):
            for t, mu in ((10.0, MU), (0.1, 1.5 * tan(0.1)), (1.0, tan(1.0) * (1 + 1e-9))):
                out.append(Case("large", f"plug2d m={2 * r} taper={t:g}", builtin("plug2d", rows=r, taper_deg=t),
                                mu, tan(t), bracket=False, exact=False))
    if want("rotation"):
        base = "rotation:angle=0"
        out.append(Case("rotation", "angle=0", plug_truss(rows), MU, tan(10.0)))
        rng = np.random.default_rng(4)
        for a in rng.uniform(0, 360, size=3 if quick else 8):
            out.append(Case("rotation", f"angle={a:.4f}", plug_truss(rows, angle_deg=a), MU, tan(10.0),
                            same_as=base))
    return out


# ------------------------------------------------------------------ runs

def _scene(spec: dict, mu: float, compute: dict):
    """The Scene of a case's tables at one mu, with these compute keys (default: rays,
    cones and the global mu^c)."""
    data = {"name": "stress", "dim": 2, **spec, "friction": {"mu": [mu]},
            "compute": {"enumerate": True, "mu_c": "global", **compute}}
    return parse_scene(data)


def _answer(res) -> dict:
    """Counts and zero-set keys of a run_scene result (one mu)."""
    run = res.runs[0]
    zero = run.ray_zero if run.ray_zero is not None else np.zeros((0, 3 * res.m), dtype=bool)
    cones = sorted((tuple(c.zero_u), tuple(c.zero_r)) for c in run.cones or [])
    return {"rays": run.n_wedged_rays, "trivial": run.n_trivial_rays, "cones": run.n_cones,
            "ray_keys": sorted(np.packbits(z).tobytes().hex() for z in zero), "cone_keys": cones,
            "mu_c": res.mu_c, "numerics": res.stats.get("numerics", {})}


def _timed(fn):
    """(fn(), seconds)."""
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def _wedged_exact(spec: dict, mu: float) -> int:
    """Wedged rays at mu by the exact DD (for the mu^c bracket)."""
    from hpcwedge.contact.build import contact_problem
    prob = contact_problem(_scene(spec, mu, {}))
    p = parametrize(prob, exact=True)
    return int(complementary_rays(friction_rows_2d(p, mu, prob.m, exact=True), prob.m, exact=True)
               .wedged().sum())


def run_case(case: Case, exact_answers: dict) -> dict:
    """One row of the table (see the module doc). Without an exact reference (case.exact
    false: m too large) the exact columns and the mismatch flags are None."""
    fl, t_float = _timed(lambda: run_scene(_scene(case.scene, case.mu, {})))
    raw, t_raw = _timed(lambda: run_scene(_scene(case.scene, case.mu, {"exact_fallback_max_m": 0})))
    pat, t_pat = _timed(lambda: run_scene(_scene(case.scene, case.mu, {"enumerate": "patterns",
                                                                      "mu_c": "none"})))
    m = fl.m
    F, R = _answer(fl), _answer(raw)
    float_pats = {tuple(p.contact) for p in pat.runs[0].patterns}
    row = {"family": case.family, "parameter": case.param, "m": m, "mu": case.mu,
           "float_rays": F["rays"], "float_cones": F["cones"], "float_patterns": len(float_pats),
           "raw_rays": R["rays"], "raw_cones": R["cones"],
           "raw_flagged": bool(R["numerics"].get("flagged")),
           "fallback": bool(F["numerics"].get("exact_fallback")),
           "unresolved": bool(F["numerics"].get("unresolved")),
           "patterns_undecided": pat.stats.get("patterns_undecided", 0),
           "mu_c": F["mu_c"], "t_float": t_float, "t_raw": t_raw, "t_patterns": t_pat,
           "numerics": F["numerics"], "raw_numerics": R["numerics"],
           "patterns_numerics": pat.stats["numerics"].get("patterns")}
    E = None
    if case.exact:
        ex, row["t_exact"] = _timed(lambda: run_scene(_scene(case.scene, case.mu, {"exact": True})))
        E = exact_answers[case.label] = _answer(ex)
        exact_pats = implied_patterns(ex.runs[0].ray_zero, m)
        row.update(exact_rays=E["rays"], exact_cones=E["cones"], exact_patterns=len(exact_pats),
                   mismatch=_differs(F, E) or float_pats != exact_pats,
                   pattern_mismatch=float_pats != exact_pats, raw_mismatch=_differs(R, E))
    ref = exact_answers.get(case.same_as) if case.same_as else None
    row["rotation_mismatch"] = (_differs(E, ref) or _differs(F, ref)) if ref is not None else None
    mu_c_ref, kind = (case.mu_c_ref, "analytic") if case.mu_c_ref is not None else \
        ((E["mu_c"], "exact") if E else (None, None))
    row.update(mu_c_ref=mu_c_ref, mu_c_ref_kind=kind,
               mu_c_err=abs(F["mu_c"] - mu_c_ref) / mu_c_ref if F["mu_c"] is not None and mu_c_ref else None)
    row["mu_c_exact_bracket"] = None
    if case.bracket and case.exact and F["mu_c"] is not None:
        row["mu_c_exact_bracket"] = (_wedged_exact(case.scene, F["mu_c"] * (1 - BRACKET_RTOL)) == 0
                                     and _wedged_exact(case.scene, F["mu_c"] * (1 + BRACKET_RTOL)) > 0)
    return row


def _differs(a: dict, b: dict) -> bool:
    """Do two answers differ in a count or a zero set?"""
    keys = ("rays", "cones", "ray_keys", "cone_keys")
    return tuple(a[k] for k in keys) != tuple(b[k] for k in keys)


CSV_COLS = ["family", "parameter", "m", "mu", "float_rays", "exact_rays", "raw_rays", "float_cones",
            "exact_cones", "raw_cones", "float_patterns", "exact_patterns", "mismatch", "pattern_mismatch",
            "raw_mismatch", "raw_flagged", "fallback", "unresolved", "patterns_undecided",
            "rotation_mismatch", "mu_c", "mu_c_ref", "mu_c_ref_kind", "mu_c_err", "mu_c_exact_bracket",
            "t_float", "t_raw", "t_exact", "t_patterns"]


def write(rows: list[dict], out_dir: str, meta: dict) -> None:
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, "stress.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_COLS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    write_json(os.path.join(out_dir, "stress.json"), {"meta": meta, "cases": rows}, default=_plain)


def _plain(o):
    """JSON for numpy scalars, arrays and tuples."""
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, tuple):
        return list(o)
    raise TypeError(type(o))


MU_C_RTOL = 1e-9      # SPEC §2


def problems(r: dict) -> list[str]:
    """What is wrong with a row: a count differing from exact arithmetic (after the
    pipeline's fallbacks), a raw float mismatch the run-time checks did not flag, a rotated
    answer differing from the unrotated one, a mu^c off by more than MU_C_RTOL or outside
    the exact bracket without a note in stats.numerics."""
    out = []
    if r.get("mismatch"):
        out.append("count differs from exact")
    if r.get("raw_mismatch") and not r["raw_flagged"]:
        out.append("raw float mismatch not flagged")
    if r.get("rotation_mismatch"):
        out.append("rotation changes the answer")
    noted = bool(r["numerics"].get("notes"))
    if not noted and ((r["mu_c_err"] or 0) > MU_C_RTOL or r["mu_c_exact_bracket"] is False):
        out.append(f"mu^c error {r['mu_c_err']:.1e} (bracket {r['mu_c_exact_bracket']})")
    return out


def summary(rows: list[dict]) -> tuple[str, bool]:
    """Per-family lines and the verdict: ok when no row has problems()."""
    def n(rs, key):
        return sum(bool(r.get(key)) for r in rs)
    lines = []
    for fam in dict.fromkeys(r["family"] for r in rows):
        rs = [r for r in rows if r["family"] == fam]
        errs = [r["mu_c_err"] for r in rs if r["mu_c_err"] is not None]
        br = [r for r in rs if r["mu_c_exact_bracket"] is not None]
        ex = [r for r in rs if "exact_rays" in r]
        lines.append(
            f"{fam:10s} cases {len(rs):3d} (exact {len(ex):2d})  mismatches {n(rs, 'mismatch'):2d}"
            f" (patterns {n(rs, 'pattern_mismatch')})  raw float mismatches {n(rs, 'raw_mismatch'):2d}"
            f" (flagged {sum(bool(r.get('raw_mismatch')) and r['raw_flagged'] for r in rs)})"
            f"  flagged {n(rs, 'raw_flagged'):2d}  exact fallbacks {n(rs, 'fallback'):2d}"
            f"  unresolved {n(rs, 'unresolved'):2d}"
            f"  max mu_c err {max(errs) if errs else float('nan'):.1e}"
            f"  bracket ok {sum(bool(r['mu_c_exact_bracket']) for r in br)}/{len(br)}"
            + (f"  rotation mismatches {n(rs, 'rotation_mismatch')}" if fam == "rotation" else ""))
        for r in rs:
            for what in problems(r):
                lines.append(f"  PROBLEM {r['parameter']} mu={r['mu']:.10g}: {what} (float "
                             f"{r['float_rays']}/{r['float_cones']}/{r['float_patterns']}, raw "
                             f"{r['raw_rays']}/{r['raw_cones']}, exact {r.get('exact_rays')}/"
                             f"{r.get('exact_cones')}/{r.get('exact_patterns')})")
    return "\n".join(lines), not any(problems(r) for r in rows)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a subset (< 3 minutes)")
    ap.add_argument("--out", default=os.path.join(ROOT, "results"))
    ap.add_argument("--family", action="append", help="only these families (repeatable)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    grid = cases(args.quick, set(args.family) if args.family else None)
    rows, exact_answers = [], {}
    for k, case in enumerate(grid):
        row = run_case(case, exact_answers)
        rows.append(row)
        flag = ", ".join(problems(row)) or ("flagged" if row["raw_flagged"] else "")
        print(f"[{k + 1}/{len(grid)}] {case.label} mu={case.mu:.10g}: rays/cones/patterns float "
              f"{row['float_rays']}/{row['float_cones']}/{row['float_patterns']} exact "
              f"{row.get('exact_rays')}/{row.get('exact_cones')}/{row.get('exact_patterns')}"
              f" ({row['t_float']:.1f} s) {flag}", flush=True)
    text, ok = summary(rows)
    meta = {"quick": args.quick, "seconds": time.perf_counter() - t0, "cases": len(rows), "ok": ok,
            "command": " ".join(["scripts/stress.py"] + sys.argv[1:])}
    write(rows, args.out, meta)
    print(text)
    print(f"{len(rows)} cases in {meta['seconds']:.0f} s: " + (
        "no count differs from exact arithmetic, every suspect run flagged, every mu^c within "
        f"{MU_C_RTOL:g} or noted" if ok else "PROBLEMS (see above)"))
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
