"""lp.py: LP feasibility by HiGHS — the pyramids sandwich the cone (inscribed feasible =>
SOCP feasible => circumscribed feasible) — and the violation of a point (lp_violation)."""
import numpy as np
import pytest
from instances import random_partial_rows, random_problem, tree_walk

from hpcwedge.contact.problem import parametrize
from hpcwedge.solvers.feasibility import decide
from hpcwedge.solvers.lp import lp_feasible, lp_violation
from hpcwedge.solvers.rows import Status, pattern_rows, pyramid_rows


def test_pyramids_sandwich_the_cone():
    """inner feasible => SOCP feasible => outer feasible, on random partial patterns."""
    rng = np.random.default_rng(7)
    n_checked = 0
    for _ in range(40):
        rows = random_partial_rows(rng)
        for mu in (0.5, 1.5):
            s = decide(rows, mu).status
            si = lp_feasible(pyramid_rows(rows, 8, inner=True), mu)[0]
            so = lp_feasible(pyramid_rows(rows, 8, inner=False), mu)[0]
            if si == Status.FEASIBLE:
                assert s == Status.FEASIBLE
            if s == Status.FEASIBLE:
                assert so == Status.FEASIBLE
            n_checked += 1
    assert n_checked == 80


def test_lp_point_meets_its_rows_and_violation_measures_a_wrong_one():
    """A HiGHS point of a feasible 2D pattern meets every row to its tolerance (lp_violation
    ~ 1e-10); infeasible patterns return no point; a point that breaks a row is measured
    by the largest violation relative to ||x||."""
    n_feasible = n_infeasible = 0
    for seed in range(20):
        p = parametrize(random_problem(np.random.default_rng(seed), 3, bool(seed % 2)))
        zu = np.array([bool(seed & 1), bool(seed & 2), True])
        rows = pattern_rows(p, 3, zu, ~zu)
        for mu in (0.3, 3.0):
            status, x = lp_feasible(rows, mu)
            if status == Status.INFEASIBLE:
                assert x is None
                n_infeasible += 1
                continue
            assert status == Status.FEASIBLE and abs(rows.norm @ x - 1) <= 1e-9
            assert lp_violation(rows, mu, x) <= 1e-8
            assert lp_violation(rows, mu, -x) > 1e-3            # sum r_n = -1: some row broken
            n_feasible += 1
    assert n_feasible >= 5 and n_infeasible >= 5


def test_a_highs_solve_stopped_short_decides_nothing():
    """HIGHS_STATUS: stopped at its iteration limit (kIterationLimit), HiGHS leaves feasible
    and infeasible patterns alike UNDECIDED, both forms of the LP tried (lp_x_space), the
    eliminated one by both simplex methods (lp_primal)."""
    seen = set()
    for seed in range(6):
        p = parametrize(random_problem(np.random.default_rng(seed), 5, bool(seed % 2)))
        rows = pattern_rows(p, 5, np.zeros(5, bool), np.zeros(5, bool))
        counts: dict = {}
        status, x = lp_feasible(rows, 1.0, {"simplex_iteration_limit": 0, "presolve": "off"}, counts=counts)
        assert status == Status.UNDECIDED and x is None and counts == {"lp_primal": 1, "lp_x_space": 1}
        seen.add(lp_feasible(rows, 1.0)[0])
    assert seen == {Status.FEASIBLE, Status.INFEASIBLE}


def _x_space_lp(rows, mu):
    """The pattern LP as written (x in R^d, equality rows kept), by HiGHS through
    scipy.optimize.linprog with presolve: the independent route lp_feasible's
    elimination must agree with."""
    from scipy.optimize import linprog
    A = rows.a0 + mu * rows.a1
    A = A / np.linalg.norm(A, axis=1)[:, None]
    E, d = rows.eq, A.shape[1]
    A_eq = np.vstack([A[E], rows.norm[None, :]])
    b_eq = np.zeros(A_eq.shape[0])
    b_eq[-1] = 1.0
    res = linprog(np.zeros(d), A_ub=-A[~E], b_ub=np.zeros((~E).sum()), A_eq=A_eq, b_eq=b_eq,
                  bounds=[(None, None)] * d, method="highs-ds",
                  options={"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10})
    return {0: Status.FEASIBLE, 2: Status.INFEASIBLE}.get(res.status, Status.UNDECIDED)


def test_eliminated_lp_agrees_with_the_x_space_lp():
    """lp_feasible solves in the null space of the equalities; on random full and partial
    2D patterns (nodes in both sets too: dependent equality rows) at mu away from every
    pattern's mu^c it gives the x-space LP's answer, and a point on the equalities to
    rounding (|eq x| <= 1e-12, sum r_n = 1) that meets every row (lp_violation), without
    the x-space fallback but on rare near-recession points."""
    rng = np.random.default_rng(11)
    seen = {Status.FEASIBLE: 0, Status.INFEASIBLE: 0}
    counts: dict = {}
    for trial in range(60):
        m = int(rng.integers(3, 7))
        p = parametrize(random_problem(rng, m, bool(trial % 2)))
        zu, zr = rng.random(m) < 0.4, rng.random(m) < 0.4
        rows = pattern_rows(p, m, zu, zr)
        for mu in (0.2, 1.0, 5.0, np.inf):
            if not np.isfinite(mu):
                rows_mu, mu = pattern_rows(p, m, zu, zr, friction=False), 0.0
            else:
                rows_mu = rows
            status, x = lp_feasible(rows_mu, mu, counts=counts)
            ref = _x_space_lp(rows_mu, mu)
            assert status == ref, (trial, mu)
            if status == Status.FEASIBLE:
                A = rows_mu.a0 + mu * rows_mu.a1
                assert np.abs(A[rows_mu.eq] @ x).max(initial=0.0) <= 1e-12 * max(1.0, np.linalg.norm(x))
                assert abs(rows_mu.norm @ x - 1) <= 1e-9
                assert lp_violation(rows_mu, mu, x) <= 1e-9
            seen[status] += 1
    assert min(seen.values()) >= 30
    assert counts.get("lp_x_space", 0) <= 2            # the eliminated LP answered


def _same(a, b) -> bool:
    return a[0] == b[0] and (a[1] is None) == (b[1] is None) and (a[1] is None or np.array_equal(a[1], b[1]))


@pytest.mark.parametrize("chain", [False, True])
def test_tree_lp_agrees_with_the_cold_lp_and_its_points_meet_the_rows(chain):
    """TreeLp (one warm HiGHS model, row bounds changed per pattern; chain: each solve from
    the last one's basis) against lp_feasible (a
    new model per pattern in the equalities' null space, with presolve): the same answer on
    every pattern it decides, a feasible point meets the pattern's rows (lp_violation) with
    sum r_n = 1; on random supported and free bodies, patterns in a tree's order, mu near
    and far from where they change; a copy made by pickle (after solves) answers bit for bit
    as the original (every solve starts from the root pattern's basis; chained: the same
    answers)."""
    import pickle

    from hpcwedge.solvers.lp import TreeLp
    decided = {Status.FEASIBLE: 0, Status.INFEASIBLE: 0}
    unsure = 0
    for seed in range(8):
        rng = np.random.default_rng(seed)
        m = 6
        p = parametrize(random_problem(rng, m, bool(seed % 2)))
        for mu in (0.2, 0.9, 4.0):
            warm, counts = TreeLp(p, m, mu, chain), {}
            for zu, zr in tree_walk(rng, m, 40):
                status, x = warm.solve(zu, zr, counts)
                rows = pattern_rows(p, m, zu, zr)
                if status == Status.UNDECIDED:
                    unsure += 1
                    continue
                assert status == lp_feasible(rows, mu)[0], (seed, mu, zu, zr)
                decided[status] += 1
                if status == Status.FEASIBLE:
                    assert abs(rows.norm @ x - 1) <= 1e-9 and lp_violation(rows, mu, x) <= 1e-8
            again = pickle.loads(pickle.dumps(warm))     # as a tree sent to another rank: the same answers
            for zu, zr in list(tree_walk(np.random.default_rng(seed), m, 10)):
                a, b = again.solve(zu, zr), warm.solve(zu, zr)
                assert _same(a, b) if not chain else a[0] == b[0] or Status.UNDECIDED in (a[0], b[0])
            assert sum(counts.values()) == 40 and set(counts) <= {"warm_feasible", "warm_infeasible", "warm_unsure"}
    assert min(decided.values()) >= 100 and unsure <= 0.1 * sum(decided.values()), (decided, unsure)


def test_tree_lp_takes_a_long_point_met_to_rounding_on_a_meshed_block():
    """block2d rows 39 (m = 80) just above its all-contact mu^c: the dive's nodes (contact
    first) have feasible points of |x| ~ 10^2-10^3 whose normalisation share is below
    NORM_SHARE_MIN, their rows met to ~1e-15. TreeLp takes them (ROUNDING_RTOL: before, every
    one was "warm_unsure" and went to a cold lp_feasible, 1.3 s a node at m = 160), and so
    does lp_feasible's eliminated LP (no x-space LP: ~30 s a call at m = 320); the answers agree."""
    import math

    from instances import global_run

    from hpcwedge.solvers.lp import NORM_SHARE_MIN, ROUNDING_RTOL, TreeLp
    res = global_run({"kind": "block2d", "rows": 39, "taper_deg": 10.0}, mu_c="none")
    p, m = parametrize(res.problem), res.m
    mu = math.tan(math.radians(10)) * (1 + 4.6e-3)
    warm, counts, low_share = TreeLp(p, m, mu), {}, 0
    for j in range(0, m + 1, 8):
        zu = np.arange(m) < j
        status, x = warm.solve(zu, np.zeros(m, bool), counts)
        assert status == Status.FEASIBLE, (j, counts)
        rows = pattern_rows(p, m, zu, np.zeros(m, bool))
        cold = {}
        assert lp_feasible(rows, mu, counts=cold)[0] == Status.FEASIBLE and "lp_x_space" not in cold, cold
        assert lp_violation(rows, mu, x) <= ROUNDING_RTOL * np.linalg.norm(x)
        low_share += np.sqrt(x.size) / (np.linalg.norm(rows.norm) * np.linalg.norm(x)) < NORM_SHARE_MIN
    assert counts == {"warm_feasible": m // 8 + 1} and low_share >= 3, (counts, low_share)


def test_a_highs_call_at_its_time_limit_decides_nothing(monkeypatch):
    """LP_TIME_LIMIT_S bounds every LP: at 0 s HiGHS stops at once (kTimeLimit), and
    lp_feasible (both forms) and TreeLp leave feasible and infeasible patterns UNDECIDED."""
    import hpcwedge.solvers.lp as lp
    from hpcwedge.solvers.lp import TreeLp
    seen = set()
    for seed in range(6):
        p = parametrize(random_problem(np.random.default_rng(seed), 5, bool(seed % 2)))
        zu, zr = np.zeros(5, bool), np.zeros(5, bool)
        seen.add(lp_feasible(pattern_rows(p, 5, zu, zr), 1.0)[0])
        monkeypatch.setattr(lp, "LP_TIME_LIMIT_S", 0.0)
        counts: dict = {}
        assert lp_feasible(pattern_rows(p, 5, zu, zr), 1.0, counts=counts) == (Status.UNDECIDED, None)
        assert counts == {"lp_primal": 1, "lp_x_space": 1}
        assert TreeLp(p, 5, 1.0).solve(zu, zr, counts) == (Status.UNDECIDED, None)
        assert counts["warm_unsure"] == 1
        monkeypatch.undo()
    assert seen == {Status.FEASIBLE, Status.INFEASIBLE}


def test_a_model_kept_warm_gets_its_time_limit_on_every_run():
    """HiGHS sums an instance's run time over its runs and compares time_limit with the sum:
    a model run ~1 ms at a time under a limit of 0.2 s must still solve after more than 1 s
    of runs in all (it stopped at once, kTimeLimit, from the 0.2 s mark before highs_run
    re-armed the limit)."""
    from hpcwedge.solvers.lp import highs_instance, highs_lp, highs_run
    rng = np.random.default_rng(3)
    A = rng.standard_normal((20, 8))
    h = highs_instance({"presolve": "off"}, 0.2)
    h.passModel(highs_lp(A, np.full(20, -np.inf), np.ones(20), -np.ones(8), np.ones(8), rng.standard_normal(8)))
    runs = 0
    while h.getRunTime() < 1.0 and runs < 20000:
        h.changeColsCost(8, np.arange(8, dtype=np.int32), rng.standard_normal(8))
        assert highs_run(h) == Status.FEASIBLE, (runs, h.getRunTime(), h.getModelStatus())
        runs += 1
    assert h.getRunTime() >= 1.0, runs


def test_a_stop_interrupts_an_lp_past_its_grace_time(monkeypatch):
    """Inside a task the engine is stopping (parallel.cancel.run_cancellable), an LP shorter
    than INTERRUPT_AFTER_S ends with its answer (the caller's own check stops the task); with
    no grace time HiGHS is interrupted and TaskCancelled raised."""
    import pytest

    import hpcwedge.solvers.lp as lp
    from hpcwedge.parallel.cancel import TaskCancelled, run_cancellable
    p = parametrize(random_problem(np.random.default_rng(1), 5, True))
    rows = pattern_rows(p, 5, np.zeros(5, bool), np.zeros(5, bool))
    alone = lp_feasible(rows, 1.0)[0]
    assert alone != Status.UNDECIDED

    def stopping(ctx, payload):
        return lp_feasible(rows, 1.0)[0]
    assert run_cancellable(stopping, None, None, lambda: True, tick_every_s=0.0) == alone
    monkeypatch.setattr(lp, "INTERRUPT_AFTER_S", 0.0)
    with pytest.raises(TaskCancelled):
        run_cancellable(stopping, None, None, lambda: True, tick_every_s=0.0)



def test_a_stop_ends_the_cold_x_space_lp_of_a_meshed_block_within_a_second():
    """The slowest LP call here: lp_feasible's x-space LP of block2d rows 159 (m = 320), the
    all-contact pattern at tan 10 deg (1 + 4.5e-3) (a dense cold solve of ~30 s; HiGHS's
    presolve has no interrupt point, so a SIGTERM there waited 18 s). Run watched, a stop
    1 s in raises TaskCancelled within 1 s."""
    import math
    import time

    import pytest

    import hpcwedge.solvers.lp as lp
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.parallel.cancel import TaskCancelled, run_cancellable
    from hpcwedge.scene.parse import parse_scene
    prob = contact_problem(parse_scene({"name": "b", "dim": 2, "model": {"kind": "block2d", "rows": 159},
                                        "friction": {"mu": 0.1}}))
    p, m = parametrize(prob), prob.m
    rows = pattern_rows(p, m, np.ones(m, bool), np.zeros(m, bool))
    A = rows.a0 + math.tan(math.radians(10)) * (1 + 4.5e-3) * rows.a1
    A, E = A / np.linalg.norm(A, axis=1, keepdims=True), rows.eq

    def x_space(ctx, payload):
        return lp._highs(A[~E], np.vstack([A[E], rows.norm[None, :]]), A.shape[1], None, "simplex", watched=True)
    start = time.monotonic()
    with pytest.raises(TaskCancelled):
        run_cancellable(x_space, None, None, lambda: time.monotonic() - start > 1.0, tick_every_s=0.0)
    assert time.monotonic() - start < 2.0
    lp._join_left_running()    # HiGHS's thread, asked to stop, ends at its next interrupt point: one
    #                            solve at a time in a process (highspy), and the tests go on in this one


def test_image_point_agrees_with_the_lp_in_x_on_the_all_contact_pattern():
    """image_point (an LP in b = R_n x >= 0 with the left null space of [U_n; R_n] as its
    only rows) against lp_feasible (the LP in x) on the all-contact pattern without friction
    (u_n = 0, r_n >= 0, sum r_n = 1) of random supported and free bodies: a point whose rows
    hold to 1e-10 exactly where lp_feasible finds the pattern feasible, both kinds met."""
    from hpcwedge.solvers.lp import image_point
    seen = {True: 0, False: 0}
    for seed in range(40):
        rng = np.random.default_rng(900 + seed)
        m = int(rng.integers(2, 7))
        p = parametrize(random_problem(rng, m, bool(seed % 2)))
        rows = pattern_rows(p, m, np.ones(m, bool), np.zeros(m, bool), friction=False)
        x = image_point(p.U[:m], p.R[:m])
        holds = x is not None and abs(rows.norm @ x - 1) <= 1e-10 and lp_violation(rows, 0.0, x) <= 1e-10
        assert holds == (lp_feasible(rows, 0.0)[0] == Status.FEASIBLE), seed
        seen[holds] += 1
    assert min(seen.values()) >= 2, seen


def _waits_during(fn, *args, **kwargs) -> int:
    """How many times dense.interruptible's waiting thread woke while fn(*args) ran (a poll
    registered for the call)."""
    from hpcwedge import dense
    woke = []
    poll = lambda: woke.append(1)       # noqa: E731
    dense.on_wait(poll)
    try:
        fn(*args, **kwargs)
    finally:
        dense._polls.remove(poll)
    return len(woke)


def test_image_point_and_the_null_projection_serve_waits_during_their_long_calls():
    """image_point's SVD and pattern_lp._null_projection's QR go through dense.dense_call: on
    matrices of ~2 million entries (0.3-2 s each here) the waiting thread wakes several times,
    so a signal or a stopping task is served within a step (scipy's wrappers, used before,
    keep the GIL for the whole call). Their answers stand: a point of the constraints, and a
    vector in the null space of A_S^T."""
    from hpcwedge.solvers.lp import image_point
    from hpcwedge.solvers.pattern_lp import _null_projection
    rng = np.random.default_rng(3)
    G = rng.standard_normal((1400, 1400))
    assert _waits_during(image_point, np.zeros((0, 1400)), G) >= 2
    x = image_point(np.zeros((0, 1400)), G)
    assert x is not None and (G @ x).min() > -1e-9 and abs((G @ x).sum() - 1.0) < 1e-9
    A, y = rng.standard_normal((1800, 1200)), rng.standard_normal(1800)
    assert _waits_during(_null_projection, A, y) >= 2
    z = _null_projection(A, y)
    assert np.abs(A.T @ z).max() < 1e-9 * np.abs(y).max() and np.linalg.norm(z) > 0.1
