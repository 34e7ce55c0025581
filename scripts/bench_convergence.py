#!/usr/bin/env python3
"""Mesh convergence of mu^c (issue 5): block2d, rows = 5 (m = 12 contact nodes),
each coarse element refined r x r times inside (r = 1, 2, 4, 8, 16 by default).

For every refinement: the condensed stiffness, the wedged rays and cones at one
mu, the mu^c of each cone and the global mu^c. Cones are matched across
refinements by their zero sets (a cone that exists at one refinement and not at
another is listed with a gap). Writes results/bench_convergence.{csv,json,png}
and prints the table with the change of each cone's mu^c from one refinement to
the next (it must settle: the interior refinement changes K by less and less).

--patch a (> 0): every contact node carries a rigid foot of half-width a (scene key
model.contact_patch, models/patch.py), so the contact is not a point load and the
condensed stiffness has a limit under refinement; writes
results/bench_convergence_patch.{csv,json,png} instead.

    PYTHONPATH=. .venv/bin/python scripts/bench_convergence.py [--refine 1 2 4 8 16] [--mu 0.65] [--patch 0.1]
"""
from __future__ import annotations

import argparse
import os
import time

from harness import OK, RESULTS, run_call, write_csv, write_json

from hpcwedge.models.patch import boundary_nodes, patch_slaves
from hpcwedge.run.pipeline import run_scene
from hpcwedge.scene.parse import parse_scene

OUT = RESULTS


def cones_at(refine: int, mu: float, rows: int, patch: float = 0.0, kind: str = "rigid") -> dict:
    """{"dofs", "seconds", "mu_c", "cones": {zero-set key: mu^c}} of block2d at one refinement
    (patch > 0: contact patches of that half-width): a case, run in a child (harness.run_call)."""
    model = {"kind": "block2d", "rows": rows, "refine": refine}
    if patch > 0:
        model["contact_patch"] = patch
        model["contact_patch_kind"] = kind
    scene = parse_scene({"name": f"block2d-r{refine}", "dim": 2, "friction": {"mu": [mu]}, "model": model,
                         "compute": {"enumerate": True, "mu_c": "cones"}})
    t = time.perf_counter()
    res = run_scene(scene)
    sec = time.perf_counter() - t
    cones = {f"u{c.zero_u} r{c.zero_r}": c.mu_c for c in res.runs[0].cones}
    return {"refine": refine, "dofs": int(res.model.K.shape[0]), "m": res.m, "seconds": sec,
            "patch_nodes": patch_nodes(res.model, patch),
            "mu_c": res.mu_c, "n_rays": res.runs[0].n_wedged_rays, "cones": cones}


def patch_nodes(model, a: float) -> int:
    """Boundary nodes in the contact patches besides the contact nodes (0 for point contacts)."""
    if a == 0:
        return 0
    slaves = patch_slaves(model.coords, boundary_nodes(model.cells, len(model.coords)), model.contact_nodes, a)
    return int(sum(len(s) for s in slaves))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--refine", type=int, nargs="+", default=[1, 2, 4, 8, 16])
    ap.add_argument("--rows", type=int, default=5)
    ap.add_argument("--mu", type=float, default=0.65)
    ap.add_argument("--patch", type=float, default=0.0,
                    help="contact patch half-width a (model.contact_patch); 0 = point contacts")
    ap.add_argument("--patch-kind", choices=["rigid", "hat"], default="rigid",
                    help="model.contact_patch_kind (results/bench_convergence_patch[_hat].*)")
    ap.add_argument("--limit", type=float, default=None, help="seconds per refinement level (default: none)")
    args = ap.parse_args()
    stem = ("bench_convergence" if args.patch == 0 else
            "bench_convergence_patch" + ("_hat" if args.patch_kind == "hat" else ""))
    levels = []
    for r in args.refine:
        case = run_call(cones_at, r, args.mu, args.rows, args.patch, args.patch_kind, limit=args.limit)
        if case["status"] != OK:
            print(f"refine {r:3d}: {case['status']} after {case['seconds']} s {case.get('error', '')}", flush=True)
            continue
        levels.append(case["value"])
        lv = levels[-1]
        print(f"refine {r:3d}: {lv['dofs']:8d} DOFs, {lv['patch_nodes']:4d} patch nodes, "
              f"{lv['n_rays']:6d} wedged rays, {len(lv['cones']):3d} cones, "
              f"global mu^c {lv['mu_c']:.12f}  ({lv['seconds']:.1f} s)", flush=True)
    keys = sorted({k for lv in levels for k in lv["cones"]},
                  key=lambda k: min(lv["cones"].get(k, 9e9) for lv in levels))
    rows = []
    for k in keys:
        vals = [lv["cones"].get(k) for lv in levels]
        row = {"cone": k}
        for lv, v in zip(levels, vals):
            row[f"r{lv['refine']}"] = v
        known = [(lv["refine"], v) for lv, v in zip(levels, vals) if v is not None]
        row["last_change_rel"] = (abs(known[-1][1] - known[-2][1]) / known[-1][1]) if len(known) > 1 else None
        # relative change from each level to the next (None across a gap)
        row["changes_rel"] = [abs(b - a) / abs(b) if a is not None and b is not None else None
                              for a, b in zip(vals, vals[1:])]
        rows.append(row)
    fields = ["cone"] + [f"r{lv['refine']}" for lv in levels] + ["last_change_rel"]
    write_csv(os.path.join(OUT, stem + ".csv"), rows, fields)
    write_json(os.path.join(OUT, stem + ".json"), {"rows_model": args.rows, "mu": args.mu, "contact_patch": args.patch,
                                                   "contact_patch_kind": args.patch_kind, "levels": levels,
                                                   "cones": rows})
    plot(levels, rows, stem, args.patch, args.patch_kind)
    print(f"\n{'cone (zero sets)':<44}" + "".join(f"{'r=' + str(lv['refine']):>15}" for lv in levels)
          + f"{'last change':>13}")
    for row in rows:
        cells = [row[f"r{lv['refine']}"] for lv in levels]
        vals = "".join(f"{v:>15.10f}" if v is not None else f"{'-':>15}" for v in cells)
        ch = row["last_change_rel"]
        print(f"{row['cone'][:43]:<44}{vals}{(f'{ch:13.2e}' if ch is not None else '-'):>13}")
    print("\nrelative change per doubling:")
    for row in rows:
        print(f"{row['cone'][:43]:<44}" + "".join(f"{c:>11.2e}" if c is not None else f"{'-':>11}"
                                                  for c in row["changes_rel"]))
    print(f"wrote results/{stem}.{{csv,json,png}}")


def plot(levels: list[dict], rows: list[dict], stem: str, patch: float, kind: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    refs = [lv["refine"] for lv in levels]
    for row in rows:
        pts = [(r, row[f"r{r}"]) for r in refs if row[f"r{r}"] is not None]
        ax.semilogx([p[0] for p in pts], [p[1] for p in pts], "o-", lw=1, ms=4)
    ax.set_xscale("log", base=2)
    ax.set_xlabel("interior refinement r (each coarse element split r x r)")
    ax.set_ylabel("mu^c of the cone")
    ax.set_title("block2d rows = 5: mu^c of each cone against refinement"
                 + (f"\n{kind} contact patches of half-width a = {patch:g}" if patch > 0 else ""))
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, stem + ".png"), dpi=120)


if __name__ == "__main__":
    main()
