"""The one atomic writer and the checksum (files.py): a failed or refused write leaves the
old file exactly as it was and no temp file behind; a written HDF5 file verifies."""
import os
import stat

import pytest

from hpcwedge.files import USERBLOCK_SIZE, FileError, replace_atomic, verify_checksum, write_atomic


def test_write_atomic_seals_and_a_failed_verify_keeps_the_old_file(tmp_path):
    path = str(tmp_path / "x.h5")
    write_atomic(path, lambda f: f.create_dataset("a", data=[1, 2, 3]))
    good = open(path, "rb").read()
    assert verify_checksum(path) and len(good) > USERBLOCK_SIZE

    def bad(tmp):
        raise FileError("no")
    with pytest.raises(FileError):
        write_atomic(path, lambda f: f.create_dataset("a", data=[4]), verify=bad)
    assert open(path, "rb").read() == good and os.listdir(tmp_path) == ["x.h5"]


def test_replace_atomic_writes_through_a_temp_file_in_the_folder(tmp_path):
    path = tmp_path / "f.png"
    seen = []

    def write(tmp):
        seen.append(tmp)
        assert os.path.dirname(tmp) == str(path.parent) and os.path.basename(tmp).startswith(".tmp-")
        assert tmp.endswith(".png") and not path.exists()
        open(tmp, "wb").write(b"picture")
    replace_atomic(str(path), write, ".png")
    assert path.read_bytes() == b"picture" and os.listdir(path.parent) == ["f.png"]
    assert not os.path.exists(seen[0])
    # a missing folder is not made (before: /nonexistent/dir/r.h5 from the API made /nonexistent)
    with pytest.raises(FileNotFoundError):
        replace_atomic(str(tmp_path / "new" / "f.png"), write, ".png")
    assert os.listdir(tmp_path) == ["f.png"]


@pytest.fixture
def umask():
    """Set the process's umask for the test (umask(m)), restored after it."""
    old = os.umask(0o022)
    os.umask(old)
    yield os.umask
    os.umask(old)


@pytest.mark.parametrize("mask", [0o022, 0o002, 0o077, 0o027])
def test_new_file_mode_follows_the_umask(tmp_path, umask, mask):
    """A new output gets what open(path, "w") would give, 0666 less the umask (before: the
    temp file's 0600 whatever the umask, so a group's shared project folder got results
    nobody else could read), on both temp-name routes."""
    umask(mask)
    path, ckpt = tmp_path / "f.png", tmp_path / "c.ckpt"
    replace_atomic(str(path), lambda t: open(t, "wb").write(b"x"), ".png")
    replace_atomic(str(ckpt), lambda t: open(t, "wb").write(b"x"), ".h5", tmp_path=str(ckpt) + ".tmp")
    plain = tmp_path / "plain"
    plain.write_bytes(b"x")
    for p in (path, ckpt):
        assert stat.S_IMODE(p.stat().st_mode) == stat.S_IMODE(plain.stat().st_mode) == 0o666 & ~mask


def test_replaced_file_keeps_its_mode(tmp_path, umask):
    """Writing over an existing file keeps its permission bits, as open(path, "w") does."""
    umask(0o022)
    path = tmp_path / "r.h5"
    write_atomic(str(path), lambda f: f.create_dataset("a", data=[1]))
    for mode in (0o640, 0o604, 0o600):
        os.chmod(path, mode)
        write_atomic(str(path), lambda f: f.create_dataset("a", data=[2]))
        assert stat.S_IMODE(path.stat().st_mode) == mode and verify_checksum(str(path))


@pytest.mark.parametrize("error", [OSError(28, "No space left on device"), KeyboardInterrupt()])
def test_replace_atomic_failure_keeps_the_old_file(tmp_path, error):
    path = tmp_path / "f.vtu"
    path.write_bytes(b"old")

    def write(tmp):
        open(tmp, "wb").write(b"half")
        raise error
    with pytest.raises(type(error)):
        replace_atomic(str(path), write, ".vtu")
    assert path.read_bytes() == b"old" and os.listdir(tmp_path) == ["f.vtu"]


def test_replace_atomic_fixed_temp_name_overwrites_a_stale_one(tmp_path):
    path, tmp = tmp_path / "c.ckpt", tmp_path / "c.ckpt.tmp"
    tmp.write_bytes(b"stale from a killed writer")
    replace_atomic(str(path), lambda t: open(t, "wb").write(b"fresh"), ".h5", tmp_path=str(tmp))
    assert path.read_bytes() == b"fresh" and not tmp.exists()


def test_is_hdf5_sees_the_signature_after_the_checksum_block(tmp_path):
    """A file write_atomic made starts with the checksum block, its HDF5 signature after it:
    HDF5; text, an empty file and a missing one are not."""
    from hpcwedge.files import HDF5_SIGNATURE, is_hdf5, remove_if_there, write_atomic
    h5 = tmp_path / "r.h5"
    write_atomic(str(h5), lambda f: f.create_dataset("x", data=[1.0]))
    assert not h5.read_bytes().startswith(HDF5_SIGNATURE) and is_hdf5(str(h5))
    (tmp_path / "s.toml").write_text('name = "s"\n')
    (tmp_path / "empty").write_bytes(b"")
    assert not any(is_hdf5(str(tmp_path / n)) for n in ("s.toml", "empty", "missing"))
    remove_if_there(str(h5))
    remove_if_there(str(h5))                    # gone already: nothing to do
    assert not h5.exists()
