#!/usr/bin/env python3
"""The 3D global mu^c against brute force on random small bodies where elasticity sets it
(SPEC §7: stress tests of numerical stability, an independent route for every answer).

    PYTHONPATH=. python scripts/stress_global_3d.py [--cases 60] [--first 0] [--limit 300]
                                                    [--out results/stress_global_3d]

Case k is drawn from seed 1000 + k. When 3 divides k: a random free body given by its
stiffness (`model.kind = "stiffness"` with its rigid modes as `null_space`: a stiffness from
another FE code; tests/instances.py's random_problem_3d, m = 5 to 8, contact frames and
compliance random, rigid motions up to ~1e4 times the reactions). Else its curved neck:
2 or 3 levels of 3 to 5 ring nodes, 0 to 2 contact nodes dropped (more where needed for m <= 10),
wall angle 0.5 to 15 deg at the foot, flare 0 to 0.8, bar stiffness spread 0 to 2
(log-normal), ring jitter up to 0.45 of a step. All are free bodies without symmetry, where
elasticity, not the rigid bound, sets mu^c.
Each case runs in its own process (harness.run_call, killed at --limit seconds):
  ours   `hpcwedge run`'s route (pipeline.run_scene; compute.mu_c = "global", mu_max =
         MU_MAX): its mu^c, and whether it is certified (no mu^c value unpolished, no
         settled pattern without a value)
  brute  each of the 2^m partitions decided at MU_MAX (one SOCP each,
         reference.brute_force_patterns) and each feasible one's mu^c (mu_critical): the
         least polished (certified) value and the least of all values
Verdict: "agree" (ours certified and within 1e-9 of brute force's least polished value),
"brute unpolished" (ours certified, below every polished value of brute force and within 1e-6
of its least value, which brute force's own mu^c computation left unpolished: the start of a
pattern's polish differs between the routes), "flagged" (ours not certified, within 1e-6 of
either: the run says so), "wrong" (anything else: a certified value off by more than 1e-9,
or any value off by more than 1e-6), "none" (both find no wedge up to MU_MAX), or the
case's own status ("timeout", "error"). Also per case:
m, the feasible patterns, how many brute-force values are unpolished and whether one lies
below the least polished value (an uncertified value that a min over patterns would take).
Writes <out>.csv and <out>.json (with the environment record and the verdict counts) after
every case; prints a line per case and the counts; exit status 1 when a case is "wrong".
"""
from __future__ import annotations

import argparse
import collections
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import bench_2d  # noqa: E402
from harness import OK, run_call, write_records  # noqa: E402

#: largest mu searched, by both routes
MU_MAX = 5.0
#: relative agreement of a certified answer, and of a flagged one
CERTIFIED_RTOL = 1e-9
FLAGGED_RTOL = 1e-6


def case_scene(k: int) -> dict:
    """Scene data of case k (module doc), drawn from seed 1000 + k: a random stiffness when
    3 divides k, else a curved neck."""
    import numpy as np
    sys.path.insert(0, os.path.join(bench_2d.ROOT, "tests"))
    from instances import curved_neck, random_problem_3d
    rng = np.random.default_rng(1000 + k)
    compute = {"enumerate": False, "mu_c": "global", "mu_max": MU_MAX}
    if k % 3 == 0:
        m = int(rng.integers(5, 9))
        prob = random_problem_3d(rng, m, free=True)
        return {"name": f"random-{k}", "dim": 3, "model": {"kind": "stiffness", "K": prob.K.tolist(),
                "null_space": prob.N.tolist()}, "friction": {"mu": [MU_MAX]}, "compute": compute,
                "run": {"symmetry": False}}
    levels, ring = int(rng.integers(2, 4)), int(rng.integers(3, 6))
    drop = max(int(rng.integers(0, 3)), levels * ring - 10)
    data = curved_neck(levels, ring, k, taper_deg=float(rng.uniform(0.5, 15)), bend=float(rng.uniform(0, 0.8)),
                       stiffness_spread=float(rng.uniform(0, 2)), jitter=float(rng.uniform(0, 0.45)), drop=drop)
    data.update(compute=compute, friction={"mu": [MU_MAX]})
    return data


def ours(k: int) -> dict:
    """`hpcwedge run`'s global mu^c of case k and whether it is certified."""
    from hpcwedge.run.pipeline import run_scene
    from hpcwedge.scene.parse import parse_scene
    res = run_scene(parse_scene(case_scene(k)))
    st = res.stats
    bnb = st.get("bnb") or {}
    return {"m": res.m, "mu_c": res.mu_c, "status": res.mu_c_status, "unpolished": int(st.get("mu_c_unpolished", 0)),
            "unsettled": int(bnb.get("unsettled", 0)), "nodes": int(bnb.get("nodes", 0)),
            "seconds": res.timings.get("total")}


def brute(k: int) -> dict:
    """Brute force over case k's partitions (module doc)."""
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.contact.problem import parametrize
    from hpcwedge.mu_c.critical import mu_critical
    from hpcwedge.reference import brute_force_patterns, contact_mask
    from hpcwedge.scene.parse import parse_scene
    prob = contact_problem(parse_scene(case_scene(k)))
    param, m = parametrize(prob), prob.m
    polished, unpolished = [], []
    for bits in brute_force_patterns(param, m, MU_MAX):
        zu = contact_mask(bits, m)
        r = mu_critical(param, m, zu, ~zu, mu_hi=MU_MAX, mu_max=MU_MAX)
        if r.mu_c is not None:
            (polished if r.polished else unpolished).append(r.mu_c)
    least = min(polished, default=None)
    return {"patterns": len(polished) + len(unpolished), "least_polished": least,
            "least_any": min(polished + unpolished, default=None), "brute_unpolished": len(unpolished),
            "unpolished_below": bool(least is not None and unpolished and min(unpolished) < least * (1 - CERTIFIED_RTOL))}


def verdict(o: dict, b: dict) -> tuple[str, float | None]:
    """(verdict, relative error of ours against the brute-force value it is judged by): brute
    force's least polished value, or its least value when that is unpolished (module doc)."""
    mu, want, least = o["mu_c"], b["least_polished"], b["least_any"]
    if mu is None or least is None:
        return ("none" if mu is None and least is None else "wrong"), None
    certified = o["unpolished"] == 0 and o["unsettled"] == 0
    rtol = CERTIFIED_RTOL if certified else FLAGGED_RTOL
    if want is not None and abs(mu - want) <= rtol * want:
        return ("agree" if certified else "flagged"), (mu - want) / want
    if least < (want if want is not None else math.inf) and abs(mu - least) <= FLAGGED_RTOL * least:
        # brute force's least value is unpolished: ours lies near it, below every polished value
        return ("brute unpolished" if certified else "flagged"), (mu - least) / least
    return "wrong", (mu - (want if want is not None else least)) / (want if want is not None else least)


def run_case(k: int, limit: float) -> dict:
    """Both routes of case k, each in its own process: one record."""
    rec = {"case": k}
    for name, fn in (("ours", ours), ("brute", brute)):
        got = run_call(fn, k, limit=limit)
        if got["status"] != OK:
            rec.update(verdict=got["status"], error=got.get("error", ""), route=name)
            return rec
        rec.update(got["value"])
        rec[f"{name}_s"] = got["seconds"]
    rec["verdict"], rec["rel_error"] = verdict(rec, rec)
    return rec


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=60)
    ap.add_argument("--first", type=int, default=0, help="first case number")
    ap.add_argument("--limit", type=float, default=300.0, help="seconds per route and case")
    ap.add_argument("--out", default=os.path.join(bench_2d.ROOT, "results", "stress_global_3d"))
    args = ap.parse_args()
    records = []
    for k in range(args.first, args.first + args.cases):
        rec = run_case(k, args.limit)
        records.append(rec)
        err = rec.get("rel_error")
        print(f"case {k}: m {rec.get('m', '-')}, {rec['verdict']}"
              + (f", ours {rec['mu_c']!r} brute {rec['least_polished']!r} ({err:+.1e})" if err is not None else "")
              + (f", brute unpolished below: {rec['unpolished_below']}" if "unpolished_below" in rec else ""), flush=True)
        counts = dict(collections.Counter(r["verdict"] for r in records))
        write_records(args.out, records, extra={"verdicts": counts, "mu_max": MU_MAX})
    print("verdicts:", counts)
    sys.exit(1 if counts.get("wrong") else 0)


if __name__ == "__main__":
    main()
