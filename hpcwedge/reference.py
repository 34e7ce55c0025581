"""Independent routes that tests and benchmarks check the engines against, each written once.

- brute force over the 2^m full sign patterns: one feasibility problem per partition
  (2D: an LP, 3D: an SOCP, feasibility.decide), `pattern_decisions` / `brute_force_patterns`;
- the patterns a set of rays implies, by trying all 2^m contact sets (`patterns_of_supports`,
  `patterns_of_rays`, SPEC §2);
- a 3D feasibility route in other variables and another solver: (u, r) with K u = r, the
  friction cones replaced by inscribed / circumscribed pyramids, HiGHS (`ur_pyramid_feasible`,
  `ur_sandwich`), and a plain bisection (`bisect`);
- brute-force extreme rays of a small cone {A x >= 0} (`brute_force_rays`);
- the peers (bench extras, imported lazily): pycddlib's double description (`cdd_generators`,
  `cdd_zero`, `complementary_filter`) and SCIP on the indicator MILP (2D) / MISOCP (3D) of a
  wedged configuration (`scip_model`: one solve `scip_wedged` / `scip_status`, all contact sets by a no-good
  loop `scip_patterns`).

Contact sets are int bitsets (bit i: node i in contact); a full pattern's gap set is the rest.
Nothing here is used by a run of the program.
"""
from __future__ import annotations

import itertools
import math
from typing import Callable, Iterator

import numpy as np

from hpcwedge.nodesets import to_bits
from hpcwedge.solvers.feasibility import decide
from hpcwedge.solvers.rows import Status, pattern_rows

CDD_HELP = ("pycddlib is not installed (needed for the cddlib peers). Install it with\n"
            "    apt-get install -y libcdd-dev libgmp-dev\n"
            "    .venv/bin/pip install \"pycddlib<3\"          # or: scripts/setup.sh bench")


# ----------------------------------------------------------------------- sign patterns

def contact_mask(bits: int, m: int) -> np.ndarray:
    """(m,) bool: node i in contact iff bit i of `bits` is set."""
    return np.array([(bits >> i) & 1 for i in range(m)], dtype=bool)


def pattern_decisions(param, m: int, mu: float, counts: dict | None = None) -> Iterator[tuple]:
    """(bits, contact mask, status, x) of every full pattern (contact = bits, gap = the rest),
    bits ascending: one feasibility.decide problem each (2D: LP; 3D: SOCP)."""
    for bits in range(1 << m):
        zu = contact_mask(bits, m)
        d = decide(pattern_rows(param, m, zu, ~zu), mu, counts=counts)
        yield bits, zu, d.status, d.x


def brute_force_patterns(param, m: int, mu: float, counts: dict | None = None) -> list[int]:
    """Contact bitsets (ascending) of the feasible full patterns at mu, by 2^m solves."""
    return [bits for bits, _, status, _ in pattern_decisions(param, m, mu, counts) if status == Status.FEASIBLE]


def patterns_of_supports(load: np.ndarray, gap: np.ndarray, m: int) -> set[int]:
    """Contact sets C (bitsets) that some ray allows, trying all 2^m: load ⊆ C and gap ∩ C = ∅.
    load, gap: (R, m) bool supports of r_n and u_n of the wedged rays (SPEC §2)."""
    out = set()
    for bits in range(1 << m):
        C = contact_mask(bits, m)
        if np.any(~(load & ~C).any(axis=1) & ~(gap & C).any(axis=1)):
            out.add(bits)
    return out


def patterns_of_rays(zero: np.ndarray, m: int) -> set[int]:
    """patterns_of_supports of complementary rays given by their (R, 3m) zero flags (rows
    [u_n, f+, f-] per node); rigid lift-offs (r = 0) imply nothing and are left out."""
    zu, zr = zero[:, 0::3], zero[:, 1::3] & zero[:, 2::3]
    wedged = ~zr.all(axis=1)
    return patterns_of_supports(~zr[wedged], ~zu[wedged], m)


# ----------------------------------------------------------------------- (u, r) route, 3D

def ur_pyramid_feasible(prob, contact: np.ndarray, mu: float, sides: int, inner: bool) -> bool:
    """Is the full pattern (contact nodes C, the others gap G) feasible with every
    friction cone replaced by an inscribed (inner) or circumscribed pyramid? In
    the variables (u, r) in R^{6m} with K u = r, by HiGHS: independent of
    parametrize() and of Clarabel."""
    from scipy.optimize import linprog
    m, n = prob.m, prob.n
    K = prob.K
    C, G = np.flatnonzero(contact), np.flatnonzero(~contact)
    eq, ub = [np.hstack([K, -np.eye(n)])], []
    for i in C:                                 # u_n,i = 0
        r_ = np.zeros((1, 2 * n))
        r_[0, i] = 1.0
        eq.append(r_)
    for i in G:                                 # r_i = 0, u_n,i >= 0
        r_ = np.zeros((3, 2 * n))
        r_[np.arange(3), n + np.arange(3) * m + i] = 1.0
        eq.append(r_)
        r_ = np.zeros((1, 2 * n))
        r_[0, i] = -1.0
        ub.append(r_)
    norm = np.zeros((1, 2 * n))
    norm[0, n:n + m] = 1.0
    th = 2 * np.pi * (np.arange(sides) + 0.5) / sides
    c = math.cos(math.pi / sides) if inner else 1.0
    for i in C:                                 # cos t r_t1 + sin t r_t2 <= c mu r_n
        r_ = np.zeros((sides, 2 * n))
        r_[:, n + m + i], r_[:, n + 2 * m + i] = np.cos(th), np.sin(th)
        r_[:, n + i] = -c * mu
        ub.append(r_)
    A_eq = np.vstack(eq + [norm])
    b_eq = np.zeros(len(A_eq))
    b_eq[-1] = 1.0
    A_ub = np.vstack(ub) if ub else None
    res = linprog(np.zeros(2 * n), A_ub=A_ub, b_ub=np.zeros(len(A_ub)) if ub else None, A_eq=A_eq,
                  b_eq=b_eq, bounds=[(None, None)] * (2 * n), method="highs")
    return res.status == 0


def ur_sandwich(prob, contact: np.ndarray, mu: float, sides: int = 64):
    """"feasible" when the inscribed pyramids admit a point, "infeasible" when the
    circumscribed ones do not, None in between (see ur_pyramid_feasible)."""
    if ur_pyramid_feasible(prob, contact, mu, sides, inner=True):
        return "feasible"
    if not ur_pyramid_feasible(prob, contact, mu, sides, inner=False):
        return "infeasible"
    return None


def bisect(holds: Callable[[float], bool], lo: float, hi: float, rtol: float) -> float:
    """Plain bisection on mu in (lo, hi] for a monotone `holds` assumed true at hi: the upper
    end of the final bracket, of relative width <= rtol."""
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        if holds(mid):
            hi = mid
        else:
            lo = mid
    return hi


# ----------------------------------------------------------------------- rays of a small cone

def brute_force_rays(A: np.ndarray, tol: float = 1e-9) -> set[tuple[bool, ...]]:
    """Zero sets of the complementary extreme rays of {A x >= 0} (A: friction rows, 3 per
    node: [u_n, f+, f-]): every d-1 row subset of rank d-1, its null vector (either sign)
    if feasible; then the complementarity filter (u_n = 0 or both friction rows tight)."""
    nc, d = A.shape
    found = set()
    for S in itertools.combinations(range(nc), d - 1):
        _, s, vt = np.linalg.svd(A[list(S)])
        if s[-1] < tol * s[0]:
            continue
        for y in (vt[-1], -vt[-1]):
            v = A @ y
            if np.all(v >= -tol):
                found.add(tuple(np.abs(v) <= tol))
    return {z for z in found
            if all(z[3 * i] or (z[3 * i + 1] and z[3 * i + 2]) for i in range(nc // 3))}


# ----------------------------------------------------------------------- peer: pycddlib

def cdd_generators(H, number_type: str = "fraction"):
    """(generators as rows [t, x...], lin_set, "pycddlib <version>") of the H-representation
    rows H ([b, a...]: b + a.x >= 0), pycddlib 2.x or 3.x: number_type "fraction" (exact, GMP
    rationals: Fractions or ints) or "float" (cddlib's floating-point arithmetic).
    ImportError (with CDD_HELP) without pycddlib."""
    try:
        import cdd
    except ImportError as e:
        raise ImportError(CDD_HELP) from e
    version = "pycddlib " + _cdd_version()
    if hasattr(cdd, "Matrix"):                      # pycddlib 2.x
        mat = cdd.Matrix(H, number_type=number_type)
        mat.rep_type = cdd.RepType.INEQUALITY
        gen = cdd.Polyhedron(mat).get_generators()
        return [gen[i] for i in range(gen.row_size)], set(gen.lin_set), version
    if number_type == "float":                       # pycddlib 3.x, float
        mat = cdd.matrix_from_array(H, rep_type=cdd.RepType.INEQUALITY)
        gen = cdd.copy_generators(cdd.polyhedron_from_matrix(mat))
        return list(gen.array), set(gen.lin_set), version
    import cdd.gmp  # pycddlib 3.x (needs a GMP build)
    mat = cdd.gmp.matrix_from_array(H, rep_type=cdd.RepType.INEQUALITY)
    gen = cdd.gmp.copy_generators(cdd.gmp.polyhedron_from_matrix(mat))
    return list(gen.array), set(gen.lin_set), version


def _cdd_version() -> str:
    try:
        from importlib.metadata import version
        return version("pycddlib")
    except Exception:
        return "?"


def cdd_zero(rows, gens, exact: bool, tol: float | None = None) -> np.ndarray:
    """(R, nrows) zero flags of cddlib's ray generators (the apex left out) on the rows.
    exact: integer rows and exact generators, exact signs (python-flint); float: |a.x| <= tol
    on unit rows and unit rays. RuntimeError when a generator violates rows x >= 0."""
    if exact:
        return _exact_zero(rows, gens)
    A = np.asarray(rows, dtype=float)
    X = np.array([[float(v) for v in g[1:]] for g in gens if float(g[0]) == 0.0], dtype=float)
    if not len(X):
        return np.zeros((0, A.shape[0]), dtype=bool)
    X /= np.linalg.norm(X, axis=1, keepdims=True)
    S = X @ (A / np.linalg.norm(A, axis=1, keepdims=True)).T
    if (S < -tol).any():
        raise RuntimeError(f"a cddlib float generator violates A x >= 0 by {-S.min():.1e}")
    return np.abs(S) <= tol


def _exact_zero(Aint, gens) -> np.ndarray:
    from fractions import Fraction

    import flint
    rays = []
    for g in gens:
        if g[0] != 0:          # the apex (origin) vertex
            continue
        x = [Fraction(v) for v in g[1:]]
        den = math.lcm(*(v.denominator for v in x))
        rays.append([int(v * den) for v in x])
    d, R = len(Aint[0]), len(rays)
    if not R:
        return np.zeros((0, len(Aint)), dtype=bool)
    S = flint.fmpz_mat(Aint) * flint.fmpz_mat(d, R, [v for j in range(d) for v in (r[j] for r in rays)])
    sign = np.array([int(s > 0) - int(s < 0) for s in S.entries()], dtype=np.int8).reshape(len(Aint), R).T
    if (sign < 0).any():
        raise RuntimeError("a cddlib generator violates A x >= 0")
    return sign == 0


def complementary_filter(zero: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """The peer's post-processing of P's extreme rays: (zero flags of the complementary
    ones, their wedged mask, how many there are). zero: (R, 3m) boolean zero flags."""
    zu, zr = zero[:, 0::3], zero[:, 1::3] & zero[:, 2::3]
    comp = (zu | zr).all(axis=1)
    zero = zero[comp]
    wedged = ~(zero[:, 1::3] & zero[:, 2::3]).all(axis=1)
    return zero, wedged, int(comp.sum())


# ----------------------------------------------------------------------- peer: SCIP

def scip_model(param, m: int, mu: float):
    """SCIP (pyscipopt) model of issue 13's indicator MILP / MISOCP at mu: (model, z). x in the
    parametrisation, u_n >= 0, friction (2D: |r_t| <= mu r_n; 3D: the cone ||r_t|| <= mu r_n,
    a nonlinear constraint SCIP recognises as second-order), sum r_n = 1, r_n,i <= z_i, and
    the indicator z_i = 1 => u_n,i <= 0: z is the contact set (SPEC's weak sign pattern)."""
    from pyscipopt import Model, quicksum, sqrt
    U, R = param.U, param.R
    d, dim = param.d, param.U.shape[0] // m
    model = Model()
    model.hideOutput()
    x = [model.addVar(lb=None, ub=None, name=f"x{j}") for j in range(d)]
    z = [model.addVar(vtype="B", name=f"z{i}") for i in range(m)]

    def lin(row):
        return quicksum(float(row[j]) * x[j] for j in range(d) if row[j] != 0.0)

    for i in range(m):
        un, rn = lin(U[i]), lin(R[i])
        model.addCons(un >= 0)
        if dim == 2:
            rt = lin(R[m + i])
            model.addCons(mu * rn + rt >= 0)
            model.addCons(mu * rn - rt >= 0)
        else:
            # the cone on variables of its own: SCIP detects sqrt(t1^2 + t2^2) <= mu n as a
            # second-order cone only on variables
            n_, t1, t2 = (model.addVar(lb=0.0 if k == 0 else None, ub=None, name=f"r{k}_{i}")
                          for k in range(3))
            model.addCons(n_ == rn)
            model.addCons(t1 == lin(R[m + i]))
            model.addCons(t2 == lin(R[2 * m + i]))
            model.addCons(sqrt(t1 * t1 + t2 * t2) <= mu * n_)
        model.addCons(rn <= z[i])
        model.addConsIndicator(un <= 0, binvar=z[i])
    model.addCons(lin(R[:m].sum(0)) == 1)
    return model, z


def _scip_solve(model, counts: dict) -> str:
    """Optimise `model`; count milp_solves / milp_nodes; its status."""
    model.optimize()
    counts["milp_solves"] = counts.get("milp_solves", 0) + 1
    counts["milp_nodes"] = counts.get("milp_nodes", 0) + int(model.getNNodes())
    return model.getStatus()


def scip_status(param, m: int, mu: float, counts: dict, time_limit: float | None = None) -> str:
    """SCIP's status on `scip_model` at mu ("optimal": wedged, "infeasible": not, else
    undecided), at most `time_limit` seconds with the model's building (None: no limit).
    Counts milp_solves / milp_nodes."""
    import time
    start = time.perf_counter()
    model, _ = scip_model(param, m, mu)
    if time_limit is not None:
        model.setParam("limits/time", max(float(time_limit) - (time.perf_counter() - start), 0.0))
    return _scip_solve(model, counts)


def scip_wedged(param, m: int, mu: float, counts: dict) -> bool:
    """SCIP on `scip_model` at mu: is there a wedged configuration? Counts milp_solves /
    milp_nodes / undecided; a run SCIP does not finish counts as wedged (keeps a bisection's
    upper end valid)."""
    status = scip_status(param, m, mu, counts)
    if status not in ("optimal", "infeasible"):
        counts["undecided"] = counts.get("undecided", 0) + 1
        return True
    return status == "optimal"


def scip_patterns(param, m: int, mu: float, counts: dict) -> list[int] | None:
    """All contact sets z (int bitsets, sorted) for which `scip_model` at mu is feasible, by
    a no-good loop: solve, record z, cut it off (sum of the flipped z_i >= 1), until SCIP
    proves the rest infeasible. None when a solve ends otherwise (time limit, numerics)."""
    model, z = scip_model(param, m, mu)
    found = []
    while True:
        status = _scip_solve(model, counts)
        if status == "infeasible":
            return sorted(found)
        if status != "optimal":
            counts["undecided"] = counts.get("undecided", 0) + 1
            return None
        bits = [int(round(model.getVal(v))) for v in z]
        found.append(to_bits(i for i, b in enumerate(bits) if b))
        model.freeTransform()
        model.addCons(sum((1 - v) if b else v for v, b in zip(z, bits)) >= 1)
