"""Raw stiffness validation and the null-space rules (SPEC §3)."""
import numpy as np
import pytest

from hpcwedge.build import raw_stiffness, stiffness_exponent
from hpcwedge.scene import SceneError, parse_scene


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
