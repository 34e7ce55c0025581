"""Scene -> Model -> ContactProblem: the model stage and the raw-stiffness route.

A `stiffness` scene gives the condensed, block-ordered local K directly (no
model, no condensation); every other kind builds a Model and condenses it.
"""
from __future__ import annotations

import math
import os

import numpy as np

from hpcwedge import exact as xq
from hpcwedge.contact.problem import ContactProblem, stiffness_range
from hpcwedge.errors import UserError
from hpcwedge.models.record import Model
from hpcwedge.progress import GB, MemoryGuard, physical_bytes, ranks_on_host
from hpcwedge.scene.parse import Scene
from hpcwedge.scene.values import SceneError, array

SYM_RTOL = 1e-10      # symmetry of a raw K, relative to max |K|
PSD_RTOL = 1e-10      # lambda_min >= -PSD_RTOL * lambda_max
SINGULAR_RTOL = 1e-10  # lambda_min <= SINGULAR_RTOL * lambda_max: numerically singular
#: a condensed model K whose smallest eigenvalue outside the rigid modes is at most this
#: times the largest is singular to rounding: the model is a mechanism (a plug truss held
#: by ground bars that leave a rotation free: 2e-16; the stiffest legitimate case of
#: scripts/stress.py, ground bars of EA 1e-8: 1.2e-10)
MECHANISM_RTOL = 1e-12


#: the scene keys of each kind whose values are stiffnesses (moduli, ground springs), with
#: the models' defaults
MODULI = {"truss": {"EA": 1.0}, "mesh": {"E": 1.0}, "block2d": {"E": 1.0}, "vgroove_bar": {"EA": 1.0, "eps": 0.0}}
#: the Model.material entries that are moduli (restored to the scene's units)
MATERIAL_MODULI = ("E", "EA")


def stiffness_exponent(scene: Scene) -> int:
    """The e with which the numerics run scale-free: the stiffnesses of the scene (a raw K;
    the moduli E, EA and ground springs eps of a model) are multiplied by 2**-e, the power
    of two nearest their largest magnitude, so that they lie near 1. A power of two is
    exact in floating point: mu^c, patterns, rays' r and zero sets do not change, and a
    ray's u (which scales with 1/stiffness) is multiplied back by 2**-e on output
    (`unscale_u`). 0 for unit moduli (the built-in plugs) and for values the model's own
    validation rejects."""
    if scene.kind == "stiffness":
        try:
            K = _raw_arrays(scene)[0]
        except UserError:
            return 0
        return _exponent(K)
    if scene.kind == "matrix":
        from hpcwedge.models.matrix import largest_entry
        try:
            return _exponent(np.array([largest_entry(os.path.join(scene.base_dir, scene.model["K"]))]))
        except (OSError, ValueError):
            return 0
    vals = []
    for key, default in MODULI.get(scene.kind, {}).items():
        v = scene.model.get(key, default)
        if v is not None and not isinstance(v, (str, bool)):
            try:
                vals.append(np.asarray(v, dtype=float).ravel())
            except (TypeError, ValueError):
                return 0
    return _exponent(np.concatenate(vals)) if vals else 0


def _exponent(values: np.ndarray) -> int:
    a = np.abs(np.asarray(values, dtype=float))
    a = a[np.isfinite(a) & (a > 0)]
    if a.size == 0:
        return 0
    mant, e = math.frexp(float(a.max()))        # max = mant 2**e, mant in [0.5, 1)
    return e if mant >= math.sqrt(0.5) else e - 1


def _scaled(value, e: int):
    """value (a scalar or a list of numbers) times 2**-e; anything else as it is."""
    if e == 0 or value is None or isinstance(value, (str, bool)):
        return value
    try:
        return np.ldexp(np.asarray(value, dtype=float), -e).tolist()
    except (TypeError, ValueError):
        return value


def unscale_u(u: np.ndarray, scene_or_e) -> np.ndarray:
    """Displacements computed on the rescaled stiffness (stiffness_exponent) in the
    scene's units: u times 2**-e (exact)."""
    e = scene_or_e if isinstance(scene_or_e, int) else stiffness_exponent(scene_or_e)
    return u if e == 0 else np.ldexp(u, -e)


def build_model(scene: Scene) -> Model:
    """The Model of a non-stiffness scene (ValueError from the models -> SceneError), its
    stiffness K scaled by 2**-stiffness_exponent(scene) (the moduli scaled before assembly,
    so that no modulus overflows it); Model.material keeps the scene's moduli (stresses in
    the scene's units). progress.MemoryLimit when its condensed problem would not fit
    (guard_condensed: a built-in's before it is built)."""
    e = stiffness_exponent(scene)
    if e == 0:
        model = _build_model(scene, scene.model)
    else:
        # the moduli the scene leaves at their defaults are scaled with the others
        given = {**MODULI.get(scene.kind, {}), **scene.model}
        params = {k: _scaled(v, e) if k in MODULI.get(scene.kind, ()) else v for k, v in given.items()}
        model = _build_model(scene, params)
        material = {k: np.ldexp(np.asarray(v, dtype=float), e) if k in MATERIAL_MODULI else v
                    for k, v in model.material.items()}
        model = model.replace(material=material)        # K stays unassembled (distributed rows)
    guard_condensed(scene, len(model.contact_nodes), model.dim)
    return model


def _build_model(scene: Scene, params: dict) -> Model:
    from hpcwedge.models import library, truss
    try:
        if scene.kind == "truss":
            c = scene.contact
            if "nodes" not in c or "normals" not in c:
                raise SceneError("contact.nodes, contact.normals: required for a truss")
            m = params
            for key in ("nodes", "bars"):
                if key not in m:
                    raise SceneError(f"model.{key}: required for a truss")
            nodes = array(m["nodes"], "model.nodes", 2)
            if nodes.shape[1] != scene.dim:
                raise SceneError(f"model.nodes: {nodes.shape[1]} coordinates per node, scene dim = {scene.dim}")
            return truss.truss_model(nodes, m["bars"], m.get("EA", 1.0), m.get("supports", []),
                                     c["nodes"], c["normals"], c.get("tangents"))
        if scene.kind == "mesh":
            return _mesh_model(scene, params)
        if scene.kind == "matrix":
            return _matrix_model(scene)
        guard_condensed(scene, library.contact_count(scene.kind, params), scene.dim)
        return library.builtin(scene.kind, params)
    except UserError:
        raise
    except MemoryError:
        raise SceneError(f"model: {_TOO_LARGE}") from None
    except (ValueError, TypeError, IndexError) as e:
        line = str(e).splitlines()[0]
        # numpy's refusal of an array too large to index (model.rows = 10**30)
        raise SceneError(f"model: {_TOO_LARGE}" if "Maximum allowed size" in line else line) from None


_TOO_LARGE = "too large to build: its arrays do not fit in memory (check the model's sizes)"


def _mesh_model(scene: Scene, m: dict) -> Model:
    """kind = "mesh": read model.file (relative to the scene file) and build the Model
    (m: the scene's model table, moduli scaled)."""
    from hpcwedge.models import mesh
    from hpcwedge.models.obstacle import parse_obstacles
    c = scene.contact
    data = mesh.read_mesh(os.path.join(scene.base_dir, m["file"]), scene.dim, name=m["file"])
    obstacles = (parse_obstacles(scene.obstacles, scene.dim, scene.obstacle_key)
                 if scene.obstacles is not None else None)
    return mesh.mesh_model(data, E=m.get("E", 1.0), nu=m.get("nu", 0.3), thickness=m.get("thickness", 1.0),
                           contact_nodes=c.get("nodes"), contact_group=c.get("group"),
                           normals=c.get("normals"), tangents=c.get("tangents"),
                           obstacles=obstacles, obstacle_key=scene.obstacle_key,
                           tolerance=c.get("tolerance", mesh.DEFAULT_TOLERANCE),
                           supports=m.get("supports"), support_group=m.get("support_group"),
                           support_dofs=m.get("support_dofs"), contact_patch=m.get("contact_patch", 0.0),
                           contact_patch_kind=m.get("contact_patch_kind", "rigid"))


def _matrix_model(scene: Scene) -> Model:
    """kind = "matrix": model.K, model.nodes and model.mesh read (relative to the scene file),
    K scaled by 2**-stiffness_exponent(scene); a PETSc binary K is only opened (its header)
    and loaded when needed (models.matrix.StiffnessFile, condense.load_petsc)."""
    from hpcwedge.contact.condense import load_petsc
    from hpcwedge.models import matrix
    m, c, e = scene.model, scene.contact, stiffness_exponent(scene)
    coords = matrix.read_nodes(m["nodes"], scene.base_dir, scene.dim)
    path = os.path.join(scene.base_dir, m["K"])
    if path.lower().endswith(".petsc"):
        if not os.path.isfile(path):
            raise SceneError(f"model.K: {m['K']} not found")
        rows, cols, _ = matrix.petsc_header(path, m["K"])
        if rows != cols:
            raise SceneError(f"model.K: must be square, got shape ({rows}, {cols})")
        K = matrix.StiffnessFile(path, rows, e, load_petsc)
    else:
        K = matrix.read_stiffness(path, m["K"])
    cells = None
    if "mesh" in m:
        from hpcwedge.models.mesh import read_mesh
        data = read_mesh(os.path.join(scene.base_dir, m["mesh"]), scene.dim, name=m["mesh"], key="model.mesh")
        if len(data.points) != len(coords):
            raise SceneError(f"model.mesh: {m['mesh']} has {len(data.points)} nodes, model.nodes {len(coords)}")
        cells = data.cells
    return matrix.matrix_model(K, coords, m.get("supports"), c["nodes"], c["normals"], c.get("tangents"),
                               cells, exponent=e)


def contact_problem(scene: Scene, model: Model | None = None, comm=None) -> ContactProblem:
    """ContactProblem of a scene: condensed from `model`, or the raw K of a stiffness scene.
    comm (mpi4py communicator, or None): condense collectively over it (every rank calls this
    with the same scene; condense.condense_distributed); None: this process alone."""
    if scene.kind != "stiffness":
        from hpcwedge.contact.condense import condense_distributed
        if model is None:
            model = build_model(scene)
        key = "model.K" if scene.kind == "matrix" else "model"
        try:
            if scene.kind == "matrix" and (comm is None or comm.size == 1) and model.assembly is not None:
                from hpcwedge.models.matrix import check_rigid
                check_rigid(model.K, model.rigid_modes)     # a PETSc binary K, loaded whole here
            K, N = condense_distributed(model, comm)
        except ValueError as e:
            line = str(e).splitlines()[0]
            raise SceneError(line if line.startswith(key) else f"{key}: {line}") from None
        problem = ContactProblem(scene.dim, K, N)
        if scene.kind == "matrix":
            check_no_extra_zero_modes(problem)
        check_not_mechanism(problem)
        return problem
    return raw_stiffness(scene)


def check_not_mechanism(problem: ContactProblem) -> None:
    """SceneError if the condensed K is singular beyond the model's rigid modes (a
    mechanism that the geometry's rigid modes do not account for): its smallest
    eigenvalue on range(K) at most MECHANISM_RTOL times its largest."""
    lo, hi = stiffness_range(problem)
    if hi > 0 and lo <= MECHANISM_RTOL * hi:
        raise SceneError(f"model: the condensed stiffness is singular apart from the {problem.N.shape[1]} "
                         f"rigid mode(s) (smallest/largest eigenvalue {lo / hi:.1e} <= {MECHANISM_RTOL:g}): "
                         "the body is a mechanism (add bars/elements or supports)")


def check_no_extra_zero_modes(problem: ContactProblem) -> None:
    """SceneError naming model.K and how many zero modes the condensed stiffness of a matrix
    body has beyond the rigid modes of its nodes and supports (eigenvalues on range(K) at most
    MECHANISM_RTOL times the largest)."""
    lam, k = problem.spectrum, problem.N.shape[1]
    extra = int((lam[k:] <= MECHANISM_RTOL * lam[-1]).sum()) if lam.size > k else 0
    if extra:
        raise SceneError(f"model.K: the body is a mechanism: {extra} zero mode(s) beyond the {k} rigid mode(s) "
                         "of model.nodes and model.supports (add supports, or check the FE model's constraints)")


def _raw_arrays(scene: Scene):
    """(K, N or None) of a stiffness scene as given (inline or file), unvalidated (its keys
    were checked by scene.parse_scene)."""
    m = scene.model
    if ("K" in m) == ("file" in m):
        raise SceneError("model.K / model.file: give exactly one")
    N = None
    if "file" in m:
        K, N = _load_file(os.path.join(scene.base_dir, m["file"]), m["file"])
    else:
        K = array(m["K"], "model.K", 2)
    if "null_space" in m:
        if N is not None:
            raise SceneError("model.null_space: given both inline and in model.file")
        N = array(m["null_space"], "model.null_space")
    if N is not None and N.ndim not in (1, 2):
        key = f"model.file {m['file']}: null_space" if "file" in m and "null_space" not in m else "model.null_space"
        raise SceneError(f"{key}: must be a vector or a matrix (columns = rigid modes), got a {N.ndim}-D array")
    return K, N


def raw_stiffness(scene: Scene) -> ContactProblem:
    """Validate a raw block-ordered K (inline or file) and its null space (SPEC §3); the
    ContactProblem's K is scaled by 2**-stiffness_exponent(scene) (values in messages are
    in the scene's units)."""
    K, N = _raw_arrays(scene)
    key = f"model.file {scene.model['file']}: K" if "file" in scene.model else "model.K"
    e = _exponent(K)
    K = np.ldexp(K, -e)
    units = lambda v: float(np.ldexp(v, e))     # noqa: E731  (a value of the scaled K in the scene's units)
    n = K.shape[0]
    if K.shape != (n, n) or n == 0:
        raise SceneError(f"{key}: must be square, got shape {K.shape}")
    if n % scene.dim:
        raise SceneError(f"{key}: size {n} is not a multiple of dim = {scene.dim}")
    scale = np.abs(K).max()
    if scale == 0:
        raise SceneError(f"{key}: all zero")
    if np.abs(K - K.T).max() > SYM_RTOL * scale:
        raise SceneError(f"{key}: not symmetric (max |K - K^T| = {units(np.abs(K - K.T).max()):.3g})")
    K = 0.5 * (K + K.T)
    lam = np.linalg.eigvalsh(K)
    if lam[0] < -PSD_RTOL * lam[-1]:
        raise SceneError(f"{key}: indefinite (eigenvalue {units(lam[0]):.3g} < 0)")
    if N is not None:
        N = N.reshape(n, -1) if N.ndim == 1 else N
        if N.shape[0] != n:
            if N.shape[1] == n:
                N = N.T
            else:
                raise SceneError(f"model.null_space: expected {n} rows (columns = rigid modes), got shape {N.shape}")
        if N.shape[1] == 0:                     # no rigid modes given: a supported body
            if lam[0] <= SINGULAR_RTOL * lam[-1]:
                raise SceneError("model.null_space: empty, but K is singular (give its null space, "
                                 "or leave model.null_space out)")
            return ContactProblem(scene.dim, K, np.zeros((n, 0)), eigenvalues=lam)
        if np.linalg.matrix_rank(N) < N.shape[1]:
            raise SceneError("model.null_space: columns are linearly dependent")
        Q = np.linalg.qr(N)[0]
        if np.abs(K @ Q).max() > 1e-8 * lam[-1]:
            raise SceneError(f"model.null_space: K @ null_space is not zero (max {units(np.abs(K @ Q).max()):.3g})")
        lam_r = np.linalg.eigvalsh(K + lam[-1] * Q @ Q.T)
        if lam_r[0] <= SINGULAR_RTOL * lam[-1]:
            raise SceneError("model.null_space: K has more null directions than the given null_space")
        return ContactProblem(scene.dim, K, Q, eigenvalues=lam)
    if lam[0] > SINGULAR_RTOL * lam[-1]:
        return ContactProblem(scene.dim, K, np.zeros((n, 0)), eigenvalues=lam)
    # singular: unambiguous only when the null space is exact (rational rank deficit)
    Kq = xq.to_q(K)
    rank = Kq.rank()
    if rank < n:
        Z = xq.to_float(xq.nullspace(Kq))
        return ContactProblem(scene.dim, K, np.linalg.qr(Z)[0], eigenvalues=lam)
    raise SceneError(f"{key}: numerically singular (eigenvalue ratio {lam[0] / lam[-1]:.2e} "
                     f"<= {SINGULAR_RTOL:g}) but of full rank in exact arithmetic: give model.null_space")


def _load_file(path: str, key: str):
    if not os.path.exists(path):
        raise SceneError(f"model.file: {key} not found")
    ext = os.path.splitext(path)[1].lower()
    try:
        if ext == ".npy":
            return array(np.load(path, allow_pickle=False), "model.file", 2), None
        if ext == ".npz":
            with np.load(path, allow_pickle=False) as z:
                if "K" not in z:
                    raise SceneError(f"model.file: {key} has no array named K")
                N = array(z["null_space"], "model.file null_space") if "null_space" in z else None
                return array(z["K"], "model.file K", 2), N
        if ext in (".h5", ".hdf5"):
            import h5py
            with h5py.File(path, "r") as f:
                if not isinstance(f.get("K"), h5py.Dataset):
                    raise SceneError(f"model.file: {key} has no dataset K" + (" (K is a group)" if "K" in f else ""))
                N = array(f["null_space"][()], "model.file null_space") if "null_space" in f else None
                return array(f["K"][()], "model.file K", 2), N
    except UserError:
        raise
    except Exception as e:  # unreadable file of a known type
        why = (str(e).strip().splitlines() or [""])[0]
        raise SceneError(f"model.file: cannot read {key} ({type(e).__name__}{': ' + why if why else ''})") from None
    raise SceneError(f"model.file: {key}: unsupported file type (use .npy, .npz or .h5)")


#: the condense stage and the parametrisation hold about this many dense copies of the
#: condensed stiffness (dim m x dim m) at their peak (plug2d rows 500 and 1000: 7.3-7.5)
CONDENSED_COPIES = 8


def guard_condensed(scene: Scene, m: int, dim: int) -> None:
    """progress.MemoryLimit (one line naming run.max_memory_gb) when the dense condensed
    problem of m contact nodes, CONDENSED_COPIES times its (dim m)^2 float64s, would not fit:
    checked before a built-in is built (its m from its parameters) and before the
    condensation, either of which would otherwise run until the machine kills it."""
    n = dim * m
    need = CONDENSED_COPIES * 8.0 * n * n
    what = f"the condensed stiffness of {m:,} contact nodes ({n:,} x {n:,} dense) and its parametrisation"
    if need > physical_bytes():
        # whatever run.max_memory_gb says: the model itself is the problem
        raise SceneError(f"model: too large to build: {what} need about {need / GB:.3g} GB, more than "
                         f"this machine's {physical_bytes() / GB:.3g} GB (check the model's sizes)")
    MemoryGuard(scene.max_memory_gb, ranks_on_host()).check(need, what)
