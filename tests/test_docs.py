"""The documentation: the site builds with warnings as errors (mkdocs build --strict), every
```python block of docs/ and README.md runs, and the generated scene reference lists exactly
the keys the parser accepts (probed through the parser's own unknown-key errors)."""
from __future__ import annotations

import glob
import importlib.util
import os
import re
import subprocess
import sys

import pytest

from hpcwedge.scene.parse import parse_scene
from hpcwedge.scene.values import SceneError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
import docs_pages  # noqa: E402

DOCS_TOOLS = ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python")
MISSING = [m for m in DOCS_TOOLS if importlib.util.find_spec(m.split(".")[0]) is None
           or importlib.util.find_spec(m) is None]
needs_docs_tools = pytest.mark.skipif(
    bool(MISSING), reason=f"docs tools not installed ({', '.join(MISSING)}): make setup-docs (make test does it)")

# docs/ itself, not what its symlinks show (results/, guide/jobs.md = jobs/README.md)
PAGES = sorted(p for p in glob.glob(os.path.join(ROOT, "docs", "**", "*.md"), recursive=True)
               if os.path.realpath(p) == os.path.join(os.path.realpath(ROOT), os.path.relpath(p, ROOT))) + [
    os.path.join(ROOT, "README.md")]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


@needs_docs_tools
def test_site_builds_strict(tmp_path):
    """make docs: mkdocs build --strict succeeds (broken links, missing anchors, bad docstrings
    and unknown benchmark tables are errors) and the generated pages are in the site."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [ROOT, os.environ.get("PYTHONPATH")])),
           "NO_MKDOCS_2_WARNING": "1"}
    p = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(tmp_path / "site")],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    ref = (tmp_path / "site" / "reference" / "scene" / "index.html").read_text()
    assert "max_memory_gb" in ref and "half_angle_deg" in ref
    api = (tmp_path / "site" / "reference" / "api" / "index.html").read_text()
    assert "solve" in api and "Scene" in api
    assert (tmp_path / "site" / "results" / "bench_2d.png").stat().st_size > 0


@pytest.mark.parametrize("page", [os.path.relpath(p, ROOT) for p in PAGES if BLOCK.search(open(p).read())])
def test_python_blocks_run(page, tmp_path, monkeypatch):
    """The ```python blocks of a page run in order, in one namespace, in a fresh directory
    that sees the repository's scripts/ (examples, meshes) as the repository root would."""
    (tmp_path / "scripts").symlink_to(os.path.join(ROOT, "scripts"))
    monkeypatch.chdir(tmp_path)
    ns: dict = {"__name__": "__docs__"}
    for i, code in enumerate(BLOCK.findall(open(os.path.join(ROOT, page)).read())):
        try:
            exec(compile(code, f"{page} block {i}", "exec"), ns)
        except Exception as e:
            pytest.fail(f"{page}, python block {i}: {type(e).__name__}: {e}")


# ---- the scene reference against the parser -------------------------------------------------

BASE = {"name": "s", "dim": 2, "model": {"kind": "plug2d"}, "friction": {"mu": 0.5}}
MESH = {"name": "s", "dim": 2, "model": {"kind": "mesh", "file": "m.msh"}, "friction": {"mu": 0.5},
        "contact": {"group": "contact"},
        "obstacle": [{"type": "cone", "apex": [0.0, 0.0], "axis": [0.0, 1.0], "half_angle_deg": 10.0}]}
TRUSS = {"name": "s", "dim": 2, "friction": {"mu": 0.5},
         "model": {"kind": "truss", "nodes": [[0.0, 0.0], [1.0, 0.0], [0.5, 1.0]], "bars": [[0, 1], [1, 2], [0, 2]]},
         "contact": {"nodes": [0, 1], "normals": [[0.0, 1.0], [0.0, 1.0]]}}
MATRIX = {"name": "s", "dim": 2, "friction": {"mu": 0.5}, "model": {"kind": "matrix", "K": "k.mtx", "nodes": "n.csv"},
          "contact": {"nodes": [0], "normals": [[0.0, 1.0]]}}
STIFF = {"name": "s", "dim": 2, "friction": {"mu": 0.5}, "model": {"kind": "stiffness", "K": [[2.0, 1.0], [1.0, 4.0]]}}


def _with(base: dict, path: str, key: str = "bogus_key") -> dict:
    """A copy of base with an unknown key added at path ("" top level, "model", "obstacle[0]")."""
    import copy
    d = copy.deepcopy(base)
    t = d
    for part in filter(None, path.split(".")):
        t = t["obstacle"][0] if part == "obstacle[0]" else t.setdefault(part, {})
    t[key] = 1
    return d


def _probe(data: dict) -> set[str] | None:
    """The allowed keys the parser names when refusing an unknown key; None if it accepts it."""
    try:
        parse_scene(data, base_dir=ROOT)
    except SceneError as e:
        msg = str(e)
        assert "bogus_key" in msg, msg
        m = re.search(r"\((?:allowed|accepted): ([^)]*)\)", msg)
        assert m, msg
        return {k.strip() for k in m.group(1).split(",")}
    return None


CASES = {"scene": (BASE, ""), "friction": (BASE, "friction"), "compute": (BASE, "compute"),
         "run": (BASE, "run"), "model.mesh": (MESH, "model"), "contact.mesh": (MESH, "contact"),
         "obstacle.cone": (MESH, "obstacle[0]"), "model.stiffness": (STIFF, "model"),
         "model.truss": (TRUSS, "model"), "contact.truss": (TRUSS, "contact"),
         "model.matrix": (MATRIX, "model"), "contact.matrix": (MATRIX, "contact")}
CASES["obstacle.plane"] = ({**MESH, "obstacle": [{"type": "plane", "point": [0.0, 0.0], "normal": [0.0, 1.0]}]},
                           "obstacle[0]")
for _kind in ("vgroove_bar", "plug2d", "plug3d", "block2d"):
    CASES[f"model.{_kind}"] = ({**BASE, "dim": 3 if _kind == "plug3d" else 2, "model": {"kind": _kind}}, "model")


def test_reference_covers_every_table():
    """Every table of the reference is probed below (a new table needs a case), and the
    reference lists the same tables."""
    tables = set(docs_pages.accepted_keys()) - {"model"}
    assert tables == set(CASES)


@pytest.mark.parametrize("table", sorted(CASES))
def test_reference_keys_are_the_parsers(table):
    """The keys the generated reference lists for a table are the ones the parser names as
    allowed when it refuses an unknown key there, and each has a row on the page."""
    data, path = CASES[table]
    allowed = _probe(_with(data, path))
    if allowed is None:
        pytest.fail(f"the parser accepted an unknown key in {table}")
    if table.startswith("obstacle."):
        allowed.add("type")
    listed = set(docs_pages.accepted_keys()[table])
    assert allowed == listed
    page = docs_pages.scene_reference()
    section = page.split(f"## {docs_pages.TITLES.get(table, '')}")[1] if table in docs_pages.TITLES else page
    for k in listed:
        assert f"| `{k}` |" in section


def test_every_key_has_a_meaning_and_none_is_stale():
    """MEANINGS (scripts/docs_pages.py) documents every accepted key and no other."""
    page = docs_pages.scene_reference()          # KeyError naming a key without a meaning
    assert "| `kind` |" in page
    assert docs_pages.stale_meanings() == []


def test_reference_defaults_are_the_parsers():
    """The defaults shown for [compute] and [run] are what a scene without the key gets."""
    s = parse_scene(BASE)
    for table in ("compute", "run"):
        for k, default in docs_pages.accepted_keys()[table].items():
            assert getattr(s, k) == default, (table, k)


def test_benchmark_markers():
    """Every benchmark table named in docs/ renders from results/*.json; an unknown name is an error."""
    names = set()
    for p in PAGES:
        names |= set(re.findall(r"<!-- bench: (\S+) -->", open(p).read()))
    for n in names:
        assert docs_pages.render_markers(f"<!-- bench: {n} -->").startswith("|")
    with pytest.raises(KeyError, match="no_such_table"):
        docs_pages.render_markers("<!-- bench: no_such_table -->")


def test_readme_is_short_and_its_links_resolve():
    """README.md stays short (the rest is in docs/) and every relative link or image in it
    names a file of the repository (GitHub renders them; mkdocs does not check the README)."""
    text = open(os.path.join(ROOT, "README.md")).read()
    assert len(text.splitlines()) <= 200
    assert "    make demo " in text and "    make test " in text
    links = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    assert len(links) >= 10
    for link in links:
        if "://" not in link:
            assert os.path.exists(os.path.join(ROOT, link)), link


TOML = re.compile(r"^```toml\n(.*?)^```", re.S | re.M)


@pytest.mark.parametrize("page", [os.path.relpath(p, ROOT) for p in PAGES if TOML.search(open(p).read())])
def test_toml_scenes_parse(page):
    """Every ```toml scene shown in docs/ and README.md is accepted by the parser as it
    stands (a renamed or removed key in an example is caught here)."""
    import tomllib
    for i, text in enumerate(TOML.findall(open(os.path.join(ROOT, page)).read())):
        data = tomllib.loads(text)
        try:
            parse_scene(data, text=text, base_dir=os.path.join(ROOT, "scripts", "examples"))
        except SceneError as e:
            pytest.fail(f"{page}, toml block {i}: {e}")


def test_tutorial_table_is_what_show_prints(tmp_path):
    """The tutorial's first scene, run through the command line, gives the table the
    tutorial shows (all but the timings line)."""
    text = open(os.path.join(ROOT, "docs", "tutorial.md")).read()
    (tmp_path / "plug.toml").write_text(TOML.findall(text)[0])
    shown = text.split("    $ hpcwedge show plug.h5\n", 1)[1].split("\n\n", 1)[0]
    expected = [ln[4:] for ln in shown.splitlines() if not ln.strip().startswith("timings:")]
    env = {**os.environ, "PYTHONPATH": ROOT}          # this checkout, not an installed copy
    run = lambda *a: subprocess.run([sys.executable, "-m", "hpcwedge", *a], cwd=tmp_path, env=env,  # noqa: E731
                                    capture_output=True, text=True, timeout=300)
    p = run("run", "plug.toml", "-o", "plug.h5")
    assert p.returncode == 0, p.stderr
    p = run("show", "plug.h5")
    assert p.returncode == 0, p.stderr
    got = [ln for ln in p.stdout.splitlines() if not ln.strip().startswith("timings:")]
    assert got == expected


def test_faults_table_from_a_campaign_file(tmp_path, monkeypatch):
    """The fault campaign's table counts its verdicts per category (the layout
    scripts/fault_campaign.py writes), and says so when no campaign result is there."""
    monkeypatch.setattr(docs_pages, "ROOT", str(tmp_path))
    assert "no `results/faults.json`" in docs_pages.faults()
    (tmp_path / "results").mkdir()
    doc = {"command": "python scripts/fault_campaign.py", "cases": 3, "seconds": 12.3,
           "by_category": {"scene": {"pass": 2, "FAIL": 0, "skip": 0}, "signal": {"pass": 0, "FAIL": 1, "skip": 0}},
           "rows": []}
    (tmp_path / "results" / "faults.json").write_text(__import__("json").dumps(doc))
    out = docs_pages.faults()
    assert "| scene | 2 | 0 | 0 |" in out and "| signal | 0 | 1 | 0 |" in out
    assert "| **all** | **2** | **1** | **0** |" in out and "3 cases in 12 s" in out
    assert "Failed in this run" not in out
    doc["rows"] = [{"case": "SIGUSR1", "category": "signal", "expected": "exit 0", "observed": "exit 1 | x",
                    "verdict": "FAIL", "seconds": 2.5}, {"case": "ok", "verdict": "pass"}]
    (tmp_path / "results" / "faults.json").write_text(__import__("json").dumps(doc))
    out = docs_pages.faults()
    assert out.endswith("Failed in this run:\n\n| case | category | expected | observed | seconds |\n|---|---|---|---|---|\n"
                        "| SIGUSR1 | signal | exit 0 | exit 1 \\| x | 2.5 |")


#: the tables that must render while their results are missing or have fewer columns
TOLERANT = ("bench_global_scale", "bench_near_critical", "bench_highs_lp", "bench_matrix", "bench_scale", "bench_3d",
            "bench_tree_cores", "bench_eta", "bench_sparse_form")


@pytest.mark.parametrize("name", TOLERANT)
def test_bench_table_without_its_file_says_not_measured(name, tmp_path, monkeypatch):
    """A table whose results are not in the checkout renders as "not measured", not a crash."""
    monkeypatch.setattr(docs_pages, "ROOT", str(tmp_path))
    out = docs_pages.render_markers(f"<!-- bench: {name} -->")
    assert out.startswith("|") and "not measured" in out


def _results(tmp_path, monkeypatch, name: str, doc: dict) -> None:
    monkeypatch.setattr(docs_pages, "ROOT", str(tmp_path))
    (tmp_path / "results").mkdir(exist_ok=True)
    (tmp_path / "results" / name).write_text(__import__("json").dumps(doc))


def test_global_scale_table_shows_peer_rows_and_missing_columns(tmp_path, monkeypatch):
    """Ours, a peer row ("engine") with its own columns, and a row cut at the limit with
    nothing but its case: one table row each, "–" where a column is missing."""
    ours = {"case": "plug3d-8x8", "m": 64, "status": "ok", "seconds": 3.18, "target_seconds": 10.0,
            "target_met": True, "rel_error": 4.7e-16, "route": "tree", "nodes": 131, "solves": 155, "lps": 0,
            "milp_solves": 0, "bound_solves": 1, "bound_certified": True, "undecided": 0}
    peer = {"case": "plug3d-8x8", "m": 64, "engine": "scip", "status": "ok", "seconds": 41.5, "rel_error": 5.6e-6,
            "milp_solves": 20, "milp_nodes": 900}
    _results(tmp_path, monkeypatch, "bench_global_scale.json",
             {"records": [ours, peer, {"case": "plug2d-r320", "status": "timeout", "seconds": 240.0}]})
    lines = docs_pages.bench_global_scale().splitlines()
    assert len(lines) == 5
    assert lines[2] == "| plug3d-8x8 | ours | 64 | 3.18 | ≤ 10 (met) | 4.7e-16 | tree | 131 | 155 / 0 | 0 | 1 / yes | 0 |"
    assert lines[3] == "| plug3d-8x8 | scip | 64 | 41.5 | – | 5.6e-06 | – | 900 | – / – | 20 | – | – |"
    assert lines[4] == "| plug2d-r320 | ours | – | > 240 (cut) | – | – | – | – | – / – | – | – | – |"


def test_near_critical_rows_before_then_after(tmp_path, monkeypatch):
    """Rows of one search and body in the order before, after, whatever the file's order."""
    row = {"task": "enumerate", "body": "plug3d", "levels": 4, "ring": 8, "m": 32, "mu": 0.2, "status": "ok",
           "wall": 10.0, "seconds": 9.0, "nodes": 100, "socps": 100, "lps": 0, "undecided": 0, "patterns": 1}
    _results(tmp_path, monkeypatch, "bench_near_critical.json",
             {"records": [dict(row, label="after", nodes=40), dict(row, label="before")]})
    lines = docs_pages.bench_near_critical().splitlines()
    assert [ln.split(" | ")[0] for ln in lines[2:]] == ["| before", "| after"]
    assert "| 100 | 100 |" in lines[2] and "| 40 | 100 |" in lines[3] and lines[2].endswith("| 1 pattern |")


def test_near_critical_probe_rows_say_how_much_of_the_tree_is_decided(tmp_path, monkeypatch):
    row = {"task": "probe", "body": "plug3d", "levels": 6, "ring": 8, "m": 48, "mu": 0.19, "status": "ok",
           "wall": 10.0, "seconds": 9.0, "nodes": 100, "socps": 100, "undecided": 0, "patterns": 1, "finished": False}
    _results(tmp_path, monkeypatch, "bench_near_critical.json",
             {"records": [dict(row, label="before"), dict(row, label="current", decided=0.0293627)]})
    lines = docs_pages.bench_near_critical().splitlines()
    assert lines[2].endswith("| 1 pattern (probe: not finished) |")
    assert lines[3].endswith("| 1 pattern (probe: not finished, 2.94 % of the tree decided) |")


def test_tree_cores_rows_with_and_without_cores(tmp_path, monkeypatch):
    """A neck record with its depths and cores, and a plug3d record of an earlier run without
    them: "every node feasible to depth" is the depth before the first infeasible node."""
    neck = {"body": "neck-4x8-s0", "m": 32, "mu": 0.3698, "nodes": 1945,
            "counts": {"feasible": 961, "infeasible": 972, "nogood_total": 10300, "fixed_total": 10790,
                       "nogood_would_prune": 4},
            "feasible_infeasible_by_depth": {"0": [1, 0], "5": [32, 0], "6": [62, 2], "7": [110, 14]},
            "core_summary": {"nodes": 80, "mean_fixings": 11.64, "mean_core": 9.76, "least_core": 6, "largest_core": 15},
            "nodes_by_first_branching": {"0": 1893, "1": 3467, "2": 1945}}
    plug = {"levels": 4, "ring": 8, "m": 32, "mu": 0.2, "nodes": 16367,
            "counts": {"feasible": 8184, "infeasible": 8183, "nogood_total": 0, "fixed_total": 0}}
    _results(tmp_path, monkeypatch, "bench_tree_pruning_neck_4x8.json", {"records": [neck]})
    _results(tmp_path, monkeypatch, "bench_tree_pruning.json", {"records": [plug]})
    lines = docs_pages.bench_tree_cores().splitlines()
    assert lines[2] == "| neck-4x8-s0 | 32 | 0.3698 | 1,945 | 961 / 972 | 5 | 9.8 of 11.6 (6–15; 80 nodes) | 10.6 of 11.1 | 4 | 1,893–3,467 |"
    assert lines[3] == "| plug3d-4x8 | 32 | 0.2 | 16,367 | 8,184 / 8,183 | – | – | 0.0 of 0.0 | 0 | – |"


def test_tree_fractions_rows_share_of_the_settling_tree(tmp_path, monkeypatch):
    """A row per record with a fraction, sorted by it; "of the settling tree's" divides by the
    nodes of the record closest above mu^c; a record without a fraction (a cores run) is left
    out, and a body without a record above mu^c shows a dash there."""
    def rec(f, nodes, seconds=1.0):
        return {"body": "neck-4x8-s0", "m": 32, "mu": 0.37 * f, "fraction_of_mu_c": f, "nodes": nodes,
                "seconds": seconds, "patterns": int(f > 1), "counts": {"feasible": nodes // 2, "infeasible": nodes // 2},
                "feasible_infeasible_by_depth": {"0": [1, 0], "6": [62, 2]}}
    cores = {"body": "neck-4x8-s0", "m": 32, "mu": 0.37, "nodes": 7, "fraction_of_mu_c": None}
    _results(tmp_path, monkeypatch, "bench_tree_pruning_neck_mu_4x8.json",
             {"records": [rec(1.1, 6000), rec(0.5, 100), rec(1.000000001, 2000), cores]})
    _results(tmp_path, monkeypatch, "bench_tree_pruning_neck_mu_6x8.json", {"records": [rec(0.8, 300)]})
    lines = docs_pages.bench_tree_fractions().splitlines()
    assert len(lines) == 6
    assert lines[2] == "| neck-4x8-s0 | 32 | 0.5 | 0.185 | 100 | 0.05 | 50 / 50 | 5 | 0 | 1.0 |"
    assert lines[3].startswith("| neck-4x8-s0 | 32 | 1.000000001 | 0.37 | 2,000 | 1.00 |")
    assert lines[4].startswith("| neck-4x8-s0 | 32 | 1.1 | 0.407 | 6,000 | 3.00 |")
    assert lines[5].startswith("| neck-4x8-s0 | 32 | 0.8 | 0.296 | 300 | – |")


def test_stress_global_rows_by_verdict(tmp_path, monkeypatch):
    """A row per verdict in GLOBAL_VERDICTS' order: cases, m range, largest |error|, how many
    had an unpolished brute-force value below, and the cases themselves unless they agree."""
    recs = [{"case": 0, "m": 6, "verdict": "agree", "rel_error": -5e-14, "unpolished_below": False},
            {"case": 1, "m": 10, "verdict": "agree", "rel_error": 2e-13, "unpolished_below": True},
            {"case": 2, "verdict": "timeout"},
            {"case": 3, "m": 7, "verdict": "flagged", "rel_error": -3e-8, "unpolished_below": True}]
    _results(tmp_path, monkeypatch, "stress_global_3d.json", {"records": recs})
    lines = docs_pages.stress_global_3d().splitlines()
    assert lines[2:] == ["| agree | 2 | 6–10 | 2.0e-13 | 1 | – |", "| flagged | 1 | 7–7 | 3.0e-08 | 1 | 3 |",
                         "| timeout | 1 | – | – | 0 | 2 |"]


def test_eta_table_rows(tmp_path, monkeypatch):
    """One row per case, one column per estimate (median told / left · share within 2x), the
    case's tree job seconds from its lines; an estimate without lines is a dash."""
    _results(tmp_path, monkeypatch, "bench_eta.json",
             {"records": [{"case": "neck-6x8-global", "job_s": 121.4}, {"case": "neck-6x8-global", "job_s": 121.4},
                          {"case": "plug", "job_s": 3.0}],
              "summary": [{"case": "neck-6x8-global", "estimate": "told", "lines": 20, "median_ratio": 0.91,
                           "within_2x": 0.85, "below_half": 0.05},
                          {"case": "neck-6x8-global", "estimate": "since start", "lines": 0},
                          {"case": "plug", "estimate": "told", "lines": 2, "median_ratio": 0.5, "within_2x": 1.0},
                          {"case": "plug", "estimate": "since start", "lines": 2, "median_ratio": 0.123, "within_2x": 0.0}]})
    lines = docs_pages.bench_eta().splitlines()
    assert lines[0] == "| case | tree job s | lines | told | since start |"
    assert lines[2] == "| neck-6x8-global | 121 | 20 | 0.91 · 85 % | – |"
    assert lines[3] == "| plug | 3 | 2 | 0.50 · 100 % | 0.12 · 0 % |"


def test_highs_lp_table_with_one_file_missing(tmp_path, monkeypatch):
    """With only the "before" file, its rows render and the missing files are named."""
    _results(tmp_path, monkeypatch, "bench_highs_lp_before.json",
             {"records": [{"model": "plug2d", "rows": 80, "m": 160, "status": "ok", "wall": 44.4, "cpu_with_setup": 8.67,
                           "route": "milp", "tree_nodes": 164, "lps": 155, "error": 8.7e-15}]})
    out = docs_pages.bench_highs_lp()
    assert "| plug2d | 80 | 160 | before | 44.4 | 8.67 | milp | 164 | 155 | 8.7e-15 |" in out
    assert "Not measured: bench_highs_lp_final.json, bench_highs_lp.json." in out
