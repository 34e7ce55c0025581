"""milp.py: the wedge MILP (HiGHS) of a 2D body — infeasible just below mu^c, feasible just
above with a pattern our LP confirms — and HiGHS's debug prints kept off stdout. The global
route that uses it: test_global_mu_c.py."""
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from instances import global_run

from hpcwedge.contact.problem import parametrize
from hpcwedge.solvers.feasibility import decide
from hpcwedge.solvers.milp import wedge_milp
from hpcwedge.solvers.rows import Status, pattern_rows


def test_wedge_milp_decides_around_mu_c_and_its_pattern_verifies():
    res = global_run({"kind": "plug2d", "rows": 3, "taper_deg": 10.0})
    p, m = parametrize(res.problem), res.m
    mu_c = math.tan(math.radians(10.0))
    assert wedge_milp(p, m, 0.99 * mu_c).status == Status.INFEASIBLE
    ans = wedge_milp(p, m, 1.01 * mu_c)
    assert ans.status == Status.FEASIBLE and ans.value > 0.5
    assert np.array_equal(ans.zero_u, ~ans.zero_r)
    assert decide(pattern_rows(p, m, ans.zero_u, ans.zero_r), 1.01 * mu_c).status == Status.FEASIBLE
    stopped = wedge_milp(p, m, 1.01 * mu_c, time_limit=0.0)          # HiGHS's time limit: no answer
    assert stopped.status == Status.UNDECIDED and stopped.zero_u is None


def test_a_milp_past_its_node_limit_is_undecided_and_the_search_falls_back_to_the_tree(monkeypatch):
    """milp.MILP_NODE_LIMIT (HiGHS's mip_max_nodes): on plug2d at a 0 deg taper (rows 5, m =
    10; elasticity sets mu^c, 0.8142, the rigid bound is 0) the MILP route (MILPs of up to
    ~700 nodes) gives the tree route's answer; with the limit at 1 node its first MILP is
    UNDECIDED and the search falls back to the tree (route "tree"), with the same answer."""
    import hpcwedge.solvers.milp as milp
    from hpcwedge.mu_c.global_search import global_mu_critical
    from hpcwedge.patterns.tree import BnBStats
    res = global_run({"kind": "plug2d", "rows": 5, "taper_deg": 0.0}, mu_c="none")
    p, m = parametrize(res.problem), res.m
    want, _ = global_mu_critical(p, m, 100.0, route="tree")
    assert 0.8 < want < 0.83
    routed = BnBStats()
    mu, _ = global_mu_critical(p, m, 100.0, stats=routed, route="milp")
    assert routed.extra["route"] == "milp" and routed.extra["milp_nodes"] > 1 and abs(mu - want) <= 1e-12 * want
    monkeypatch.setitem(milp.MILP_OPTIONS, "mip_max_nodes", 1)
    limited = BnBStats()
    mu, _ = global_mu_critical(p, m, 100.0, stats=limited, route="milp")
    assert limited.extra["route"] == "tree" and limited.statuses["milp_undecided"] == 1
    assert abs(mu - want) <= 1e-12 * want


def test_highs_debug_prints_never_reach_stdout():
    """HiGHS's MIP solver printf()s debug lines past its output_flag on these bodies (6 lines
    without lp.stdout_silenced); stdout carries `hpcwedge run --json`."""
    code = f"""
import sys
sys.path.insert(0, {os.path.dirname(os.path.dirname(os.path.abspath(__file__)))!r})
from functools import partial
import numpy as np
from instances import random_problem
from hpcwedge.mu_c.critical import mu_critical
from hpcwedge.mu_c.global_search import global_bracket_milp
from hpcwedge.patterns.tree import BnBStats
from hpcwedge.contact.problem import parametrize
for seed in range(100, 106):
    prob = random_problem(np.random.default_rng(seed), 6, free=seed % 2 == 0)
    p = parametrize(prob)
    global_bracket_milp(p, prob.m, 50.0, partial(mu_critical, p, prob.m, mu_max=50.0), BnBStats(), dive=0)
print("done")
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout == "done\n"


def test_a_stop_interrupts_a_long_milp_within_half_a_second():
    """HiGHS's branch and bound polls the engine's stop (lp.highs_instance's interrupt
    callbacks): plug2d rows 40 (m = 80) at mu = 100 runs past 30 s, and a stop asked 1 s in
    raises TaskCancelled within 0.5 s of it (before: the MILP ran to its end, > 145 s at m =
    640, whatever the signal)."""
    import time

    from hpcwedge.parallel.cancel import TaskCancelled, run_cancellable
    res = global_run({"kind": "plug2d", "rows": 40, "taper_deg": 10.0}, mu_c="none")
    p, m = parametrize(res.problem), res.m
    assert wedge_milp(p, m, 100.0, time_limit=3.0).status == Status.UNDECIDED     # longer than 3 s
    start = time.monotonic()
    asked = []

    def check():
        if time.monotonic() - start >= 1.0:
            asked.append(asked[0] if asked else time.monotonic())
            return True
        return False
    with pytest.raises(TaskCancelled):
        run_cancellable(lambda ctx, payload: wedge_milp(p, m, 100.0), None, None, check)
    assert asked and time.monotonic() - asked[0] < 0.5, time.monotonic() - start
    # the next solve starts although the stopped one may still run (highspy's run locks are
    # shared by every instance: before, "Solver is already running" under load)
    assert wedge_milp(p, m, 100.0, time_limit=0.5).status == Status.UNDECIDED


MILP_RUN = """
import functools, sys
import hpcwedge.mu_c.global_search as gs
from hpcwedge import cli
milp, bracket = gs.wedge_milp, gs.global_bracket_milp

def announced(param, m, mu, *args, **kw):
    print(f"MILP at mu = {mu}", file=sys.stderr, flush=True)
    return milp(param, m, mu, *args, **kw)

gs.wedge_milp = announced
gs.global_bracket_milp = functools.partial(bracket, dive=0)      # every step a MILP
gs.floor_candidate = lambda *args, **kw: None                    # no pattern at the floor
sys.exit(cli.main())
"""


def test_sigterm_inside_a_long_milp_exits_75_within_2_s_with_a_checkpoint(tmp_path):
    """`hpcwedge run` (global mu^c, plug2d rows 40, m = 80, the MILP route without its dive
    and without the floor's pattern, which would end the search before any MILP)
    gets SIGTERM 1 s into its MILP at mu_max = 100 (a 46 s HiGHS call on its own): exit 75
    with the checkpoint written, within 2 s of the process's CPU time after the signal and
    2 s of wall time (times the machine's load per core, when it is shared beyond its cores).
    Before: the signal waited for the MILP's end (13 s even with only the simplex polled)."""
    import signal
    import time

    import h5py
    from mpi_helpers import cpu_seconds, env

    from hpcwedge.files import checkpoint_path
    scene = tmp_path / "s.toml"
    scene.write_text('name = "p"\ndim = 2\n[model]\nkind = "plug2d"\nrows = 40\ntaper_deg = 10.0\n'
                     '[friction]\nmu = [0.1]\n[compute]\nenumerate = false\nmu_c = "global"\n'
                     '[run]\nsymmetry = false\n')
    out = str(tmp_path / "r.h5")
    p = subprocess.Popen([sys.executable, "-c", MILP_RUN, "run", str(scene), "-o", out, "-q"], env=env(),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        for line in p.stderr:
            if line.startswith("MILP at mu = 100"):
                break
        else:
            pytest.fail(f"no MILP at mu_max: exit {p.wait()}")
        time.sleep(1.0)
        assert p.poll() is None
        cpu = cpu_seconds(p.pid)
        p.send_signal(signal.SIGTERM)
        t = time.monotonic()
        _, status, usage = os.wait4(p.pid, 0)
        took = time.monotonic() - t
        p.returncode = os.waitstatus_to_exitcode(status)
    finally:
        if p.poll() is None:
            p.kill()
    cpu = usage.ru_utime + usage.ru_stime - cpu
    load = max(1.0, os.getloadavg()[0] / os.cpu_count())
    rest = p.stderr.read()
    assert p.returncode == 75 and cpu < 2.0 and took < 2.0 * load, (p.returncode, cpu, took, load, rest)
    with h5py.File(checkpoint_path(out), "r") as f:
        assert f.attrs["reason"] == "SIGTERM"
