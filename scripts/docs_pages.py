"""Generated documentation pages: the scene reference and the benchmark tables.

The scene reference is rendered from the table of scene keys (hpcwedge/scene/keys.py: per
key its type, allowed values, default, unit, meaning and whether it is a run setting; a
built-in's keys are its generator's parameters, their meanings keys.BUILTIN), the table the
parser reads its key sets and defaults from, so it cannot drift from what a scene may say.
A built-in parameter without a meaning is an error (KeyError), and so is a meaning no
built-in takes (stale_meanings, tests/test_docs.py).

The benchmark tables are rendered from results/*.json (never copied by hand); see BENCHMARKS.

Used by scripts/mkdocs_hooks.py at build time; `python scripts/docs_pages.py scene` prints the
reference page.
"""
from __future__ import annotations

import json
import math
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REQUIRED = "required"
NONE = "—"


def accepted_keys() -> dict[str, dict[str, object]]:
    """{table: {key: default}} of every table of scene/keys.py, in its order (REQUIRED where
    there is no default, NONE where absence has a meaning of its own; "model.<builtin>"
    for each built-in)."""
    from hpcwedge.scene import keys
    return {t: {k: _default(key.default) for k, key in ks.items()} for t, ks in keys.tables().items()}


def _default(v: object) -> object:
    """A default as the page shows it: Absent.REQUIRED -> REQUIRED, Absent.OPTIONAL -> NONE."""
    from hpcwedge.scene.keys import Absent
    return v.value if isinstance(v, Absent) else v


def stale_meanings() -> list[str]:
    """Built-in parameters with a meaning (keys.BUILTIN) that no built-in takes."""
    from hpcwedge.models.library import BUILTINS
    from hpcwedge.scene import keys
    used = {k for kind in BUILTINS for k in keys.table(f"model.{kind}")}
    return [f"builtin.{k}" for k in keys.BUILTIN if k not in used]


def _fmt(v: object) -> str:
    if v in (REQUIRED, NONE) and isinstance(v, str):
        return v
    if isinstance(v, bool):
        return "`true`" if v else "`false`"
    if isinstance(v, str):
        return f'`"{v}"`'
    return f"`{v!r}`"


TITLES = {
    "scene": "Top level", "model": "[model]", "friction": "[friction]", "compute": "[compute]", "run": "[run]",
    "model.stiffness": '[model] kind = "stiffness"', "model.truss": '[model] kind = "truss"',
    "contact.truss": "[contact] of a truss", "model.mesh": '[model] kind = "mesh"',
    "contact.mesh": "[contact] of a mesh", "obstacle.plane": '[[obstacle]] type = "plane"',
    "obstacle.cone": '[[obstacle]] type = "cone"', "model.matrix": '[model] kind = "matrix"',
    "contact.matrix": "[contact] of a matrix",
}


def scene_reference() -> str:
    """The Markdown page of every scene key: table, type, allowed values, default, unit, meaning."""
    from hpcwedge.scene import keys
    lines = ["# Scene reference", "",
             "Every key a scene file may hold, generated from the table of scene keys that the parser",
             "reads (`hpcwedge/scene/keys.py`; a built-in's keys are its generator's parameters in",
             "`models/library.py`) by `python scripts/docs_pages.py scene`; the docs build and",
             "tests/test_docs.py fail when this page is stale. Any other key is an error naming it. A built-in",
             "`model.kind` takes only its generator's parameters; its `[contact]` is fixed by the model.", "",
             "*required*: no default. *—*: optional, no default (absent has its own meaning,",
             "given in the text). *Values*: what the type admits (blank: any). Units: the scene's own",
             "consistent units (mu^c does not depend on them: stiffnesses are rescaled internally).",
             "*Run setting*: changes neither the answers nor their bits (SPEC §5); a checkpoint resumes,",
             "and a complete result stands, under another value. Every other key changes the answers.", ""]
    for table, ks in keys.tables().items():
        title = TITLES.get(table) or f'[model] kind = "{table[6:]}" (built-in)'
        lines += [f"## {title}", "", "| key | type | values | default | unit | meaning |",
                  "|---|---|---|---|---|---|"]
        for k in ks.values():
            text = k.meaning + (" *Run setting.*" if k.setting else "")
            lines.append(f"| `{k.name}` | {k.type} | {k.values} | {_fmt(_default(k.default))} | {k.unit} | {text} |")
        lines.append("")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# benchmarks: tables rendered from results/*.json

def _load(name: str) -> dict:
    with open(os.path.join(ROOT, "results", name)) as f:
        return json.load(f)


def _num(v: object, digits: int = 3) -> str:
    if v is None:
        return "–"
    if isinstance(v, bool) or isinstance(v, str):
        return str(v)
    if isinstance(v, int):
        return f"{v:,}"
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    return f"{v:.{digits}g}"


def table(header: list[str], rows: list[list[object]]) -> str:
    """A Markdown table; numbers formatted by _num."""
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(_num(c) if not isinstance(c, str) else c for c in r) + " |" for r in rows]
    return "\n".join(out)


def _s(v: float | None, digits: int = 3) -> str:
    """Seconds (or any positive quantity) to `digits` significant digits, thousands separated."""
    if v is None:
        return "–"
    if v >= 10 ** digits:
        return f"{v:,.0f}"
    txt = f"{float(f'{v:.{digits}g}'):f}".rstrip("0").rstrip(".")
    return txt


def _x(v: float) -> str:
    """A ratio: 4,595× / 1.8×."""
    return f"{v:,.0f}×" if v >= 100 else f"{float(f'{v:.2g}'):g}×"


def bench_2d() -> str:
    """results/bench_2d.json: plug2d rows 2..10, our engines against cddlib (scripts/bench_2d.py)."""
    d = _load("bench_2d.json")
    by = {}
    for r in d["records"]:
        by.setdefault(r["m"], {})[r["engine"]] = r

    def cell(r):
        if r is None or r["status"] == "not_run":
            return "–"
        if r["status"] == "timeout":
            return f"> {r['seconds_lower_bound']:.0f} (limit)"
        return _s(r["seconds"])

    rows = []
    for m in sorted(by):
        e = by[m]
        ours, cdd = e["ours_enumerate"], e.get("cdd_exact")
        if cdd and cdd["status"] == "ok":
            ratio = _x(cdd["seconds"] / ours["seconds"])
        elif cdd and cdd["status"] == "timeout":
            ratio = "> " + _x(cdd["seconds_lower_bound"] / ours["seconds"])
        else:
            ratio = "–"
        rows.append([str(m), f"{ours['n_wedged_rays']:,}", str(ours["n_cones"]), cell(ours),
                     cell(e.get("ours_run_scene")), cell(e.get("ours_mpirun")), cell(e.get("ours_exact")),
                     cell(cdd), ratio])
    return table(["m", "wedged rays", "cones", "ours enum", "run_scene", "mpirun, 2 workers", "ours (exact)",
                  "cddlib exact + filter + cliques", "peer / ours enum"], rows)


def bench_parallel() -> str:
    """results/bench_parallel.json: plug3d 3 x 6 serially and with 1-3 workers (scripts/bench_parallel.py)."""
    d = _load("bench_parallel.json")
    rows = [[("serial (no mpirun)" if r["config"] == "serial" else r["config"]), f"{r['seconds']:.1f}",
             f"{r['speedup_vs_1_worker']:.2f}", f"{r['program_seconds']:.1f}", f"{r['program_speedup_vs_1_worker']:.2f}",
             f"{r['patterns']:,}", "yes" if r["same_answers"] else "**no**"] for r in d["rows"]]
    return table(["", "wall s", "speedup vs 1 worker", "program s", "speedup", "patterns", "same answers"], rows)


def bench_socp_count() -> str:
    """results/bench_socp_count.json: SOCPs of the branch and bound on plug3d (scripts/bench_socp_count.py)."""
    runs = _load("bench_socp_count.json")["runs"]
    by = {}
    for r in runs:
        by.setdefault((r["m"], r["mu"]), {})[r["branching"]] = r
    rows = []
    for (m, mu), e in sorted(by.items()):
        st, dy, sy = e["static"], e["dynamic"], e["symmetric"]
        rows.append([str(m), f"{mu:g}", f"{sy['patterns']} ({sy['leaves_found']})",
                     f"{st['socps']:,} → {dy['socps']:,} → {sy['socps']:,}", f"{sy['partitions'] / sy['socps']:.1f}",
                     f"{st['bnb_seconds']:.2f} → {dy['bnb_seconds']:.2f} → {sy['bnb_seconds']:.2f}",
                     _equal([x.get("brute_equal") for x in (st, dy, sy)])])
    return table(["m", "mu", "patterns (orbit representatives)", "SOCPs static → dynamic → symmetric",
                  "2^m / SOCPs (symmetric)", "B&B s static → dynamic → symmetric",
                  "= brute force"], rows)


def _equal(flags: list) -> str:
    """yes / **no** / – (not checked) for a list of agreement flags (None: not checked)."""
    if any(f is False for f in flags):
        return "**no**"
    return "yes" if any(f for f in flags) else "–"


def bench_condense() -> str:
    """results/bench_condense.json (10^6 DOFs) and bench_condense_quick.json (10^5): serial
    against distributed condensation of block2d (scripts/bench_condense.py)."""
    rows = []
    for name in ("bench_condense_quick.json", "bench_condense.json"):
        for r in _load(name)["rows"]:
            rows.append([f"{r['n_dofs']:,}", str(r["ranks"]), _s(r["condense_s"]), _s(r["build_s"], 2),
                         ", ".join(f"{v:,.0f}" for v in r["maxrss_mb_per_rank"]),
                         f"{r['rel_diff_vs_first']:.1e}" if r["rel_diff_vs_first"] else "(reference)"])
    return table(["DOFs", "ranks", "condense (s)", "model build (s)", "peak RSS per rank (MB)",
                  "condensed K against 1 rank"], rows)


GROWTH = [("2d/ours", "2D ours, whole run_scene"), ("2d/ours_split", "2D ours, enumerate only (parametrize + DD + cliques)"),
          ("2d/cdd_exact", "2D peer: cddlib exact DD + filter + cliques"), ("3d/bnb_sym", "3D ours, B&B with symmetry"),
          ("3d/bnb", "3D ours, B&B without symmetry"), ("3d/brute", "3D peer: brute force, one SOCP per partition")]


def bench_growth() -> str:
    """results/bench_growth.json: fitted growth of time and memory per contact node (scripts/bench_growth.py)."""
    d = _load("bench_growth.json")
    rows = []
    for key, label in GROWTH:
        dim, engine = key.split("/")
        f = d["fits"][key]
        pts = [p for p in d["points"] if f"{p['dim']}d" == dim and p["engine"] == engine and p["status"] == "ok"]
        last = max(pts, key=lambda p: p["m"])
        t, mem = f["time"], f["memory"]
        rows.append([label, "{}–{}".format(*t["m_range"]), f"{t['b']:.2f}", f"{t['nodes_per_doubling']:.1f}",
                     f"{_s(last['seconds'], 2)} s (m = {last['m']})", f"{last['maxrss_mb']:,.0f} MB",
                     f"{mem['b']:.2f} (m {mem['m_range'][0]}–{mem['m_range'][1]})" if mem else "flat"])
    return table(["engine", "m", "time ×b per node", "nodes per doubling", "time at largest m",
                  "peak RSS at largest m", "memory ×b per node"], rows)


PEER_ENGINES_2D = [("ours_exact", "ours exact"), ("cdd_exact", "cddlib exact + filter + cliques"),
                   ("cdd_float", "cddlib float + filter + cliques"), ("brute_lp", "brute force, 2^m LPs")]


def _peer_cell(r: dict, ours: dict, extra: str = "") -> str:
    """`seconds (ratio×)` of a peer record against ours, or why there is no time."""
    if r["status"] == "timeout":
        return f"> {r['wall']:.0f}, cut (> {_x(r['wall'] / ours['seconds'])})"
    if r["status"] == "error":
        return "**aborted**"
    if r["status"] != "ok":
        return r["status"]
    return f"{_s(r['seconds'], 2)}{extra} ({_x(r['seconds'] / ours['seconds'])})"


def bench_peers_2d() -> str:
    """results/bench_peers.json, section 2d: every 2D engine on the same scenes (scripts/bench_peers.py)."""
    recs = [r for r in _load("bench_peers.json")["records"] if r["section"] == "2d"]
    rows = []
    for ours in (r for r in recs if r["engine"] == "ours_float"):
        same = {r["engine"]: r for r in recs if r["scene"] == ours["scene"]}
        rows.append([ours["scene"], str(ours["m"]), _s(ours["seconds"], 2),
                     *[_peer_cell(same[e], ours) if e in same else "–" for e, _ in PEER_ENGINES_2D],
                     _equal([None if r.get("agree", "-") in ("-", "") or r["agree"].startswith("aborted")
                             else r["agree"].startswith("yes") for r in same.values()])])
    return table(["scene", "m", "ours float", *[t for _, t in PEER_ENGINES_2D], "all agree"], rows)


def bench_peers_3d() -> str:
    """results/bench_peers.json, section 3d: plug3d, branch and bound against the brute force."""
    recs = [r for r in _load("bench_peers.json")["records"] if r["section"] == "3d"]
    rows = []
    for ours in (r for r in recs if r["engine"] == "bnb_sym"):
        same = {r["engine"]: r for r in recs if r["scene"] == ours["scene"]}
        cells = []
        for e in ("bnb", "brute"):
            r = same[e]
            cells.append(f"{_s(r['seconds'], 2)} s ({_x(r['seconds'] / ours['seconds'])}), "
                         f"{r['socps']:,} SOCPs ({_x(r['socps'] / ours['socps'])})" if r["status"] == "ok" else r["status"])
        rows.append([ours["scene"], str(ours["m"]), f"{_s(ours['seconds'], 2)} s, {ours['socps']:,} SOCPs", *cells,
                     f"{ours['patterns']:,}", _equal([r.get("patterns_digest") == ours["patterns_digest"] for r in same.values()])])
    return table(["scene", "m", "ours, B&B + symmetry", "ours, B&B without symmetry", "brute force, 2^m SOCPs",
                  "patterns", "same pattern sets"], rows)


def _gmean(v: list[float]) -> float:
    return math.exp(sum(math.log(x) for x in v) / len(v))


def bench_peers_mu_c() -> str:
    """results/bench_peers.json, section mu_c: plain bisection against our accurate mu^c."""
    recs = [r for r in _load("bench_peers.json")["records"] if r["section"] == "mu_c" and r["status"] == "ok"]
    methods = ["bisection 1e-6", "bisection 1e-9", "accurate"]
    rows = []
    for dim in (2, 3):
        rs = [r for r in recs if r["dim"] == dim]
        acc = {r["scene"]: r for r in rs if r["engine"] == "accurate"}
        err, tim = [f"{dim}D ({'LP' if dim == 2 else 'SOCP'}), worst error"], [f"{dim}D, time / ours"]
        for e in methods:
            sel = [r for r in rs if r["engine"] == e]
            worst = max(r["rel_error"] for r in sel)
            tol = {"bisection 1e-6": 1e-6, "bisection 1e-9": 1e-9}.get(e, 1e-9)
            above = sum(r["rel_error"] > tol for r in sel) if e == "bisection 1e-9" else 0
            err.append(f"{worst:.1e}" + (f" ({above} of {len(sel)} scenes above 1e-9)" if above else "")
                       if e != "accurate" else f"**{worst:.1e}**")
            if e == "accurate":
                tim.append(f"{_s(min(r['seconds'] for r in sel), 2)}–{_s(max(r['seconds'] for r in sel), 2)} s")
            else:
                ratios = [r["seconds"] / acc[r["scene"]]["seconds"] for r in sel]
                tim.append(f"{_x(min(ratios))[:-1]}–{_x(max(ratios))} (geometric mean {_x(_gmean(ratios))})")
        rows += [err, tim]
    return table(["", "plain bisection 1e-6", "plain bisection 1e-9", "ours, accurate"], rows)


def bench_mu_c() -> str:
    """results/bench_mu_c.json: mu^c by plain bisection against the accurate method (scripts/bench_mu_c.py)."""
    d = _load("bench_mu_c.json")
    cols = [("bisection tol=1e-06", "plain bisection 1e-6"), ("bisection tol=1e-12", "plain bisection 1e-12"),
            ("tight bisection tol=1e-12", "tight solver, 1e-12"), ("accurate", "accurate")]
    rows = []
    for dim, label in (("2d", "2D (LP, HiGHS)"), ("3d", "3D (SOCP, Clarabel)")):
        sm = d["summary"][dim]
        row = [label]
        for key, _ in cols:
            m = sm["methods"][key]
            cell = f"{m['worst_error']:.1e}, {m['mean_seconds'] * 1e3:.{2 if m['mean_seconds'] < 0.01 else 0}f} ms"
            row.append(f"**{cell.split(',')[0]}**,{cell.split(',')[1]}" if key == "accurate" else cell)
        row.append(f"{_x(sm['accurate_over_bisection_1e-6'])} (worst scene {_x(sm['worst_ratio'])})")
        rows.append(row)
    return table(["", *[t for _, t in cols], "accurate / bisection 1e-6"], rows)


def bench_global_mu_c() -> str:
    """results/bench_global_mu_c{,_large,_block2d}.json: the 2D global mu^c against MILP peers
    (scripts/bench_global_mu_c.py)."""
    recs = [dict(r, model=r.get("model", "plug2d")) for name in GLOBAL_MU_C_FILES for r in _load(name)["records"]]
    engines = [e for e in ("ours", "ours_milp", "ours_tree", "highs_bisect", "scip_bisect")
               if any(r["engine"] == e for r in recs)]
    rows = []
    for model, m in sorted({(r["model"], r["m"]) for r in recs}, key=lambda k: (k[0] != "plug2d", k)):
        same = {r["engine"]: r for r in recs if r["m"] == m and r["model"] == model}
        ours = same.get("ours")
        if ours is None or ours["status"] != "ok":
            continue
        cells = [f"{_s(ours['seconds'], 2)} ({ours['lps']:,} LPs, {ours['tree_nodes']:,} nodes, "
                 f"{ours['milp_solves']} MILPs; error {ours['rel_error']:.0e})"]
        for e in engines[1:]:
            r = same.get(e)
            cells.append("–" if r is None else r["status"] if r["status"] == "skipped" else _peer_cell(r, ours))
        rows.append([model, str(m), *cells])
    heads = {"ours_milp": "MILPs alone", "ours_tree": "tree alone", "highs_bisect": "HiGHS MILP, bisection",
             "scip_bisect": "SCIP, bisection (error 5.6e-6)"}
    return table(["body", "m", "ours, s", *[heads[e] for e in engines[1:]]], rows)


#: the files of bench_global_mu_c's table (plug2d m = 10..40 every engine; m = 80, 160 and
#: block2d: ours and SCIP)
GLOBAL_MU_C_FILES = ("bench_global_mu_c.json", "bench_global_mu_c_large.json", "bench_global_mu_c_block2d.json")


def bench_search_3d() -> str:
    """results/bench_search_3d.json: the 3D pattern search without symmetry (scripts/bench_search_3d.py),
    beside results/bench_search_3d_before.json (the same script on the code before issue 13) and
    the SCIP peer of the same run (records with engine "scip")."""
    data = _load("bench_search_3d.json")
    every, limit = data["records"], data.get("limit_s")
    recs = [r for r in every if r.get("engine", "ours") == "ours"]
    peer = {(r["task"], r["m"]): r for r in every if r.get("engine") == "scip"}
    before = {(r["task"], r["m"]): r for r in _load("bench_search_3d_before.json")["records"]}
    rows = []
    for r in recs:
        b = before.get((r["task"], r["m"]), {"status": "–"})
        if r["status"] != "ok":
            rows.append([r["task"], f"{r['levels']} × {r['ring']}", str(r["m"]), r["status"]] + [""] * 4)
            continue
        enum = r["task"] == "enumerate"

        def cells(x: dict) -> list[str]:
            if x.get("status") != "ok":
                return [x.get("status", "–")] * 3
            share = f"{100 * x['first_attempt']:.1f} %" if enum and x.get("first_attempt") is not None else "–"
            return [f"{x['socps']:,}" + (f" ({x['socps_per_pattern']:.1f} / pattern)" if enum else ""),
                    share if enum else str(x["undecided"]), _s(x["seconds"], 3)]
        now, was = cells(r), cells(b)
        rows.append([r["task"], f"{r['levels']} × {r['ring']}", str(r["m"]),
                     f"{r['patterns']:,} patterns" if enum else f"mu^c {r['mu_c']:.12g}",
                     *[f"{a} (was {w})" for a, w in zip(now, was)], _scip_cell(peer.get((r["task"], r["m"])), r, limit)])
    return table(["search", "plug3d", "m", "answer", "SOCPs", "first attempt settled / undecided",
                  "CPU s", "SCIP, same run"], rows)


def bench_search_3d_kinds() -> str:
    """Ours in results/bench_search_3d.json (an AMD EPYC with AVX-512) beside
    results/bench_search_3d_no_avx512.json (one without it, later code): the counts of each
    tree on both kinds, and the CPU seconds."""
    kinds = [_load("bench_search_3d.json"), _load("bench_search_3d_no_avx512.json")]
    arch = [k["environment"]["blas"][0]["architecture"] for k in kinds]
    recs = [{(r["task"], r["m"]): r for r in k["records"] if r.get("engine", "ours") == "ours"} for k in kinds]
    rows = []
    for key, a in recs[0].items():
        b = recs[1].get(key)
        if b is None or "ok" not in (a["status"], b["status"]):
            continue
        enum = key[0] == "enumerate"
        same = (a["nodes"], a["socps"]) == (b["nodes"], b["socps"])
        answer = "the same" if (a.get("patterns_hash") == b.get("patterns_hash") if enum
                                else abs(a["mu_c"] - b["mu_c"]) <= 1e-14 * a["mu_c"]) else "another"
        rows.append([key[0], f"{a['levels']} × {a['ring']}", str(key[1]),
                     f"{a['nodes']:,} / {a['socps']:,}", "the same" if same else f"{b['nodes']:,} / {b['socps']:,}",
                     answer, _s(a["seconds"], 3), _s(b["seconds"], 3)])
    return table(["search", "plug3d", "m", f"nodes / SOCPs ({arch[0]})", f"nodes / SOCPs ({arch[1]})",
                  "patterns (hash) or mu^c (to 1e-14)", f"CPU s ({arch[0]})", f"CPU s ({arch[1]})"], rows)


def bench_search_3d_screens() -> str:
    """The enumerations of results/bench_search_3d.json with and without the LP screens
    (engines "ours" and "screens", `run.screens`): patterns (the same set?), nodes, SOCPs
    (per pattern), LPs, first attempt settled and CPU seconds of each."""
    recs = _load("bench_search_3d.json")["records"]
    screened = {r["m"]: r for r in recs if r.get("engine") == "screens" and r["task"] == "enumerate"}
    rows = []
    for a in (r for r in recs if r.get("engine", "ours") == "ours" and r["task"] == "enumerate"):
        b = screened.get(a["m"])
        if b is None or "ok" not in (a["status"], b["status"]) or a["status"] != b["status"]:
            continue
        same = "the same" if a["patterns_hash"] == b["patterns_hash"] else "ANOTHER SET"
        cells = [[f"{x['nodes']:,}", f"{x['socps']:,} ({x['socps_per_pattern']:.1f})", f"{x.get('lps') or 0:,}",
                  f"{100 * x['first_attempt']:.1f} %", _s(x["seconds"], 3)] for x in (a, b)]
        rows.append([f"{a['levels']} × {a['ring']}", str(a["m"]), f"{a['patterns']:,} ({same})",
                     *[f"{u} → {v}" for u, v in zip(*cells)]])
    return table(["plug3d", "m", "patterns (screened)", "tree nodes", "SOCPs (per pattern)", "LPs",
                  "first attempt settled", "CPU s"], rows)


def stress_3d() -> str:
    """results/stress_3d.json (scripts/stress_3d.py) beside results/stress_3d_before.json (the
    same script on the code before the balanced reaction form): per case the patterns, SOCPs,
    the tree's first-attempt share, pyramid LPs, undecided nodes, mu^c error and seconds."""
    now, was = (_load(f) for f in ("stress_3d.json", "stress_3d_before.json"))
    before = {(r["kind"], r["taper_deg"]): r for r in was["records"]}
    label = {"enumerate": "patterns at 1.5 tan(taper)", "enumerate65": "patterns at 0.65", "global": "global mu^c"}

    def cells(x: dict | None) -> list[str]:
        if x is None or x.get("status") != "ok":
            cut = x is not None and x.get("status") == "timeout"
            return [f"> {was.get('limit_s', 0):g} s (cut)" if cut else "–"] + ["–"] * 5
        share = x.get("first_attempt_share")
        err = x.get("rel_error")
        return [f"{x['solves']:,}", "–" if share is None else f"{100 * share:.1f} %", f"{x['lps']:,}",
                str(x["undecided"]), "–" if err is None else f"{err:.1e}", _s(x["total_s"], 3)]
    rows = []
    for r in now["records"]:
        a, b = cells(r), cells(before.get((r["kind"], r["taper_deg"])))
        rows.append([label[r["kind"]], f"{r['taper_deg']:g}°", "–" if r.get("patterns") is None else str(r["patterns"]),
                     *[f"{x} (was {y})" for x, y in zip(a, b)]])
    return table(["case", "taper", "patterns", "SOCPs", "tree's first attempts decided", "pyramid LPs",
                  "undecided", "mu^c error", "seconds"], rows)


#: the order of stress_global_3d's verdicts in its table
GLOBAL_VERDICTS = ("agree", "brute unpolished", "flagged", "none", "wrong", "timeout", "error")


def stress_global_3d() -> str:
    """results/stress_global_3d.json (scripts/stress_global_3d.py): a row per verdict, with its
    cases, their m, the largest |error| against brute force's least polished mu^c, and the
    cases where brute force had an unpolished value below that."""
    recs = _records("stress_global_3d.json")
    if recs is None:
        return not_measured("stress_global_3d.json")
    by = {}
    for r in recs:
        by.setdefault(r["verdict"], []).append(r)
    rows = []
    for v in sorted(by, key=lambda v: GLOBAL_VERDICTS.index(v) if v in GLOBAL_VERDICTS else len(GLOBAL_VERDICTS)):
        rs = by[v]
        ms = [r["m"] for r in rs if "m" in r]
        errs = [abs(r["rel_error"]) for r in rs if r.get("rel_error") is not None]
        rows.append([v, f"{len(rs):,}", f"{min(ms)}–{max(ms)}" if ms else "–", f"{max(errs):.1e}" if errs else "–",
                     str(sum(bool(r.get("unpolished_below")) for r in rs)),
                     ", ".join(str(r["case"]) for r in rs) if v != "agree" else "–"])
    return table(["verdict", "cases", "m", "largest |error|", "brute force: an unpolished value below", "which"], rows)


def _scip_cell(p: dict | None, ours: dict, limit: float | None) -> str:
    """The SCIP peer's answer and CPU seconds beside ours: the same pattern set (hash) or its
    mu^c's distance from ours; a run cut at the time limit as "> limit s"."""
    if p is None:
        return "–"
    if p["status"] == "timeout" and limit:
        return f"> {limit:g} s (cut)"
    if p["status"] != "ok":
        return p["status"]
    if ours["task"] == "enumerate":
        same = "the same set" if p.get("patterns_hash") == ours["patterns_hash"] else "another set"
        answer = f"{p['patterns']:,} patterns ({same})"
    else:
        answer = f"mu^c off by {abs(p['mu_c'] - ours['mu_c']) / ours['mu_c']:.1e}"
    return f"{answer}, {p['milp_solves']:,} solves, {_s(p['seconds'], 3)} s"


def examples() -> str:
    """scripts/examples/examples.json: the Gmsh example bodies and the counts of a run of
    each (scripts/make_examples.py; tests/test_examples.py checks them)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("make_examples", os.path.join(ROOT, "scripts", "make_examples.py"))
    mk = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mk)                 # its constants (the tapers); gmsh is imported lazily
    with open(os.path.join(ROOT, "scripts", "examples", "examples.json")) as f:
        d = json.load(f)
    taper = {"cork2d": mk.TAPER_2D_DEG, "plug3d": mk.TAPER_3D_DEG}
    rows = []
    for name, e in d.items():
        runs = e["result"]["runs"]
        col = lambda k: " / ".join("-" if r[k] is None else f"{r[k]:,}" for r in runs)  # noqa: E731
        cells = ", ".join(f"{n} {k}" for k, n in e["cells"].items())
        rows.append([name, str(e["m"]), cells, " / ".join(f"{r['mu']:g}" for r in runs), col("n_wedged_rays"),
                     col("n_cones"), col("n_patterns"), f"{e['result']['mu_c']:.12f}",
                     f"{math.tan(math.radians(taper[name])):.12f}"])
    return table(["scene", "m", "cells", "mu", "wedged rays", "cones", "patterns", "global mu^c", "tan(taper)"], rows)


def faults() -> str:
    """results/faults.json: the fault campaign's verdicts per category (scripts/fault_campaign.py)
    and every failed case as the campaign recorded it; a note instead of a table while no
    campaign result is committed."""
    if not os.path.exists(os.path.join(ROOT, "results", "faults.json")):
        return "| campaign |\n|---|\n| no `results/faults.json` in this checkout yet: run the command below |"
    d = _load("faults.json")
    cats = d["by_category"]
    rows = [[c, str(v["pass"]), str(v["FAIL"]), str(v["skip"])] for c, v in cats.items()]
    rows.append(["**all**", *(f"**{sum(v[k] for v in cats.values())}**" for k in ("pass", "FAIL", "skip"))])
    failed = [r for r in d.get("rows") or [] if r.get("verdict") == "FAIL"]
    out = table(["category", "pass", "fail", "skipped"], rows) + \
        f"\n\n{d['cases']} cases in {d['seconds']:.0f} s (`{d['command']}`)."
    reruns = [r for r in d.get("rows") or [] if r.get("rerun")]
    if reruns:
        out += (f" {len(reruns)} of them were run again alone after a fix or because they had failed under load "
                "(the counts above hold their last verdict): " +
                "; ".join(f"{r['case']} ({r['verdict']}, `{r['rerun']}`)" for r in reruns) + ".")
    if failed:
        out += "\n\nFailed in this run:\n\n" + table(
            ["case", "category", "expected", "observed", "seconds"],
            [[r.get("case", "–"), r.get("category", "–"), r.get("expected", "–"),
              str(r.get("observed", "–")).replace("|", "\\|"), _g(r, "seconds")] for r in failed])
    return out


# ---- tables that must survive a missing file or column (results other helpers extend) -------

def _records(name: str, key: str = "records") -> list[dict] | None:
    """The rows under `key` of results/NAME; None when this checkout has no such file."""
    if not os.path.exists(os.path.join(ROOT, "results", name)):
        return None
    return _load(name).get(key) or []


def not_measured(*names: str) -> str:
    """The one-cell table that stands for a result not in this checkout."""
    return table(["result"], [["not measured: no " + ", ".join(f"`results/{n}`" for n in names) + " in this checkout"]])


def _g(r: dict, key: str, digits: int = 3) -> str:
    """A row's value as a cell: "–" when the column is missing or empty."""
    v = r.get(key)
    if v is None or v == "":
        return "–"
    return _s(v, digits) if isinstance(v, float) and v >= 0 else v if isinstance(v, str) else _num(v, digits)


def _seconds_or_status(r: dict, key: str = "seconds") -> str:
    """Seconds of a finished row; "> N (cut)" for one cut at its limit; else its status."""
    status, v = r.get("status", "ok"), r.get(key)
    if status == "timeout":
        return f"> {v:g} (cut)" if isinstance(v, (int, float)) else "cut"
    if v is None or status not in ("ok", "found", "optimal"):
        return str(status)
    return _s(v)


def _fixed(r: dict, key: str, places: int, sign: str = "") -> str:
    """A row's fraction to `places` decimals ("+" shows the sign); "–" when missing."""
    v = r.get(key)
    return "–" if v is None else f"{v:{sign}.{places}f}"


def _error(r: dict, key: str = "rel_error") -> str:
    v = r.get(key)
    return "–" if v is None else f"{v:.1e}"


def bench_global_scale() -> str:
    """results/bench_global_scale.json: the global mu^c of issue 41's meshed-body targets through
    `hpcwedge run` (scripts/bench_global_scale.py), ours and any peer rows ("engine"/"peer"),
    against tan 10 deg; a row cut at the limit shows "> limit (cut)"."""
    recs = _records("bench_global_scale.json")
    if recs is None:
        return not_measured("bench_global_scale.json")
    rows = []
    for r in recs:
        target = r.get("target_seconds")
        met = r.get("target_met")
        goal = "–" if target is None else f"≤ {target:g}" + ("" if met is None else " (met)" if met else " (**missed**)")
        bound = "–" if r.get("bound_solves") is None else \
            f"{r['bound_solves']:,} / {'yes' if r.get('bound_certified') else 'no'}"
        rows.append([r.get("case", "–"), r.get("engine") or r.get("peer") or "ours", _g(r, "m"),
                     _seconds_or_status(r), goal, _error(r), _g(r, "route"),
                     _g(r, "nodes") if r.get("nodes") is not None else _g(r, "milp_nodes"),
                     f"{_g(r, 'solves')} / {_g(r, 'lps')}", _g(r, "milp_solves"), bound, _g(r, "undecided")])
    return table(["case", "engine", "m", "seconds", "target s", "mu^c error", "route", "nodes",
                  "solves (SOCPs 3D, LPs 2D) / pyramid LPs", "MILPs", "bound solves / certified", "undecided"], rows)


def bench_stop_latency() -> str:
    """results/bench_stop_latency.json: SIGTERM at N moments of each global run or long
    condensation, serial or under mpirun (scripts/bench_stop_latency.py): the seconds to the
    exit, the exits and the resume."""
    recs = _records("bench_stop_latency.json")
    if recs is None:
        return not_measured("bench_stop_latency.json")
    rows = []
    for r in recs:
        resumed = "–" if r.get("resume_same") is None else "same answer" if r["resume_same"] else "**differs**"
        served = f"{_g(r, 'exit_75')} / {_g(r, 'exit_0')}" + ("" if r.get("all_served") else " (**not all served**)")
        rows.append([r.get("case", "–"), _g(r, "ranks") if "ranks" in r else "1", _g(r, "full_s"),
                     f"{len(r.get('stops') or []):,}", served,
                     _g(r, "median_latency_s"), _g(r, "worst_latency_s"), _g(r, "over_target"), resumed])
    return table(["case", "ranks", "run s", "stops", "exit 75 / 0 (finished)", "median s to exit", "worst s to exit",
                  "over 2 s", "resumed"], rows)


def bench_condense_routes() -> str:
    """results/bench_condense_routes.json: a serial condensation in the process, in a forked
    child and in a spawned interpreter (scripts/bench_condense_routes.py): seconds and bits."""
    recs = _records("bench_condense_routes.json")
    if recs is None:
        return not_measured("bench_condense_routes.json")
    rows = [[_g(r, "refine"), _g(r, "n_dofs"), r.get("route", "–"), _g(r, "seconds"), _g(r, "over_here_s"),
             "yes" if r.get("same_bits") else "**no**"] for r in recs]
    return table(["block2d refine", "DOFs", "route", "seconds", "over in-process s", "K_local bits as in-process"], rows)


def bench_near_critical() -> str:
    """results/bench_near_critical.json: the 3D tree near the critical mu (scripts/bench_near_critical.py),
    one row per record, grouped by search and body, "before" above "after"."""
    recs = _records("bench_near_critical.json")
    if recs is None:
        return not_measured("bench_near_critical.json")
    order = {"before": 0, "after": 1}
    key = lambda r: (r.get("task", ""), r.get("body", ""), r.get("m") or 0, order.get(r.get("label"), 2),  # noqa: E731
                     r.get("engine") or "")
    rows = []
    for r in sorted(recs, key=key):
        answer = ("–" if r.get("status") != "ok" else f"mu^c {r['mu_c']:.12g}" if r.get("mu_c") is not None
                  else f"{r['patterns']:,} pattern" + "s" * (r["patterns"] != 1) if r.get("patterns") is not None else "–")
        if r.get("certified") is not None:
            answer += ", certified" if r["certified"] else ", not certified"
        if r.get("engine"):          # a peer: its bisection's bracket, its error against our certified value
            answer = (f"mu^c {r['mu_c']:.12g}" if r.get("mu_c") is not None
                      else f"[{r['mu_lo']:.9g}, {r['mu_hi']:.9g}] when cut" if r.get("mu_hi") is not None else "–")
            if r.get("rel_error") is not None:
                answer += f" ({r['rel_error']:+.1e} against ours)"
        if r.get("finished") is False:
            answer += (" (probe: not finished)" if r.get("decided") is None
                       else f" (probe: not finished, {100 * r['decided']:.3g} % of the tree decided)")
        mu = r.get("mu")
        search = r.get("task", "–") + (f" ({r['engine']})" if r.get("engine") else "")
        rows.append([r.get("label", "–"), search, r.get("body", "–"),
                     f"{r.get('levels', '?')} × {r.get('ring', '?')}", _g(r, "m"), "global" if mu is None else f"{mu:.6g}",
                     _seconds_or_status(r, "wall"), _g(r, "seconds"), _g(r, "nodes"), _g(r, "socps"), _g(r, "lps"),
                     _g(r, "undecided"), answer])
    return table(["run", "search", "body", "levels × ring", "m", "mu", "wall s", "CPU s", "nodes", "SOCPs", "LPs",
                  "undecided", "answer"], rows)


#: the files of bench_tree_cores' table (scripts/bench_tree_pruning.py's runs)
TREE_CORE_FILES = ("bench_tree_pruning_neck_4x8.json", "bench_tree_pruning_neck_6x8.json", "bench_tree_pruning.json")


def _full_depth(by_depth: dict) -> str:
    """The depth down to which every tree node was feasible (the tree full binary there)."""
    first = min((int(d) for d, (_, inf) in by_depth.items() if inf), default=None)
    return "–" if first is None else str(first - 1)


def bench_tree_cores() -> str:
    """results/bench_tree_pruning*.json: how many fixings the 3D tree's relaxation needs before
    it prunes (scripts/bench_tree_pruning.py; --neck: the curved neck's settling tree)."""
    rows = []
    for name in TREE_CORE_FILES:
        for r in _records(name) or []:
            c, s = r.get("counts", {}), r.get("core_summary") or {}
            core = (f"{s['mean_core']:.1f} of {s['mean_fixings']:.1f} ({s['least_core']}–{s['largest_core']}; "
                    f"{s['nodes']} nodes)" if s else "–")
            nogood = c.get("nogood_total", 0) / max(c.get("infeasible", 1), 1)
            fixed = c.get("fixed_total", 0) / max(c.get("infeasible", 1), 1)
            rows.append([r.get("body", f"plug3d-{r.get('levels')}x{r.get('ring')}"), _g(r, "m"), f"{r['mu']:.6g}",
                         _g(r, "nodes"), f"{c.get('feasible', 0):,} / {c.get('infeasible', 0):,}",
                         _full_depth(r.get("feasible_infeasible_by_depth") or {}) if "feasible_infeasible_by_depth" in r
                         else "–", core, f"{nogood:.1f} of {fixed:.1f}", f"{c.get('nogood_would_prune', 0):,}",
                         _spread(r.get("nodes_by_first_branching") or {})])
    if not rows:
        return not_measured(*TREE_CORE_FILES)
    return table(["tree", "m", "mu", "nodes", "SOCPs feasible / infeasible", "every node feasible to depth",
                  "minimal core: mean fixings of a pruned node (range; sample)",
                  "Farkas support: mean fixings", "SOCPs a global nogood store prunes",
                  "nodes from each first branching"], rows)


#: the files of bench_tree_fractions' table (bench_tree_pruning.py --neck --fractions)
TREE_FRACTION_FILES = ("bench_tree_pruning_neck_mu_4x8.json", "bench_tree_pruning_neck_mu_6x8.json")


def bench_tree_fractions() -> str:
    """results/bench_tree_pruning_neck_mu_*.json: the curved neck's tree at multiples of its
    global mu^c (a row per tree): its nodes, and their share of the settling tree's (the
    record of the same body closest above mu^c, 1 + 1e-9 when measured)."""
    rows = []
    for name in TREE_FRACTION_FILES:
        recs = [r for r in _records(name) or [] if r.get("fraction_of_mu_c") is not None]
        above = [r for r in recs if r["fraction_of_mu_c"] >= 1.0]
        settling = min(above, key=lambda r: r["fraction_of_mu_c"])["nodes"] if above else None
        for r in sorted(recs, key=lambda r: r["fraction_of_mu_c"]):
            c = r.get("counts", {})
            share = f"{r['nodes'] / settling:.2f}" if settling else "–"
            rows.append([r.get("body", "–"), _g(r, "m"), str(r["fraction_of_mu_c"]), f"{r['mu']:.6g}",
                         _g(r, "nodes"), share, f"{c.get('feasible', 0):,} / {c.get('infeasible', 0):,}",
                         _full_depth(r.get("feasible_infeasible_by_depth") or {}), _g(r, "patterns"),
                         f"{r['seconds']:.1f}" if "seconds" in r else "–"])
    if not rows:
        return not_measured(*TREE_FRACTION_FILES)
    return table(["tree", "m", "mu / mu^c", "mu", "nodes", "of the settling tree's", "SOCPs feasible / infeasible",
                  "every node feasible to depth", "patterns", "CPU s"], rows)


def _spread(by_first: dict) -> str:
    """The least and largest tree over the first branching nodes ("–": not measured)."""
    return f"{min(by_first.values()):,}–{max(by_first.values()):,}" if by_first else "–"


def bench_eta() -> str:
    """results/bench_eta.json: the time left that a tree job's progress lines told against what
    was left (scripts/bench_eta.py): a row per case, its tree job's seconds and lines, and per
    estimate (a column, in the summary's order) the median told / left and the share of lines
    within a factor of 2."""
    recs = _records("bench_eta.json", "summary")
    if recs is None:
        return not_measured("bench_eta.json")
    job_s = {}
    for r in _records("bench_eta.json") or []:
        job_s[r["case"]] = max(job_s.get(r["case"], 0.0), r.get("job_s") or 0.0)
    estimates = list(dict.fromkeys(r["estimate"] for r in recs))
    cases: dict = {}
    for r in recs:
        cases.setdefault(r["case"], {})[r["estimate"]] = r
    rows = []
    for case, by in cases.items():
        lines = max((r.get("lines") or 0) for r in by.values())
        cells = []
        for e in estimates:
            r = by.get(e, {})
            cells.append("–" if r.get("median_ratio") is None else f"{r['median_ratio']:.2f} · {_share(r, 'within_2x')}")
        rows.append([case, f"{job_s[case]:.0f}" if case in job_s else "–", str(lines), *cells])
    return table(["case", "tree job s", "lines", *estimates], rows)


#: the files of bench_sparse_form's table (scripts/bench_sparse_form.py's runs)
SPARSE_FORM_FILES = ("bench_sparse_form_6x8.json", "bench_sparse_form.json")


def bench_sparse_form() -> str:
    """results/bench_sparse_form*.json: the node SOCP in the product's condensed form against the
    uncondensed sparse truss (scripts/bench_sparse_form.py): per body the medians and agreement."""
    rows = []
    for name in SPARSE_FORM_FILES:
        recs = _records(name)
        if not recs:
            continue
        s, r = _load(name).get("summary", {}), recs[0]
        rows.append([r.get("body", "–"), _g(r, "m"), _g(r, "full_dofs"), f"{r['mu']:.3g}", f"{s.get('agree', 0)} of {s.get('nodes', 0)}",
                     _g(s, "ours_nnz_median"), _g(s, "sparse_nnz_median"), _g(s, "ours_ms_median"),
                     _g(s, "sparse_ms_median"), _g(s, "sparse_setup_ms_median")])
    if not rows:
        return not_measured(*SPARSE_FORM_FILES)
    return table(["body", "m", "truss DOFs", "mu", "same decision", "nonzeros, condensed", "nonzeros, sparse",
                  "ms per solve, condensed (kept solver)", "ms per solve, sparse", "+ sparse setup ms"], rows)


def _share(r: dict, key: str) -> str:
    return "–" if r.get(key) is None else f"{100 * r[key]:.0f} %"


#: the files of bench_highs_lp's table and how each is labelled
HIGHS_LP_FILES = (("bench_highs_lp_before.json", "before"), ("bench_highs_lp_final.json", "after"),
                  ("bench_highs_lp.json", "latest run"))


def bench_highs_lp() -> str:
    """results/bench_highs_lp{_before,_final,}.json: the 2D tree's LPs through highspy kept warm
    (scripts/bench_highs_lp.py): per body and file the wall and CPU seconds, tree nodes, LPs
    and the mu^c error."""
    got = [(label, _records(name)) for name, label in HIGHS_LP_FILES]
    if all(recs is None for _, recs in got):
        return not_measured(*(n for n, _ in HIGHS_LP_FILES))
    rows = []
    for label, recs in got:
        for r in recs or []:
            rows.append([r.get("model", "–"), _g(r, "rows"), _g(r, "m"), label, _seconds_or_status(r, "wall"),
                         _g(r, "cpu_with_setup"), _g(r, "route"), _g(r, "tree_nodes"), _g(r, "lps"),
                         _error(r, "error")])
    rows.sort(key=lambda c: (c[0], int(c[1].replace(",", "")) if c[1] != "–" else 0))
    missing = [n for (n, _), (_, recs) in zip(HIGHS_LP_FILES, got) if recs is None]
    note = f"\n\nNot measured: {', '.join(missing)}." if missing else ""
    return table(["body", "rows", "m", "run", "wall s", "CPU s", "route", "tree nodes", "LPs", "mu^c error"],
                 rows) + note


def bench_matrix() -> str:
    """results/bench_matrix.json: a stiffness in PETSc binary against the built-in body, condensed
    under mpirun (scripts/bench_matrix.py): per route the seconds, peak memory per rank and how
    often a rank loaded the whole matrix."""
    if _records("bench_matrix.json", "rows") is None:
        return not_measured("bench_matrix.json")
    d = _load("bench_matrix.json")
    rows = [[r.get("route", "–"), _g(r, "ranks"), _g(r, "n_dofs"), _g(r, "build_s"), _g(r, "condense_s"),
             _g(r, "wall_s"), ", ".join(f"{v:,.0f}" for v in r.get("maxrss_mb_per_rank") or []) or "–",
             ", ".join(str(v) for v in r.get("whole_loads_per_rank") or []) or "–"] for r in d.get("rows") or []]
    body, diff = d.get("body") or {}, d.get("rel_diff_matrix_vs_builtin")
    about = (f"\n\n{d.get('model', 'the body')}: {_g(body, 'nnz')} stored entries, {_g(body, 'file_mb')} MB; "
             f"condensed K, matrix against built-in: {'–' if diff is None else f'{diff:.1e}'} relative.")
    return table(["route", "ranks", "DOFs", "model build s", "condense s", "wall s", "peak RSS per rank (MB)",
                  "whole matrix loaded (per rank)"], rows) + about


def bench_scale() -> str:
    """results/bench_scale.json: the engine's master loop at 3-65 ranks on sleeping tasks, measured,
    and its discrete-event model beyond (scripts/bench_scale.py)."""
    measured = _records("bench_scale.json", "measured")
    if measured is None:
        return not_measured("bench_scale.json")
    rows = [[_g(r, "ranks"), r.get("workload", "–"), _g(r, "tasks"), _g(r, "tasks_per_s"), _fixed(r, "master_busy", 2),
             _fixed(r, "efficiency", 3), _fixed(r, "model_error", 3, "+")] for r in measured]
    out = table(["ranks", "workload", "tasks", "tasks/s", "master busy", "efficiency", "model − measured"], rows)
    modelled = _records("bench_scale.json", "modelled") or []
    rows = [[_g(r, "ranks"), r.get("workload", "–"), _g(r, "worker_seconds", 4), _fixed(r, "efficiency", 3),
             _fixed(r, "master_busy", 2)] for r in modelled]
    out += "\n\nModelled:\n\n" + table(["ranks", "workload", "worker-seconds", "efficiency", "master busy"], rows)
    floors = _records("bench_scale.json", "floor") or []
    rows = [[r.get("workload", "–"), _fixed(r.get("tried", [{}])[0], "efficiency", 3),
             "yes" if r.get("meets_floor") else "no", _g(r, "smallest_worker_seconds_at_0.9", 4),
             _fixed(r, "longest_task_s", 2), _fixed(r, "share_at_floor_s", 2), r.get("why", "–")] for r in floors]
    if rows:
        out += "\n\nAt 1,024 ranks, the floor of 2,000 worker-seconds:\n\n" + table(
            ["workload", "efficiency at the floor", "meets it", "smallest job at 0.9 (worker-s)",
             "longest task (s)", "a worker's share (s)", "why"], rows)
    return out


#: the serial 3D tables of scripts/bench_3d.py (plug3d levels x ring)
BENCH_3D_FILES = (("bench_3d_2x5.json", "2 × 5"), ("bench_3d_3x4.json", "3 × 4"), ("bench_3d_3x5.json", "3 × 5"))


def bench_3d() -> str:
    """results/bench_3d_*.json: per body the patterns and SOCPs of the tree at each mu (against
    the brute force's 2^m SOCPs), every pattern's mu^c at mu = 1, and the global mu^c."""
    rows = []
    for name, size in BENCH_3D_FILES:
        if _records(name, "runs") is None:
            rows.append([size] + ["not measured"] + ["–"] * 5)
            continue
        d = _load(name)
        runs, mp, gl = d.get("runs") or [], d.get("mu_c_patterns") or {}, d.get("global") or {}
        per_mu = ", ".join(f"{r['mu']:g}: {r['patterns']:,} / {r['solves']:,}" for r in runs)
        brute = _equal([r.get("brute_equal") for r in runs])
        pat = "–" if not mp else (f"{mp.get('n', 0):,} patterns, {mp.get('polished', 0):,} polished, "
                                  f"{mp.get('solves', 0):,} solves, {_s(mp.get('seconds'))} s")
        glob = "–" if not gl else f"{_error(gl)} off tan(taper), {_s(gl.get('seconds'))} s, {_g(gl, 'solves')} solves"
        rows.append([size, _g(d, "m"), per_mu, f"{sum(r.get('bnb_seconds', 0) for r in runs):.2f} / "
                     f"{sum(r.get('brute_seconds', 0) for r in runs):.1f}", brute, pat, glob])
    return table(["plug3d", "m", "mu: patterns / SOCPs", "B&B / brute force s (all mu)", "= brute force",
                  "mu^c of every pattern at mu = 1", "global mu^c"], rows)


#: benchmark name -> (function rendering its Markdown table from results/*.json, the files,
#: the command that writes them: `make bench` runs each)
BENCHMARKS: dict = {
    "bench_2d": (bench_2d, "results/bench_2d.json", "OMP_NUM_THREADS=1 .venv/bin/python scripts/bench_2d.py --budget 300"),
    "bench_parallel": (bench_parallel, "results/bench_parallel.json", ".venv/bin/python scripts/bench_parallel.py --repeat 3"),
    "bench_socp_count": (bench_socp_count, "results/bench_socp_count.json",
                         "PYTHONPATH=. .venv/bin/python scripts/bench_socp_count.py --brute-max 14"),
    "bench_condense": (bench_condense, "results/bench_condense.json, results/bench_condense_quick.json",
                       ".venv/bin/python scripts/bench_condense.py [--quick]"),
    "bench_peers_2d": (bench_peers_2d, "results/bench_peers.json", "PYTHONPATH=. .venv/bin/python scripts/bench_peers.py"),
    "bench_peers_3d": (bench_peers_3d, "results/bench_peers.json", "PYTHONPATH=. .venv/bin/python scripts/bench_peers.py"),
    "bench_peers_mu_c": (bench_peers_mu_c, "results/bench_peers.json", "PYTHONPATH=. .venv/bin/python scripts/bench_peers.py"),
    "bench_mu_c": (bench_mu_c, "results/bench_mu_c.json", "PYTHONPATH=. .venv/bin/python scripts/bench_mu_c.py"),
    "examples": (examples, "scripts/examples/examples.json", "PYTHONPATH=. .venv/bin/python scripts/make_examples.py"),
    "faults": (faults, "results/faults.json", "python scripts/fault_campaign.py"),
    "bench_global_mu_c": (bench_global_mu_c, ", ".join(f"results/{f}" for f in GLOBAL_MU_C_FILES),
                          "PYTHONPATH=. .venv/bin/python scripts/bench_global_mu_c.py [--rows 40 80 --engines ours scip_bisect"
                          " --out results/bench_global_mu_c_large] [--model block2d --rows 19 39 --engines ours"
                          " scip_bisect --out results/bench_global_mu_c_block2d]"),
    "bench_search_3d": (bench_search_3d, "results/bench_search_3d.json, results/bench_search_3d_before.json",
                        "PYTHONPATH=. .venv/bin/python scripts/bench_search_3d.py --full"),
    "bench_search_3d_kinds": (bench_search_3d_kinds, "results/bench_search_3d.json, results/bench_search_3d_no_avx512.json",
                              "PYTHONPATH=. .venv/bin/python scripts/bench_search_3d.py --full [--no-peers --out"
                              " results/bench_search_3d_no_avx512]"),
    "bench_search_3d_screens": (bench_search_3d_screens, "results/bench_search_3d.json",
                                "PYTHONPATH=. .venv/bin/python scripts/bench_search_3d.py --full"),
    "stress_3d": (stress_3d, "results/stress_3d.json, results/stress_3d_before.json",
                  "PYTHONPATH=. .venv/bin/python scripts/stress_3d.py"),
    "stress_global_3d": (stress_global_3d, "results/stress_global_3d.json",
                         "PYTHONPATH=. .venv/bin/python scripts/stress_global_3d.py --cases 200"),
    "bench_growth": (bench_growth, "results/bench_growth.json", "PYTHONPATH=. .venv/bin/python scripts/bench_growth.py"),
    "bench_global_scale": (bench_global_scale, "results/bench_global_scale.json",
                           ".venv/bin/python scripts/bench_global_scale.py [--limit 300]"),
    "bench_stop_latency": (bench_stop_latency, "results/bench_stop_latency.json",
                           ".venv/bin/python scripts/bench_stop_latency.py"),
    "bench_condense_routes": (bench_condense_routes, "results/bench_condense_routes.json",
                              "PYTHONPATH=. .venv/bin/python scripts/bench_condense_routes.py"),
    "bench_near_critical": (bench_near_critical, "results/bench_near_critical.json",
                            ".venv/bin/python scripts/bench_near_critical.py"),
    "bench_tree_cores": (bench_tree_cores, ", ".join(f"results/{f}" for f in TREE_CORE_FILES),
                         "PYTHONPATH=. .venv/bin/python scripts/bench_tree_pruning.py [--neck --levels 4 --ring 8"
                         " --cores 80 --out results/bench_tree_pruning_neck_4x8]"),
    "bench_tree_fractions": (bench_tree_fractions, ", ".join(f"results/{f}" for f in TREE_FRACTION_FILES),
                             "PYTHONPATH=. .venv/bin/python scripts/bench_tree_pruning.py --neck --levels 6 --ring 8"
                             " --fractions 0.5 0.8 0.9 0.97 0.99 1.000000001 --out results/bench_tree_pruning_neck_mu_6x8"),
    "bench_highs_lp": (bench_highs_lp, ", ".join(f"results/{f}" for f, _ in HIGHS_LP_FILES),
                       ".venv/bin/python scripts/bench_highs_lp.py [--checkout DIR --out results/bench_highs_lp_before]"),
    "bench_matrix": (bench_matrix, "results/bench_matrix.json", ".venv/bin/python scripts/bench_matrix.py"),
    "bench_eta": (bench_eta, "results/bench_eta.json", "PYTHONPATH=. .venv/bin/python scripts/bench_eta.py"),
    "bench_sparse_form": (bench_sparse_form, ", ".join(f"results/{f}" for f in SPARSE_FORM_FILES),
                          "PYTHONPATH=. .venv/bin/python scripts/bench_sparse_form.py [--levels 6 --out results/bench_sparse_form_6x8]"),
    "bench_3d": (bench_3d, ", ".join(f"results/{f}" for f, _ in BENCH_3D_FILES),
                 "PYTHONPATH=. .venv/bin/python scripts/bench_3d.py [--levels 3 --ring 4]"),
    "bench_scale": (bench_scale, "results/bench_scale.json", "PYTHONPATH=. .venv/bin/python scripts/bench_scale.py --quick"),
}


def render(name: str) -> str:
    """The table of one benchmark, with a caption naming its file and command."""
    fn, files, command = BENCHMARKS[name]
    return f"{fn()}\n\n*Rendered from `{files}`, written by `{command}`.*\n"


def render_markers(markdown: str) -> str:
    """Replace every `<!-- bench: NAME -->` line by render(NAME) (KeyError if unknown)."""
    out = []
    for line in markdown.split("\n"):
        s = line.strip()
        if s.startswith("<!-- bench:") and s.endswith("-->"):
            name = s[len("<!-- bench:"):-3].strip()
            if name not in BENCHMARKS:
                raise KeyError(f"<!-- bench: {name} -->: no such table in scripts/docs_pages.py BENCHMARKS")
            out.append(render(name))
        else:
            out.append(line)
    return "\n".join(out)


SCENE_PAGE = os.path.join(ROOT, "docs", "reference", "scene.md")


def stale_scene_reference() -> str:
    """'' when docs/reference/scene.md (committed, so that links to it resolve on the
    repository too) is what scene_reference() renders; else the one line that says how to
    regenerate it."""
    page = open(SCENE_PAGE).read() if os.path.exists(SCENE_PAGE) else ""
    if page == scene_reference() + "\n":
        return ""
    return ("docs/reference/scene.md is not the scene reference of hpcwedge/scene/keys.py: "
            "regenerate it with `PYTHONPATH=. python scripts/docs_pages.py scene > docs/reference/scene.md`")


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "scene"
    if what == "scene":
        print(scene_reference())
    else:
        print(render(what))
