"""Raw stiffness validation and the null-space rules (SPEC §3)."""
import numpy as np
import pytest

from hpcwedge.contact.build import raw_stiffness, stiffness_exponent
from hpcwedge.scene.parse import parse_scene
from hpcwedge.scene.values import SceneError


def sc(model, dim=2):
    return parse_scene({"name": "s", "dim": dim, "model": {"kind": "stiffness", **model},
                        "friction": {"mu": [1.0]}})


@pytest.mark.parametrize("K,key", [
    ([[1.0, 2.0], [0.0, 1.0]], "not symmetric"),
    ([[1.0, 2.0], [2.0, 1.0]], "indefinite"),
    ([[1.0, 0.0, 0.0]], "square"),
    ([[1.0, float("nan")], [float("nan"), 1.0]], "NaN"),
    ([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], "multiple of dim"),
    ([[1.0, 1.0], [1.0, 1.0 + 1e-13]], "numerically singular"),
])
def test_bad_K(K, key):
    with pytest.raises(SceneError) as e:
        raw_stiffness(sc({"K": K}))
    assert str(e.value).startswith("model.") and key in str(e.value)


def test_exactly_singular_K_gets_its_null_space():
    p = raw_stiffness(sc({"K": [[1.0, -1.0], [-1.0, 1.0]]}))
    assert p.N.shape == (2, 1) and np.allclose(np.abs(p.N[:, 0]), 1 / np.sqrt(2))


def test_given_null_space_checked():
    K = [[1.0, -1.0], [-1.0, 1.0]]
    assert raw_stiffness(sc({"K": K, "null_space": [[1.0], [1.0]]})).N.shape == (2, 1)
    with pytest.raises(SceneError, match="model.null_space"):
        raw_stiffness(sc({"K": K, "null_space": [[1.0], [0.0]]}))


@pytest.mark.parametrize("empty", [[[], []], []])
def test_empty_null_space_means_no_rigid_modes(empty):
    """An empty null space (no columns) declares a supported body: accepted for a regular K
    (the same problem as without it), refused by name for a singular one (before: an
    internal ValueError from a zero-size reduction, exit 1)."""
    K = [[2.0, 0.5], [0.5, 1.0]]
    p = raw_stiffness(sc({"K": K, "null_space": empty}))
    assert p.N.shape == (2, 0) and np.array_equal(p.K, raw_stiffness(sc({"K": K})).K)
    with pytest.raises(SceneError, match="^model.null_space: empty, but K is singular"):
        raw_stiffness(sc({"K": [[1.0, -1.0], [-1.0, 1.0]], "null_space": empty}))


@pytest.mark.parametrize("ext", ["npy", "npz"])
def test_complex_K_file_refused(tmp_path, ext):
    """A complex K in a file (numpy would drop the imaginary part with a warning): refused."""
    K = np.array([[2.0, 0.5 + 1j], [0.5 - 1j, 1.0]])
    f = tmp_path / f"k.{ext}"
    np.save(f, K) if ext == "npy" else np.savez(f, K=K)
    scene = parse_scene({"name": "s", "dim": 2, "model": {"kind": "stiffness", "file": f.name},
                         "friction": {"mu": [1.0]}}, base_dir=str(tmp_path))
    with pytest.raises(SceneError, match="^model.file.*complex entries"):
        raw_stiffness(scene)


def test_files(tmp_path):
    import h5py
    K = np.array([[2.0, 0.5], [0.5, 1.0]])
    np.save(tmp_path / "k.npy", K)
    np.savez(tmp_path / "k.npz", K=K)
    with h5py.File(tmp_path / "k.h5", "w") as f:
        f["K"] = K
    for name in ("k.npy", "k.npz", "k.h5"):
        s = parse_scene({"name": "s", "dim": 2, "model": {"kind": "stiffness", "file": name},
                         "friction": {"mu": [1.0]}}, base_dir=str(tmp_path))
        e = stiffness_exponent(s)               # K is rescaled by a power of two near max |K| = 2
        assert e == 1 and np.array_equal(raw_stiffness(s).K, np.ldexp(K, -e))
    s = parse_scene({"name": "s", "dim": 2, "model": {"kind": "stiffness", "file": "missing.npy"},
                     "friction": {"mu": [1.0]}}, base_dir=str(tmp_path))
    with pytest.raises(SceneError, match="model.file"):
        raw_stiffness(s)


def test_building_imports_no_engine():
    """Scene -> Model -> ContactProblem imports none of the engines (dd, patterns, numerics,
    the solvers) nor the parallel layer."""
    import subprocess
    import sys
    code = ("import sys\n"
            "from hpcwedge.contact.build import build_model, contact_problem\n"
            "from hpcwedge.scene.parse import parse_scene\n"
            "s = parse_scene({'name': 's', 'dim': 2, 'model': {'kind': 'plug2d', 'rows': 2},"
            " 'friction': {'mu': [1.0]}})\n"
            "contact_problem(s, build_model(s))\n"
            "print(' '.join(sorted(m for m in sys.modules if m.startswith('hpcwedge.'))))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    engines = {"rays", "patterns", "mu_c", "solvers", "parallel", "run"}     # the subpackages above contact/
    loaded = {m.split(".")[1] for m in out}
    assert "contact" in loaded and not engines & loaded, out


def test_raw_K_eigenvalues_computed_once():
    from hpcwedge.contact.problem import stiffness_range
    p = raw_stiffness(sc({"K": [[2.0, 0.0], [0.0, 8.0]]}))
    assert p.spectrum is p.eigenvalues and stiffness_range(p) == (0.25, 1.0)      # K scaled by 2**-3


def test_unreadable_files_and_null_spaces_say_why(tmp_path):
    """A null space that is neither a vector nor a matrix (inline or in the file) is a one-line
    SceneError naming it (before: an internal error, numpy's 'truth value of an array is
    ambiguous'); an unreadable K file says why, not only the exception's type."""
    import h5py
    K = [[2.0, -2.0], [-2.0, 2.0]]
    with pytest.raises(SceneError, match=r"^model.null_space: must be a vector or a matrix .* 3-D array"):
        raw_stiffness(sc({"K": K, "null_space": [[[1.0]], [[1.0]]]}))
    np.savez(tmp_path / "k.npz", K=np.array(K), null_space=np.ones((2, 1, 1)))
    np.save(tmp_path / "obj.npy", np.array([[1, "a"]], dtype=object))
    with h5py.File(tmp_path / "g.h5", "w") as f:
        f.create_group("K")
    for name, phrase in (("k.npz", "model.file k.npz: null_space: must be a vector or a matrix"),
                         ("obj.npy", "cannot read obj.npy (ValueError: Object arrays cannot be loaded"),
                         ("g.h5", "g.h5 has no dataset K (K is a group)")):
        s = parse_scene({"name": "s", "dim": 2, "model": {"kind": "stiffness", "file": name},
                         "friction": {"mu": [1.0]}}, base_dir=str(tmp_path))
        with pytest.raises(SceneError) as e:
            raw_stiffness(s)
        assert phrase in str(e.value) and "\n" not in str(e.value), str(e.value)


@pytest.mark.parametrize("rows", [10**9, 10**18, 10**30])
def test_a_model_too_large_to_build_names_the_model(rows):
    """plug2d with 10**9, 10**18 or 10**30 rows: one line naming the model, before it is built
    (before: numpy's 'Maximum allowed size exceeded' without a key, or the memory guard
    blaming run.max_memory_gb; and 10**9 rows built until the kernel killed the run at 24 GB,
    exit 137 and no word)."""
    from hpcwedge.contact.build import build_model
    with pytest.raises(SceneError, match=r"^model: too large to build"):
        build_model(parse_scene({"name": "s", "dim": 2, "model": {"kind": "plug2d", "rows": rows},
                                 "friction": {"mu": [1.0]}}))


def test_a_stop_while_k_is_read_is_a_stop_not_an_unreadable_file(tmp_path):
    """A stop (parallel.Interrupted, raised by the run's SIGTERM handler) that lands while a
    K file is read goes through as a stop (before: 'model.file: cannot read K.npz
    (Interrupted: SIGTERM)', exit 2, instead of the checkpointing stop and exit 75)."""
    import signal

    from hpcwedge.contact.build import raw_stiffness
    from hpcwedge.errors import Interrupted
    rng = np.random.default_rng(0)
    A = rng.standard_normal((1500, 1500))
    np.savez_compressed(tmp_path / "K.npz", K=A @ A.T)
    scene = parse_scene({"name": "s", "dim": 2, "model": {"kind": "stiffness", "file": "K.npz"},
                         "friction": {"mu": [1.0]}}, base_dir=str(tmp_path))

    def stop(signum, frame):
        raise Interrupted("SIGTERM")
    old = signal.signal(signal.SIGALRM, stop)
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.002)
        with pytest.raises(Interrupted):
            raw_stiffness(scene)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
