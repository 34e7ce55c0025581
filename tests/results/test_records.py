"""The records of a solve (results/record.py, SPEC §4): Run's counts, SolveStats with its
sub-records as the stats object of the result file, in the file's key order; Result.to_dict
as `show --json` prints the result's file; read_result as the Result written."""
import contextlib
import io
import json

import numpy as np
import pytest

from hpcwedge.cli import main
from hpcwedge.results.hdf5 import read_result, write_result
from hpcwedge.results.record import (
    NOT_COMPUTED,
    Cone,
    GlobalRouteStats,
    Pattern,
    Result,
    Run,
    SolveStats,
    StoredModel,
    SymmetryStats,
    TreeStats,
)


def test_solve_stats_as_dict_is_the_file_object():
    """SolveStats.as_dict: the fields that are set, in the result file's key order."""
    s = SolveStats()
    assert s.as_dict() == {"dd": [], "lp_solves": 0, "mu_c_polished": 0, "mu_c_unpolished": 0, "lp_undecided": 0}
    s.add(solves=3, undecided=1, polished=1)
    s.add(unpolished=2)
    s.symmetry = SymmetryStats(2)
    s.bnb = TreeStats.of({"solves": 4, "status_optimal": 1}, partitions=8)
    s.numerics = {}
    d = s.as_dict()
    assert list(d) == ["dd", "lp_solves", "mu_c_polished", "mu_c_unpolished", "lp_undecided", "symmetry", "bnb",
                       "numerics"]
    assert (d["lp_solves"], d["lp_undecided"], d["mu_c_polished"], d["mu_c_unpolished"]) == (3, 1, 1, 2)
    assert d["symmetry"] == {"order": 2}
    assert d["bnb"] == {"nodes": 0, "solves": 4, "skipped": 0, "pruned": 0, "undecided": 0, "lps": 0,
                        "partitions": 8}
    s.bnb = GlobalRouteStats(solves=1, nodes=2, route="milp")
    assert list(s.as_dict()["bnb"]) == ["solves", "skipped", "undecided", "nodes", "route", "milp_solves",
                                        "milp_nodes", "pruned", "lps", "unsettled", "bound_solves",
                                        "bound_certified"]


def test_run_counts_are_none_until_asked():
    """Run.n_*: len of the field, None while the scene did not ask for it."""
    run = Run(mu=0.5)
    assert (run.n_wedged_rays, run.n_trivial_rays, run.n_cones, run.n_patterns) == (None, None, None, None)
    run = Run(mu=0.5, rays=np.zeros((3, 4)), trivial_rays=np.zeros((0, 4)), cones=[{}, {}], patterns=[])
    assert (run.n_wedged_rays, run.n_trivial_rays, run.n_cones, run.n_patterns) == (3, 0, 2, 0)


def test_tree_stats_of_counters():
    """TreeStats.of: a patterns job's counters, absent ones 0, and the partitions given."""
    t = TreeStats.of({"nodes": 5, "pruned": 2, "status_optimal": 7}, partitions=16)
    assert t == TreeStats(nodes=5, solves=0, skipped=0, pruned=2, undecided=0, lps=0, partitions=16)


# ---- Result.to_dict and read_result: the record and its file -------------------------------

SOLVED = {"2d": dict(kind="plug2d", rows=3, mu=[0.3, 0.65]),
          "2d-no-mu_c": dict(kind="plug2d", rows=3, mu=[0.3, 0.65], mu_c="none"),
          "3d": dict(kind="plug3d", ring=3, mu=[0.3, 0.65]),
          "3d-no-mu_c": dict(kind="plug3d", ring=3, mu=[0.65], mu_c="none")}


@pytest.fixture(scope="module", params=sorted(SOLVED))
def written(request, tmp_path_factory):
    """(a solved Result, the result file write_result made of it)."""
    import hpcwedge as hw
    options = dict(SOLVED[request.param])
    r = hw.solve(hw.Scene.builtin(options.pop("kind"), **options))
    path = str(tmp_path_factory.mktemp("res") / "r.h5")
    hw.write_result(r, path)
    return r, path


def _show_json(path: str, *flags: str) -> str:
    """What `hpcwedge show PATH --json` prints."""
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["show", path, "--json", *flags]) == 0
    return buf.getvalue()


def test_to_dict_is_what_show_json_prints(written):
    """Result.to_dict(), made from the record alone, is the object `show --json` prints of its
    file, key order included; with_rays=False that of --no-rays."""
    r, path = written
    for flags, with_rays in (((), True), (("--no-rays",), False)):
        shown = json.loads(_show_json(path, *flags))
        assert r.to_dict(with_rays) == shown
        assert json.dumps(r.to_dict(with_rays)) == json.dumps(shown)        # the keys' order too
    cones_or_patterns = [run.cones or run.patterns for run in r.runs]
    assert all(isinstance(i, (Cone, Pattern)) for items in cones_or_patterns for i in items)
    computed = r.scene.mu_c != "none"
    assert all((i.mu_c is not None) == computed and (i.mu_c_polished is NOT_COMPUTED) != computed
               for items in cones_or_patterns for i in items)
    assert all(("mu_c_polished" in i) == computed for run in shown["runs"]
               for i in (run["cones"] or run["patterns"]))


def test_read_result_is_the_result_written(written):
    """read_result gives back the Result that was written, field for field: the scene, the
    runs (rays and zero flags bit for bit, the same Cone and Pattern records), mu^c, stats;
    the body as the file keeps it; no problem (not stored)."""
    r, path = written
    back = read_result(path)
    assert isinstance(back, Result) and back.scene == r.scene and back.scene.hash == r.scene.hash
    for name in ("m", "mu_c", "mu_c_status", "complete", "stages", "timings", "stats", "version"):
        assert getattr(back, name) == getattr(r, name), name
    assert len(back.runs) == len(r.runs)
    for a, b in zip(back.runs, r.runs):
        assert a.mu == b.mu and a.cones == b.cones and a.patterns == b.patterns
        for name in ("rays", "trivial_rays", "ray_zero"):
            x, y = getattr(a, name), getattr(b, name)
            assert (x is None) == (y is None), name
            if x is not None:
                assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), name
    assert back.problem is None and isinstance(back.model, StoredModel)
    for name in ("coords", "contact_nodes", "normals"):
        assert np.array_equal(getattr(back.model, name), getattr(r.model, name)), name
    assert back.model.cells.keys() == r.model.cells.keys()
    assert back.to_dict() == r.to_dict()
    light = read_result(path, with_rays=False)
    assert all(run.rays is None and run.trivial_rays is None for run in light.runs)
    assert [(a.n_wedged_rays, a.n_trivial_rays, a.n_cones, a.n_patterns) for a in light.runs] == \
        [(b.n_wedged_rays, b.n_trivial_rays, b.n_cones, b.n_patterns) for b in r.runs]
    assert light.to_dict(with_rays=False) == r.to_dict(with_rays=False)


def test_a_result_read_back_writes_the_same_file_object(written, tmp_path):
    """write_result(read_result(file)) stores what the file held: show --json is the same."""
    r, path = written
    again = str(tmp_path / "again.h5")
    write_result(again, read_result(path))
    assert _show_json(again) == _show_json(path)
