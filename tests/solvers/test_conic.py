"""One Clarabel solve (conic.py): the settings as values, the matrix as the binding reads
it, the kept solvers' answers against new ones."""
import numpy as np
from instances import partial_masks, partial_rows, plug3d_param

from hpcwedge.solvers.conic import CLARABEL_STATUS, LONG_STEP, settings
from hpcwedge.solvers.rows import Status, pattern_rows
from hpcwedge.solvers.socp import pattern_socp


def test_settings_are_values():
    assert settings(0, True).tol_feas == 1e-10 and settings(0, False).tol_feas != 1e-10
    assert settings(2, False).static_regularization_constant == 1e-7
    assert not settings(0, False).equilibrate_enable and settings(3, False).equilibrate_enable
    assert settings(1, True) is settings(1, True)               # cached: one object per (attempt, tight)
    # long steps: only on a feasibility problem's first attempt, and only when asked for
    assert settings(0, False, True, long_steps=True).max_step_fraction == LONG_STEP > 0.99
    assert settings(0, False, True).max_step_fraction == settings(0, False).max_step_fraction == 0.99
    assert settings(1, False, True, long_steps=True).max_step_fraction == 0.99


def test_the_status_map_names_every_clarabel_status():
    """CLARABEL_STATUS lists every status of the installed Clarabel (one it did not would be
    read as UNDECIDED unseen), and only a solved problem and a certificate of primal
    infeasibility decide."""
    import clarabel
    names = {str(v) for v in vars(clarabel.SolverStatus).values() if isinstance(v, clarabel.SolverStatus)}
    assert set(CLARABEL_STATUS) == names
    decided = {name: s for name, s in CLARABEL_STATUS.items() if s != Status.UNDECIDED}
    assert decided == {"Solved": Status.FEASIBLE, "PrimalInfeasible": Status.INFEASIBLE}


def test_reaction_matrix_is_stored_as_clarabel_reads_it():
    """reaction_socp's DenseDiag: its dense form has the sum-r_n row on the r_n columns and
    (-mu / g, -1, -1) below the reactions, a cone's slack being (mu r_n, r_t) / g of the
    point (read from the parametrisation's own rows; g = mu below BALANCE_MU, else 1); A^T z
    agrees with the dense product; the CSC handed to Clarabel, rebuilt by scipy, is the same
    matrix entry for entry (sorted indices, no duplicates), as is a dense matrix's. At a
    10 deg taper the plain form; at 0.1 deg with mu < BALANCE_MU the balanced one, the rigid
    amplitudes' u_n block orthonormal."""
    from hpcwedge.solvers.socp import BALANCE_MU, _reaction_layout
    rng = np.random.default_rng(3)
    for taper, (lo, hi) in ((10.0, (0.2, 1.0)), (0.1, (0.001, 0.04))):
        p, m = plug3d_param(2, 4, taper_deg=taper)
        lay = _reaction_layout(p.reactions, m)
        block = lay.rest[p.reactions.E.shape[0]:, lay.beta]
        whitened = lay.beta_map is not None
        assert whitened == (taper < 1)
        if whitened:
            assert np.allclose(block.T @ block, np.eye(len(lay.beta)), rtol=0, atol=1e-8)
        checked = 0
        for _ in range(20):
            masks = partial_masks(rng, m)
            if masks is not None:
                mu = rng.uniform(lo, hi)
                _check_reaction_matrix(p, m, pattern_rows(p, m, *masks), mu, mu if mu < BALANCE_MU else 1.0, rng)
                checked += 1
        assert checked >= 10


def _check_reaction_matrix(p, m, rows, mu, g, rng):
    import scipy.sparse as sp
    from scipy.linalg import null_space

    from hpcwedge.solvers.conic import DenseDiag, _clarabel_csc
    from hpcwedge.solvers.socp import reaction_socp
    socp = reaction_socp(rows, mu)
    A = socp.problem.A
    assert isinstance(A, DenseDiag)
    dense = A.toarray()
    c = len(rows.nodes)
    assert np.array_equal(dense[0, :3 * c], np.tile([1.0, 0.0, 0.0], c)) and not dense[0, 3 * c:].any()
    assert np.array_equal(dense[A.k:, :3 * c], np.diag(np.tile([-mu / g, -1.0, -1.0], c)))
    assert not dense[A.k:, 3 * c:].any()
    z = rng.standard_normal(A.shape[0])
    assert np.allclose(A.rmatvec(z), dense.T @ z, rtol=0, atol=1e-13)
    # the dense rows: unit rows; a lin row's slack s = -A w is u_n / |row| of its node,
    # u_n = U x at the point x of w (the parametrisation's own rows, another route)
    assert np.allclose(np.linalg.norm(dense[1:A.k], axis=1), 1.0, rtol=0, atol=1e-14)
    w = rng.standard_normal(A.shape[1])
    lin = slice(socp.problem.n_zero, socp.problem.n_zero + socp.problem.n_lin)
    x = socp.to_x(w)
    u_n = p.U[:m] @ x
    # to rounding of the terms summed (a whitened amplitude's map reaches 1 / 1.5e-6 here)
    assert np.allclose(-(dense @ w)[lin] * socp.lin_scale, u_n[socp.lin_nodes], rtol=0,
                       atol=1e-13 * (np.abs(p.U[:m]) @ np.abs(x)).max())
    # on the equalities (equilibrium among them) r is the point's own reactions
    N = null_space(dense[1:socp.problem.n_zero])
    w = N @ rng.standard_normal(N.shape[1])
    r = p.R @ socp.to_x(w)
    cone = np.stack([mu * r[rows.nodes], r[m + rows.nodes], r[2 * m + rows.nodes]], axis=1).ravel() / g
    assert np.allclose(-(dense @ w)[A.k:], cone, rtol=0, atol=1e-12 * np.abs(cone).max())
    for M, ref in ((A, dense), (dense, dense)):
        h = _clarabel_csc(M)
        assert h.has_canonical_format and h.nnz == len(h.data) and h.shape == ref.shape
        back = sp.csc_matrix((h.data, h.indices, h.indptr), shape=h.shape)
        assert back.has_canonical_format and np.array_equal(back.toarray(), ref)


def test_kept_solvers_answer_as_new_ones_bit_for_bit(monkeypatch):
    """A problem solved by a data update of a kept solver of its structure (_KeptSolvers)
    gets the answer a new solver gives, bit for bit: the tree's SOCPs (reaction form,
    attempt 0, long steps) of random partial patterns of plug3d 2 x 4 at two mu, and the
    dense null-space form's retries (attempts 1 and 2), steered (with an objective) and
    plain; among them failures (NumericalError), which a kept solver would answer from
    the previous problem's last iterate. Many reuse a solver; the kept ones stay within
    both bounds."""
    from dataclasses import replace

    from hpcwedge.solvers import conic
    from hpcwedge.solvers.socp import reaction_socp
    p, m = plug3d_param(2, 4)
    rng = np.random.default_rng(11)
    problems = []
    for mu, rows in partial_rows(p, m, rng, (0.4, 0.9), 40):
        problems.append((reaction_socp(rows, mu).problem, 0, False, True))
        dense = pattern_socp(rows, mu)
        problems.append((dense, 1 + int(rng.integers(2)), False, False))
        problems.append((replace(dense, q=rng.standard_normal(dense.A.shape[1])), 0, True, False))

    def answers(kept):
        monkeypatch.setattr(conic, "_KEPT", kept)
        out = [conic.solve(*args) for args in problems]
        return [(s.status, s.name, s.x.tobytes(), s.z.tobytes()) for s in out]

    new = answers(conic._KeptSolvers(0, 0))
    reused = 0
    take = conic._KeptSolvers.take

    def counted(self, key):
        nonlocal reused
        solver = take(self, key)
        reused += solver is not None
        return solver

    monkeypatch.setattr(conic._KeptSolvers, "take", counted)
    assert answers(conic._KeptSolvers(64, 1 << 20)) == new
    assert reused >= len(problems) // 5
    small = conic._KeptSolvers(4, 300)
    assert answers(small) == new
    assert 0 < len(small._solvers) <= 4 and small._stored <= 300
    # settled answers and others (solved again on a new solver) both among them
    assert {name for _, name, _, _ in new} > {"Solved", "PrimalInfeasible"}


def test_a_task_starts_without_kept_solvers_and_gives_them_back():
    """conic.task_solvers (entered around every engine task): no kept solver inside, the
    task's own dropped, the caller's back after it."""
    from hpcwedge.parallel.cancel import run_cancellable
    from hpcwedge.solvers import conic
    p, m = plug3d_param(2, 4)
    rows = next(iter(partial_rows(p, m, np.random.default_rng(3), (0.9,), 1)))[1]
    problem = pattern_socp(rows, 0.9)
    conic.solve(problem, 1, False)
    outer = dict(conic._KEPT._solvers)
    assert outer

    def task(ctx, payload):
        assert not conic._KEPT._solvers
        conic.solve(problem, 2, False)
        return set(conic._KEPT._solvers)

    inside = run_cancellable(task, None, None, lambda: False)
    assert inside and not inside & set(outer)
    assert conic._KEPT._solvers == outer
def test_a_solve_is_bounded_in_time_and_stops_with_its_task():
    """Every attempt carries Clarabel's time limit; inside a task the engine stops, a solve
    raises TaskCancelled within an interior-point iteration or two (Clarabel's termination
    callback asks task_stopping), on a new solver and on a kept one, where outside a task
    the same problem is decided. plug3d 4 x 8 (m = 32), every node in contact."""
    import time

    import pytest

    from hpcwedge.parallel.cancel import TaskCancelled, run_cancellable
    from hpcwedge.solvers.conic import TIME_LIMIT_S, solve
    assert all(settings(k, t, f).time_limit == TIME_LIMIT_S for k in range(4) for t in (False, True) for f in (False, True))
    p, m = plug3d_param(4, 8)
    problem = pattern_socp(pattern_rows(p, m, np.ones(m, bool), np.zeros(m, bool)), 0.5)
    asked = []

    def check():
        asked.append(time.monotonic())
        return len(asked) > 2                   # go on for two iterations, then stop

    for _ in range(2):                          # a new solver, then the kept one
        with pytest.raises(TaskCancelled):
            run_cancellable(lambda ctx, pb: solve(pb, 1, False), None, problem, check, tick_every_s=0.0)
        assert len(asked) == 3
        asked.clear()
    assert solve(problem, 1, False).status != Status.UNDECIDED


def test_a_large_solve_runs_on_one_thread_with_the_bits_of_one_core(tmp_path):
    """The thread policy holds for Clarabel: a pattern SOCP of plug3d 8 x 16 (m = 128, whose
    KKT system Clarabel's "auto" hands to faer's LDL) solved in a fresh process leaves no
    solver threads behind, and gives the same bits as in a process confined to one core (a
    rank Open MPI binds). With faer's default, one thread per core, the process had 2 more
    threads on 2 cores and another x (the BLAS on one thread, as the command line has it)."""
    import os
    import subprocess
    import sys

    from mpi_helpers import ROOT
    if len(os.sched_getaffinity(0)) < 2:
        import pytest
        pytest.skip("needs 2 cores: on one, one thread per core is one thread")
    code = ("import os, sys, hashlib, numpy as np\n"
            "sys.path.insert(0, 'tests')\n"
            "from instances import plug3d_param\n"
            "from hpcwedge.solvers.conic import solve\n"
            "from hpcwedge.solvers.rows import pattern_rows\n"
            "from hpcwedge.solvers.socp import pattern_socp\n"
            "p, m = plug3d_param(8, 16)\n"
            "problem = pattern_socp(pattern_rows(p, m, np.ones(m, bool), np.zeros(m, bool)), 0.5)\n"
            "before = len(os.listdir('/proc/self/task'))\n"
            "sol = solve(problem, 1, False)\n"
            "print(sol.name, len(os.listdir('/proc/self/task')) - before,"
            " hashlib.sha256(sol.x.tobytes()).hexdigest())\n")
    from hpcwedge.environment import THREAD_VARIABLES
    # BLAS on one thread, as the command line sets it; Clarabel's own setting is under test
    env = {**os.environ, **{k: "1" for k in THREAD_VARIABLES}, "PYTHONPATH": ROOT}
    env.pop("RAYON_NUM_THREADS")
    runs = [subprocess.run(prefix + [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True,
                           text=True, timeout=300) for prefix in ([], ["taskset", "-c", "0"])]
    for r in runs:
        assert r.returncode == 0, r.stderr
    (name, extra, bits), (_, _, one_core) = (r.stdout.split() for r in runs)
    assert name == "Solved" and extra == "0"
    assert bits == one_core
