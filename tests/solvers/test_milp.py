"""milp.py: the wedge MILP (HiGHS) of a 2D body — infeasible just below mu^c, feasible just
above with a pattern our LP confirms — and HiGHS's debug prints kept off stdout. The global
route that uses it: test_global_mu_c.py."""
import math
import os
import subprocess
import sys

import numpy as np
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

    import pytest

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
