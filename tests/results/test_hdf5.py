"""Result files (resultfile.py, SPEC §4-5): every file is sealed with the SHA-256 of its bytes
and verified on read; a damaged or malformed result is one line and exit 2 in show, show
--json, plot and export (never a traceback) and stays as it is; results written before
checksums are read with a note; a result records the digests of the files its scene names."""
import hashlib
import os
import random
import shutil
import time

import h5py
import pytest
from mpi_helpers import ROOT, damaged, run, show_json, write_scene

from hpcwedge.cli import main
from hpcwedge.files import CHECKSUM_MAGIC, FileError, seal, verify_checksum
from hpcwedge.results.hdf5 import read_result

SCENE = 'name = "plug"\ndim = 2\n[model]\nkind = "plug2d"\nrows = 2\n[friction]\nmu = [0.65]\n'
#: a result written before checksums (plug2d m = 8; a copy of the demo's from before them,
#: since `make demo` rewrites results/demo)
OLD_RESULT = os.path.join(ROOT, "tests", "data", "result_before_checksums.h5")


@pytest.fixture(scope="module")
def result(tmp_path_factory) -> str:
    """A real result of a body (plug2d, m = 4), written by the command line."""
    tmp = tmp_path_factory.mktemp("res")
    (tmp / "s.toml").write_text(SCENE)
    out = str(tmp / "r.h5")
    run(None, "run", str(tmp / "s.toml"), "-o", out, "-q")
    return out


COMMANDS = {"show": lambda p, o: ["show", p], "json": lambda p, o: ["show", p, "--json"],
            "plot": lambda p, o: ["plot", p, "-o", o + ".png"],
            "export": lambda p, o: ["export", p, "--ray", "0", "-o", o + ".vtu"]}


def _refused(path: str, capsys, phrase: str = "") -> None:
    """show, show --json, plot and export of `path` each exit 2 with one line naming the file
    (and `phrase`), print nothing on stdout, write no output and leave the file as it was."""
    before = open(path, "rb").read()
    out = os.path.join(os.path.dirname(path), "out")
    for name, args in COMMANDS.items():
        capsys.readouterr()
        code = main(args(path, out))
        got = capsys.readouterr()
        err = got.err.strip()
        assert code == 2 and len(err.splitlines()) == 1 and not got.out, (name, got)
        assert err.startswith("hpcwedge: error: ") and path in err and phrase in err, (name, err)
    assert not os.path.exists(out + ".png") and not os.path.exists(out + ".vtu")
    assert open(path, "rb").read() == before


def test_a_result_verifies_and_reads(result, capsys):
    assert verify_checksum(result)
    with open(result, "rb") as f:
        assert f.read(len(CHECKSUM_MAGIC)) == CHECKSUM_MAGIC
    for args in COMMANDS.values():
        assert main(args(result, os.path.join(os.path.dirname(result), "ok"))) == 0
    assert "note" not in capsys.readouterr().err


def test_random_damage_refused_everywhere(result, tmp_path, capsys):
    """20 random damages (fixed seed): 1 or 16 flipped bytes anywhere in the file, or a
    truncation; each is refused by show, show --json, plot and export."""
    good = open(result, "rb").read()
    rng = random.Random(7)
    for i in range(20):
        path = str(tmp_path / f"r{i}.h5")
        open(path, "wb").write(damaged(good, rng, i))
        _refused(path, capsys)


def test_damage_in_the_ray_values_is_found(result, tmp_path, capsys):
    """One changed bit in the ray vectors: HDF5 reads the file without complaint (a wrong
    number), the checksum refuses it; also in a real process."""
    path = str(tmp_path / "r.h5")
    shutil.copy(result, path)
    with h5py.File(path, "r") as f:
        ds = f["runs/000/rays"]
        offset, rays = ds.id.get_offset(), ds[()]
    with open(path, "r+b") as fh:
        fh.seek(offset + 5)
        byte = fh.read(1)[0]
        fh.seek(offset + 5)
        fh.write(bytes([byte ^ 1]))
    with h5py.File(path, "r") as f:
        assert (f["runs/000/rays"][()] != rays).sum() == 1
    _refused(path, capsys, "damaged: its SHA-256 checksum does not match")
    p = run(None, "show", path, "--json", check=False)
    assert p.returncode == 2 and not p.stdout and len(p.stderr.strip().splitlines()) == 1, p.stderr
    with pytest.raises(FileError, match="checksum"):
        read_result(path)


def test_verified_once_until_the_file_changes(result, tmp_path, monkeypatch):
    """A stable result is hashed once per process however often it is opened, and again as
    soon as it changes (then the damage is found)."""
    import hpcwedge.results.hdf5 as R
    path = str(tmp_path / "r.h5")
    shutil.copy(result, path)
    monkeypatch.setattr(R, "STABLE_S", 0.2)
    time.sleep(0.3)
    calls, real = [], R.verify_checksum
    monkeypatch.setattr(R, "verify_checksum", lambda p: calls.append(p) or real(p))
    assert read_result(path).to_dict() == read_result(path).to_dict() and len(calls) == 1
    with open(path, "r+b") as fh:
        fh.seek(os.path.getsize(path) // 2)
        byte = fh.read(1)[0]
        fh.seek(-1, os.SEEK_CUR)
        fh.write(bytes([byte ^ 4]))
    with pytest.raises(FileError, match="checksum"):
        read_result(path)
    assert len(calls) == 2


@pytest.mark.parametrize("content", [b"", b"not a result\n", b"\x89HDF\r\n\x1a\n" + bytes(3000)])
def test_not_a_result_refused(tmp_path, capsys, content):
    path = str(tmp_path / "r.h5")
    open(path, "wb").write(content)
    _refused(path, capsys)


def _tamper_attr(f):
    f.attrs["dim"] = "two"


def _tamper_runs(f):
    del f["runs"]


def _tamper_rays(f):
    del f["runs/000/rays"]
    f["runs/000/rays"] = [1.0, 2.0, 3.0]


def _tamper_cones(f):
    del f["runs/000/cones_json"]
    f["runs/000/cones_json"] = "[{\"rays\": 3"


def _tamper_cone_items(f):
    del f["runs/000/cones_json"]
    f["runs/000/cones_json"] = '[{"rays": [99999], "zero_u": [0], "zero_r": [], "mu_c": "low"}]'


@pytest.mark.parametrize("tamper", [_tamper_attr, _tamper_runs, _tamper_rays, _tamper_cones, _tamper_cone_items])
@pytest.mark.parametrize("sealed", [True, False])
def test_malformed_result_refused(result, tmp_path, capsys, tamper, sealed):
    """A result changed with h5py (its checksum redone, or an old one without checksum):
    a wrong attribute type, a missing group, rays of the wrong shape, bad JSON, cones that
    are not this run's -> one line."""
    path = str(tmp_path / "r.h5")
    shutil.copy(result if sealed else OLD_RESULT, path)
    with h5py.File(path, "r+") as f:
        tamper(f)
    if sealed:
        seal(path)
        assert verify_checksum(path)
    _refused(path, capsys, "not a hpcwedge result")


def test_result_without_checksum_read_with_a_note(tmp_path, capsys):
    """Results written before checksums (a demo result of that time) are still read."""
    path = str(tmp_path / "old.h5")
    shutil.copy(OLD_RESULT, path)
    assert verify_checksum(path) is False
    capsys.readouterr()
    assert main(["show", path]) == 0
    err = capsys.readouterr().err.strip()
    assert err == (f"hpcwedge: note: {path} has no checksum (written by an hpcwedge older than checksummed "
                   f"results): read without verification")
    assert show_json(path)["runs"][0]["n_wedged_rays"] == 244


def test_the_result_records_the_digests_of_its_input_files(tmp_path):
    """A stiffness scene's K file: its SHA-256 is in the result (show --json "inputs")."""
    scene = write_scene(tmp_path)
    out = str(tmp_path / "r.h5")
    run(None, "run", scene, "-o", out, "-q")
    digest = hashlib.sha256((tmp_path / "plug8.npz").read_bytes()).hexdigest()
    assert show_json(out, rays=False)["inputs"] == {"model.file plug8.npz": digest}

