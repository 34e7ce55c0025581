"""Random small contact problems for the tests (supported and free bodies, 2D and 3D, with
a planted node symmetry, random partial 3D patterns, a tree's walk over patterns) and the
helpers two test files share; the independent routes are in hpcwedge.reference."""
from __future__ import annotations

import math

import numpy as np
import scipy.linalg as sla

from hpcwedge.contact.problem import ContactProblem, parametrize
from hpcwedge.solvers.rows import pattern_rows


def rigid_modes_local(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """2D rigid modes (x, y translation, rotation) of contact points, block-ordered local."""
    m = len(points)
    tang = np.stack([normals[:, 1], -normals[:, 0]], axis=1)
    modes = [np.tile([1.0, 0.0], (m, 1)), np.tile([0.0, 1.0], (m, 1)),
             np.stack([-points[:, 1], points[:, 0]], axis=1)]
    return np.stack([np.concatenate([(v * normals).sum(1), (v * tang).sum(1)]) for v in modes], axis=1)


def random_problem(rng: np.random.Generator, m: int, free: bool) -> ContactProblem:
    """A random 2D problem: supported (K SPD) or free (K PSD, null space = rigid modes
    of random contact points and normals pointing roughly upward into the body)."""
    n = 2 * m
    if not free:
        G = rng.standard_normal((n, n))
        return ContactProblem(2, G @ G.T + 0.2 * np.eye(n), np.zeros((n, 0)))
    pts = rng.uniform(-1, 1, size=(m, 2))
    ang = rng.uniform(0.2, np.pi - 0.2, size=m)
    nrm = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    N = np.linalg.qr(rigid_modes_local(pts, nrm))[0]
    k = np.linalg.matrix_rank(N)
    N = N[:, :k]
    B = sla.null_space(N.T)
    G = rng.standard_normal((B.shape[1], B.shape[1]))
    K = B @ (G @ G.T + 0.2 * np.eye(B.shape[1])) @ B.T
    return ContactProblem(2, 0.5 * (K + K.T), N)


def tree_factory(seed: int, m: int = 5, free: bool = False):
    """(make_tree, problem): make_tree(mu) -> the PatternTree of a random 2D problem at mu
    (picklable: the engine's subtree tasks take it)."""
    from functools import partial

    from hpcwedge.patterns.tree import PatternTree
    prob = random_problem(np.random.default_rng(seed), m, free=free)
    return partial(PatternTree, parametrize(prob), m), prob


def kernel_dim(K, rtol: float = 1e-10) -> tuple[int, np.ndarray]:
    """(number of eigenvalues of the sparse K within rtol of zero relative to the largest,
    all eigenvalues ascending)."""
    ev = np.linalg.eigvalsh(K.toarray())
    return int((np.abs(ev) <= rtol * ev[-1]).sum()), ev


def frames_3d(rng: np.random.Generator, m: int) -> np.ndarray:
    """(m, 3, 3) random right-handed contact frames (n, t1, t2): normals pointing
    roughly upward into the body, t1 at a random angle in the tangent plane."""
    F = np.empty((m, 3, 3))
    for i in range(m):
        v = rng.standard_normal(3)
        v[2] = abs(v[2]) + 0.3
        n = v / np.linalg.norm(v)
        a = rng.standard_normal(3)
        t1 = a - (a @ n) * n
        t1 /= np.linalg.norm(t1)
        F[i] = [n, t1, np.cross(n, t1)]
    return F


def rigid_modes_local_3d(points: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """3D rigid modes (3 translations, 3 rotations about the origin) of contact points,
    in the local frames, block-ordered [n.., t1.., t2..]: (3m, 6)."""
    modes = []
    for k in range(6):
        e = np.zeros(3)
        e[k % 3] = 1.0
        v = np.tile(e, (len(points), 1)) if k < 3 else np.cross(e, points)
        modes.append(np.concatenate([(frames[:, a, :] * v).sum(1) for a in range(3)]))
    return np.stack(modes, axis=1)


def random_problem_3d(rng: np.random.Generator, m: int, free: bool) -> ContactProblem:
    """A random 3D problem: supported (K SPD) or free (K PSD whose null space is the
    rigid modes of random contact points and frames: 6 for m >= 3, fewer below)."""
    n = 3 * m
    if not free:
        G = rng.standard_normal((n, n))
        return ContactProblem(3, G @ G.T + 0.2 * np.eye(n), np.zeros((n, 0)))
    pts = rng.uniform(-1, 1, size=(m, 3))
    M = rigid_modes_local_3d(pts, frames_3d(rng, m))
    U, s, _ = np.linalg.svd(M, full_matrices=False)
    N = U[:, s > 1e-10 * s[0]]
    B = sla.null_space(N.T)
    G = rng.standard_normal((B.shape[1], B.shape[1]))
    K = B @ (G @ G.T + 0.2 * np.eye(B.shape[1])) @ B.T
    return ContactProblem(3, 0.5 * (K + K.T), N)


def symmetric_problem_3d(rng: np.random.Generator, m: int, free: bool) -> ContactProblem:
    """A random 3D problem with a planted cyclic node symmetry: contact points on a
    ring (node k = node 0 turned by 2 pi k / m about z, its frame turned with it)
    and K averaged over the m shifts of the node blocks, so that node i -> i + 1
    (mod m) with unchanged local frames leaves K invariant. Supported (K SPD) or
    free (null space = the ring's rigid modes, which the shifts map onto themselves)."""
    n = 3 * m
    p0 = np.array([rng.uniform(0.5, 1.5), 0.0, rng.uniform(-0.5, 0.5)])
    f0 = frames_3d(rng, 1)[0]
    rot = [np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
           for a in 2 * np.pi * np.arange(m) / m]
    pts = np.array([R @ p0 for R in rot])
    frames = np.array([f0 @ R.T for R in rot])
    if free:
        M = rigid_modes_local_3d(pts, frames)
        U, s, _ = np.linalg.svd(M, full_matrices=False)
        N = U[:, s > 1e-10 * s[0]]
        B = sla.null_space(N.T)
        G = rng.standard_normal((B.shape[1], B.shape[1]))
        K0 = B @ (G @ G.T + 0.2 * np.eye(B.shape[1])) @ B.T
    else:
        N = np.zeros((n, 0))
        G = rng.standard_normal((n, n))
        K0 = G @ G.T + 0.2 * np.eye(n)
    K = np.zeros((n, n))
    for k in range(m):
        idx = (np.arange(3)[:, None] * m + (np.arange(m) + k) % m).ravel()   # dof of node i -> node i + k
        P = np.zeros((n, n))
        P[idx, np.arange(n)] = 1.0
        K += P @ K0 @ P.T
    K /= m
    return ContactProblem(3, 0.5 * (K + K.T), N)


def global_run(model: dict, dim: int = 2, mu_max: float | None = None, mu_c: str = "global"):
    """run_scene of a scene of `model` that asks only for the global mu^c (test_global_mu_c.py,
    test_milp.py)."""
    from hpcwedge.run.pipeline import run_scene
    from hpcwedge.scene.parse import parse_scene
    data = {"name": "g", "dim": dim, "model": model, "friction": {"mu": [0.01]},
            "compute": {"enumerate": False, "mu_c": mu_c}}
    if mu_max is not None:
        data["compute"]["mu_max"] = mu_max
    return run_scene(parse_scene(data))


def plug3d_param(levels: int = 2, ring: int = 5, **model):
    """(parametrisation, m) of the built-in plug3d LEVELS x RING, other model keys as given
    (e.g. taper_deg): a body searched without its symmetry (test_socp.py,
    test_global_mu_c.py, test_mu_critical.py)."""
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.scene.parse import parse_scene
    prob = contact_problem(parse_scene({"name": "p", "dim": 3, "friction": {"mu": [1.0]},
                                        "model": {"kind": "plug3d", "levels": levels, "ring": ring, **model}}))
    return parametrize(prob), prob.m


def partial_masks(rng, m: int):
    """Masks (zero_u, zero_r) of a random partial pattern: each node free, in contact or in
    gap with probability 1/3 each; None when every node is in gap (nothing to normalise)."""
    state = rng.integers(0, 3, m)
    zu, zr = state == 1, state == 2
    return (zu, zr) if (~zr).any() else None


def partial_rows(param, m: int, rng, mus, draws: int):
    """(mu, pattern_rows) of `draws` random partial patterns (partial_masks, all-gap draws
    skipped) at each mu in turn, drawn lazily from rng."""
    for mu in mus:
        for _ in range(draws):
            masks = partial_masks(rng, m)
            if masks is not None:
                yield mu, pattern_rows(param, m, *masks)


def random_partial_rows(rng, m: int = 3):
    """Rows of a random partial pattern (about 40 % of the nodes fixed in contact, 40 % of
    the rest fixed open) of a random free or supported 3D body with m contact nodes."""
    p = parametrize(random_problem_3d(rng, m, bool(rng.integers(2))))
    zu, zr = rng.random(m) < 0.4, np.zeros(m, bool)
    zr[~zu] = rng.random((~zu).sum()) < 0.4
    return pattern_rows(p, m, zu, zr)


def brute_3d(p, m, mu):
    """Feasible full patterns by one SOCP per partition (contact bits; test_tree.py)."""
    from hpcwedge.reference import brute_force_patterns
    return set(brute_force_patterns(p, m, mu))


def result_file(tmp_path, text: str, name: str = "result.h5", compute: dict | None = None) -> str:
    """A result file of the scene `text` (compute: its [compute] table), run and written
    (test_plot.py, test_plot3d.py)."""
    import tomllib

    from hpcwedge.results.hdf5 import write_result
    from hpcwedge.run.pipeline import run_scene
    from hpcwedge.scene.parse import parse_scene
    data = tomllib.loads(text)
    if compute:
        data["compute"] = compute
    result = run_scene(parse_scene(data, text))
    path = str(tmp_path / name)
    write_result(path, result)
    return path


def check_png(path) -> tuple[int, int]:
    """(width, height) of a PNG figure of plausible size with something drawn in it
    (test_plot.py, test_plot3d.py)."""
    import struct
    with open(path, "rb") as f:
        head = f.read(24)
        f.seek(0, 2)
        size = f.tell()
    assert head[:8] == b"\x89PNG\r\n\x1a\n"
    assert head[12:16] == b"IHDR"
    width, height = struct.unpack(">II", head[16:24])
    assert 600 <= width <= 4000 and 300 <= height <= 3000, (width, height)
    assert size > 10_000, size                     # two drawn panels, not an empty canvas
    return width, height


def python_calls(build) -> int:
    """The function calls (Python and C) made from Python while build() runs (sys.setprofile)."""
    import sys
    calls = 0

    def count(frame, event, arg):
        nonlocal calls
        calls += event in ("call", "c_call")
    sys.setprofile(count)
    try:
        build()
    finally:
        sys.setprofile(None)
    return calls


def pyramid_agreement(param, m: int, mu: float, inner, outer) -> None:
    """Every partition of a 3D body (a node out of gap) decided by two pyramid LPs,
    inner(zu, zr) and outer(zu, zr) -> (status, x or None: the inner LP's point when it has
    one; the status a `rows.Status`, or the bench's engines' "infeasible", which
    Status.INFEASIBLE equals as a StrEnum), and by the SOCP route (feasibility.decide): an inner point that verifies on the circular
    cones only where the SOCP is feasible, an outer "infeasible" only where it is not, and
    (pyramids of 64 facets, within 1.2e-3 of the circle, on a body with no full pattern that
    close to its mu^c) every partition decided one way or the other (test_screens.py,
    test_bench_lp_screens.py)."""
    from hpcwedge.solvers.feasibility import decide
    from hpcwedge.solvers.rows import Status, pattern_rows
    from hpcwedge.solvers.socp import VERIFY_TOL, violation
    feasible = proved_feasible = proved_infeasible = 0
    for code in range(1, 2 ** m):
        zr = np.array([not code >> i & 1 for i in range(m)])
        zu = ~zr
        rows = pattern_rows(param, m, zu, zr)
        status = decide(rows, mu).status
        feasible += status == Status.FEASIBLE
        _, x = inner(zu, zr)
        if x is not None and violation(rows, mu, x) <= VERIFY_TOL:
            assert status == Status.FEASIBLE
            proved_feasible += 1
        if outer(zu, zr)[0] == Status.INFEASIBLE:
            assert status == Status.INFEASIBLE
            proved_infeasible += 1
    assert 0 < feasible < 2 ** m - 1
    assert (proved_feasible, proved_infeasible) == (feasible, 2 ** m - 1 - feasible)


def curved_neck(levels: int = 2, ring: int = 5, seed: int = 0, taper_deg: float = 3.0, bend: float = 0.3,
                stiffness_spread: float = 1.0, jitter: float = 0.25, drop: int = 0, mu: float = 1.0) -> dict:
    """Scene data (parse_scene's dict, `[model] kind = "truss"`) of a plug in a curved neck: plug3d's
    bars (LEVELS rings of RING nodes and a centre per level, z = 0..1) on a wall whose radius
    0.5 + z tan(taper) + bend z^2 flares with height (the wall's angle to the axis grows from
    `taper_deg` at z = 0 to atan(tan taper + 2 bend) at z = 1), each ring node's angle moved by
    up to `jitter` of a ring step and each bar's EA = exp(stiffness_spread * N(0, 1)) (seeded):
    a free body with no symmetry. Contact: every ring node but `drop` of them drawn at random
    (m = levels * ring - drop), normal -cos(tau) e_r + sin(tau) e_z at the node's wall angle
    tau(z) (into the body), t1 = e_phi. The rigid bound (self-equilibrated reactions in the
    cones) is about tan(taper_deg); elastic compatibility sets the global mu^c above it."""
    from hpcwedge.models.library import plug3d
    rng = np.random.default_rng(seed)
    bars = plug3d(levels, ring).cells["line"]
    z = np.repeat(np.arange(levels) / (levels - 1), ring)
    t0 = math.tan(math.radians(taper_deg))
    radius, slope = 0.5 + z * t0 + bend * z ** 2, t0 + 2 * bend * z
    phi = 2 * np.pi * (np.tile(np.arange(ring), levels) + jitter * rng.uniform(-1, 1, levels * ring)) / ring
    er = np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], axis=1)
    nodes = np.concatenate([radius[:, None] * er + np.outer(z, [0.0, 0.0, 1.0]),
                            np.outer(np.arange(levels) / (levels - 1), [0.0, 0.0, 1.0])])
    tau = np.arctan(slope)[:, None]
    normals = -np.cos(tau) * er + np.sin(tau) * np.array([0.0, 0.0, 1.0])
    tangents = np.stack([-np.sin(phi), np.cos(phi), np.zeros_like(phi)], axis=1)
    EA = np.exp(stiffness_spread * rng.standard_normal(len(bars)))
    keep = np.sort(rng.permutation(levels * ring)[drop:])
    return {"name": f"neck-{levels}x{ring}-s{seed}", "dim": 3,
            "model": {"kind": "truss", "nodes": nodes.tolist(), "bars": bars.tolist(), "EA": EA.tolist()},
            "contact": {"nodes": keep.tolist(), "normals": normals[keep].tolist(),
                        "tangents": tangents[keep].tolist()},
            "friction": {"mu": [mu]}, "run": {"symmetry": False}}


def scene_param(data: dict):
    """(parametrisation, m) of scene data (parse_scene's dict)."""
    from hpcwedge.contact.build import contact_problem
    from hpcwedge.scene.parse import parse_scene
    prob = contact_problem(parse_scene(data))
    return parametrize(prob), prob.m


def tree_walk(rng: np.random.Generator, m: int, steps: int):
    """Patterns of a depth-first walk as a tree visits them: one node fixed (contact or gap)
    per step down, back to a random depth now and then: (zero_u, zero_r) pairs."""
    state = np.zeros(m, int)                     # 0 free, 1 contact, 2 gap
    for _ in range(steps):
        free = np.flatnonzero(state == 0)
        if free.size == 0 or rng.random() < 0.2:
            state[rng.permutation(m)[:rng.integers(1, m + 1)]] = 0
        else:
            state[free[0]] = rng.integers(1, 3)
        yield state == 1, state == 2
