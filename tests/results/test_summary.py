"""`hpcwedge show`'s text (results/summary.py): small runs list every item, large ones give
the first, the least mu^c (checked against a scan of the items), the spread and how to list
them all; runs numbered from 0 as the JSON's list."""
import random

from hpcwedge.results.record import Cone, Pattern, Result, Run
from hpcwedge.results.summary import LIST_MAX, show_lines
from hpcwedge.scene.parse import parse_scene

SCENE3 = parse_scene({"name": "s3", "dim": 3, "model": {"kind": "plug3d"}, "friction": {"mu": [0.5, 1.0]}})


def _patterns(n: int, seed: int) -> list[Pattern]:
    rng = random.Random(seed)
    return [Pattern(contact=sorted(rng.sample(range(9), 3)), mu_c=rng.uniform(0.1, 0.9), mu_c_polished=True)
            for _ in range(n)]


def test_large_run_is_summarised_small_run_listed():
    small, large = _patterns(LIST_MAX, 1), _patterns(500, 2)
    res = Result(scene=SCENE3, m=9, runs=[Run(mu=0.5, patterns=small), Run(mu=1.0, patterns=large)],
                 mu_c=0.1, mu_c_status="found", timings={"total": 1.0})
    lines = show_lines(res, "r.h5")
    assert len(lines) == 2 + 1 + LIST_MAX + 1 + 4 + 1
    rows = [ln.split() for ln in lines if ln[:3].strip().isdigit()]
    assert [(r[0], r[1], r[-1]) for r in rows] == [("0", "0.5", str(LIST_MAX)), ("1", "1.0", "500")]
    least = min(range(500), key=lambda j: large[j].mu_c)      # the independent scan
    big = lines[lines.index(next(ln for ln in lines if ln.startswith("  1 "))) + 1:]
    assert big[0].startswith(f"         pattern 0: contact {large[0].contact}") and big[0].endswith("(the first)")
    assert big[1].startswith(f"         pattern {least}: ") and big[1].endswith("(the least mu_c)")
    assert f"{large[least].mu_c:.12g} to {max(p.mu_c for p in large):.12g}" in big[2]
    assert big[3] == "         498 more not listed: hpcwedge show r.h5 --all"
    every = show_lines(res, "r.h5", every_item=True)
    assert len(every) == 2 + 2 + LIST_MAX + 500 + 1
    assert every[-2].startswith("         pattern 499: ")


def test_summary_of_cones_without_values():
    scene = parse_scene({"name": "s2", "dim": 2, "model": {"kind": "plug2d"}, "friction": {"mu": 0.6}})
    cones = [Cone(rays=[j], trivial_rays=[], zero_u=[j], zero_r=[]) for j in range(LIST_MAX + 1)]
    res = Result(scene=scene, m=8, runs=[Run(mu=0.6, cones=cones)], timings={"total": 0.5})
    lines = show_lines(res, "x.h5")
    assert lines[3].endswith("mu_c - (the first)")
    assert lines[4] == f"         {LIST_MAX:,} more not listed: hpcwedge show x.h5 --all"
