"""Files this program writes: the one atomic writer and the checksum of HDF5 files.

Every output (a result, a checkpoint, a plot's PNG, an export's VTU) is written by
`replace_atomic`: a temp file in the same folder, filled, fsynced, then os.replace and an
fsync of the folder, so a crash never leaves a half-written file at the path.

Every HDF5 file `write_atomic` writes (results and checkpoints) starts with a 512-byte
user block: CHECKSUM_MAGIC, the SHA-256 (hex) of all the bytes after the block, a
newline, zeros. verify_checksum checks it before h5py opens the file, so any damage (a
flipped byte anywhere, a truncation) is found, also in bytes h5py would never read.
"""
from __future__ import annotations

import hashlib
import io
import os
import re
import stat
import tempfile

from hpcwedge.errors import UserError


class FileError(UserError):
    """A file this program wrote (a result, a checkpoint) that cannot be used: damaged, not
    ours, or missing parts. The message is one line naming the file and the reason."""


def error_reason(e: BaseException) -> str:
    """A short one-line reason for an error of a file operation: the system's words for an
    OSError's errno, also the errno HDF5 embeds in h5py's messages ("No space left on
    device"), else the message on one line."""
    m = re.search(r"errno = (\d+)", str(e))
    if m:
        return os.strerror(int(m.group(1)))
    text = e.strerror if isinstance(e, OSError) and e.strerror else str(e)
    return " ".join(str(text).split()) or type(e).__name__


class CheckpointGiven(FileError):
    """A checkpoint where a result was expected (resultfile.open_result): `show` summarises
    it instead, plot and export refuse it with this one line."""


#: the root attribute "format" of a checkpoint (parallel/checkpoint.py)
CHECKPOINT_FORMAT = "hpcwedge-checkpoint"


def checkpoint_path(output: str) -> str:
    """Where the checkpoint of the run writing `output` lives."""
    return output + ".ckpt"


def resume_hint(ckpt: str) -> str:
    """The command that finishes the run of the checkpoint file `ckpt`."""
    result = ckpt.removesuffix(".ckpt") if ckpt.endswith(".ckpt") else "RESULT.h5"
    return f"hpcwedge run SCENE -o {result} --resume"


#: the user block at the start of every file write_atomic writes (see the module doc)
USERBLOCK_SIZE = 512
CHECKSUM_MAGIC = b"hpcwedge-sha256 "
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_CHUNK = 8 << 20


def _body_digest(fh) -> str:
    """SHA-256 (hex) of the bytes of the open binary file fh after the user block."""
    h = hashlib.sha256()
    fh.seek(USERBLOCK_SIZE)
    while chunk := fh.read(_CHUNK):
        h.update(chunk)
    return h.hexdigest()


def _checksum_block(digest: str) -> bytes:
    """The user block that records the SHA-256 `digest` (hex) of the bytes after it."""
    return (CHECKSUM_MAGIC + digest.encode() + b"\n").ljust(USERBLOCK_SIZE, b"\0")


def seal(path: str) -> None:
    """Write the checksum user block of the closed HDF5 file `path` (made with
    userblock_size=USERBLOCK_SIZE, or changed in place after it was sealed) and fsync it."""
    with open(path, "rb+") as fh:
        block = _checksum_block(_body_digest(fh))
        fh.seek(0)
        fh.write(block)
        fh.flush()
        os.fsync(fh.fileno())


def verify_checksum(path: str) -> bool:
    """Check the checksum user block of `path` against its bytes. True: verified; False: an
    HDF5 file without one (written before checksums). FileError when the file is damaged
    (digest differs, truncated, block altered), is not an HDF5 file, or cannot be read."""
    try:
        with open(path, "rb") as fh:
            block = fh.read(USERBLOCK_SIZE)
            if block[:len(HDF5_SIGNATURE)] == HDF5_SIGNATURE:
                return False
            if not block.startswith(CHECKSUM_MAGIC):
                raise FileError(f"{path}: not a file written by hpcwedge (no checksum block, no HDF5 signature)")
            stored = block[len(CHECKSUM_MAGIC):len(CHECKSUM_MAGIC) + 65]
            intact = (len(block) == USERBLOCK_SIZE and stored[-1:] == b"\n"
                      and not block[len(CHECKSUM_MAGIC) + 65:].strip(b"\0"))
            if not intact or _body_digest(fh).encode() != stored[:-1]:
                raise FileError(f"{path}: damaged: its SHA-256 checksum does not match its contents, "
                                f"it was truncated or altered after it was written")
    except OSError as e:
        raise FileError(f"{path}: cannot read ({error_reason(e)})") from None
    return True


def _umask() -> int:
    """The process's file mode creation mask (Linux: read from /proc, which leaves it
    untouched; elsewhere set and restored)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def output_mode(path: str) -> int:
    """The permission bits a file written to `path` gets: those of the regular file it
    replaces, else 0666 less the umask - what open(path, "w") would give."""
    try:
        st = os.stat(path)
        if stat.S_ISREG(st.st_mode):
            return stat.S_IMODE(st.st_mode)
    except OSError:
        pass
    return 0o666 & ~_umask()


def replace_atomic(path: str, write, suffix: str, tmp_path: str | None = None) -> None:
    """Make the file `path` through `write(tmp)`, which fills the temp file `tmp` (same
    folder; a fresh ".tmp-*<suffix>" name, mode 0600 while written, or the fixed
    `tmp_path`: a stale one from a killed writer is simply overwritten) and may raise to
    refuse it. Then tmp is given `output_mode(path)`, fsynced and renamed onto `path` and
    the folder fsynced, so a crash never leaves a half-written file and a refused or failed
    write (OSError: full disk, read-only folder...) raises, removes tmp and leaves `path`
    as it was."""
    folder = os.path.dirname(os.path.abspath(path)) or "."
    if tmp_path is None:
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=suffix, dir=folder)
        os.close(fd)
    else:
        tmp = tmp_path
    try:
        write(tmp)
        os.chmod(tmp, output_mode(path))
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    try:
        dfd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dfd)
    except OSError:
        pass
    finally:
        os.close(dfd)


def write_atomic(path: str, fill, tmp_path: str | None = None, verify=None) -> None:
    """Write an HDF5 file through `fill(h5file)` with replace_atomic: the temp file is
    closed, sealed with its checksum (module doc), optionally `verify(tmp)` (raises if the
    file is bad), then renamed, so a bad file never replaces a good one."""

    def write(tmp):
        # HDF5 builds the file in memory; only plain writes touch the disk, so a full disk or
        # a quota is an OSError here, not a failure inside the HDF5 library (which ended a run
        # with a segfault and h5py's tracebacks when its file could not be flushed or closed)
        image = io.BytesIO()
        import h5py  # HDF5 only where a file is written or read
        with h5py.File(image, "w", userblock_size=USERBLOCK_SIZE) as f:
            fill(f)
        body = image.getbuffer()[USERBLOCK_SIZE:]
        with open(tmp, "wb") as fh:
            fh.write(_checksum_block(hashlib.sha256(body).hexdigest()))
            fh.write(body)
        body.release()
        if verify is not None:
            verify(tmp)

    replace_atomic(path, write, ".h5", tmp_path)


def is_hdf5(path: str) -> bool:
    """Does the file at `path` carry HDF5's signature (after a user block, as a result's
    checksum block)? False when it cannot be read."""
    try:
        import h5py
        return bool(h5py.is_hdf5(path))
    except OSError:
        return False


def remove_if_there(path: str) -> None:
    """Remove the file `path` if it is there (a stale temp file; one that cannot be removed
    is left: the next write replaces it)."""
    try:
        os.unlink(path)
    except OSError:
        pass


class OutputLock:
    """An exclusive lock on a run's output: flock on OUTPUT.lock, held by the master for the
    whole run (the kernel releases it when the process dies, even by kill -9). A second run on
    the same output gets FileError naming the holder's pid. release() removes the file while
    still holding the lock; a run that opened the file before the removal notices that the
    path no longer names what it locked, and tries again."""

    def __init__(self, output: str):
        import fcntl
        self.path = output + ".lock"
        while True:
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as e:
                raise FileError(f"{self.path}: cannot create the output's lock file ({e.strerror})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
                os.close(fd)
                raise FileError(f"{output}: another hpcwedge run (pid {holder}) is writing this output "
                                 f"(lock {self.path}); wait for it to end or choose another -o") from None
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)                        # removed by the run that held it: lock the new file
        self.fd = fd
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        except OSError as e:                    # a full or failing disk: refuse before the work
            self.release()
            raise FileError(f"{output}: cannot write in its folder ({e.strerror})") from None

    def release(self) -> None:
        """Remove the lock file and release the lock (idempotent)."""
        if self.fd is None:
            return
        try:
            os.unlink(self.path)
        except OSError:
            pass
        os.close(self.fd)
        self.fd = None


def refuse_not_ours(path: str, hdf5_ok: bool = False) -> None:
    """FileError when `path` is a non-empty regular file that hpcwedge did not write (not ours
    to replace): ours begin with the checksum block (a result or checkpoint, even a damaged
    one) or, written before checksums, are HDF5 files holding a scene_text. hdf5_ok (the
    checkpoint beside a result): any HDF5 file passes, a damaged checkpoint among them (the
    resume then says so)."""
    if not os.path.isfile(path) or not os.path.getsize(path) or written_by_us(path):
        return
    if hdf5_ok and is_hdf5(path):
        return
    kind = "an HDF5 file hpcwedge did not write" if is_hdf5(path) else "not an HDF5 file"
    raise FileError(f"{path}: exists and is {kind}; refusing to replace it (remove it first, or give "
                     "another -o)")


def written_by_us(path: str) -> bool:
    """Does `path` begin with our checksum block, or is it an HDF5 file with a scene_text
    (a result or checkpoint written before checksums)?"""
    try:
        with open(path, "rb") as fh:
            if fh.read(len(CHECKSUM_MAGIC)) == CHECKSUM_MAGIC:
                return True
        import h5py
        with h5py.File(path, "r") as f:
            return "scene_text" in f
    except Exception:  # noqa: BLE001  (h5py raises OSError, RuntimeError... on damaged files)
        return False


def check_output(path: str, inputs=(), name_check=None, replaces_hdf5_only: bool = False) -> None:
    """Refuse an output path before any work (FileError naming it): empty, a directory or
    any other existing non-regular file (a device, a pipe), in a missing or read-only
    folder, not writable, the same file as one of `inputs` (hard and symbolic links
    included), a name that name_check(path) refuses (ValueError: a suffix of the wrong
    format), or, with replaces_hdf5_only (run: -o takes any name), an existing non-empty
    file hpcwedge did not write (a scene, a mesh, a table or a data file given to -o by
    mistake: refuse_not_ours). Used by
    run, plot and export, and by the API's writers (api.py)."""
    if not path:
        raise FileError("-o: empty file name")
    folder = os.path.dirname(os.path.abspath(path))
    try:
        st = os.stat(path)
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise FileError(f"{path}: cannot use as output ({e.strerror})") from None
    if st is not None:
        if stat.S_ISDIR(st.st_mode):
            raise FileError(f"{path}: is a directory (give a file name to -o)")
        if not stat.S_ISREG(st.st_mode):
            raise FileError(f"{path}: exists and is not a regular file (a device, pipe or socket); "
                             "refusing to replace it")
        for inp in inputs:
            try:
                same = os.path.samefile(path, inp)
            except OSError:
                same = False
            if same:
                raise FileError(f"{path}: is the input {inp}; writing the output would destroy it")
        if not os.access(path, os.W_OK):
            raise FileError(f"{path}: not writable")
        if replaces_hdf5_only:
            refuse_not_ours(path)
    elif os.path.islink(path):
        raise FileError(f"{path}: a dangling symbolic link; refusing to write through it")
    if not os.path.isdir(folder):
        raise FileError(f"{path}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise FileError(f"{path}: cannot write in {folder} (read-only file system or no permission)")
    if name_check is not None:
        try:
            name_check(path)
        except ValueError as e:
            raise FileError(str(e)) from None


def compression(arr) -> str | None:
    """The h5py filter for a dataset: gzip for large integer/bool/bytes arrays (zero sets,
    bit words, flags), none for floats (rays): gzip shrank float rays by ~8 % at 10x the
    write time (plug2d m = 16: 76 MB in 2.9 s against 82 MB in 0.3 s; m = 20: 1.20 GB
    against 1.28 GB, 40 s against ~2 s)."""
    return "gzip" if arr.size > 4096 and arr.dtype.kind not in "fc" else None
