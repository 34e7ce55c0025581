"""Results: Run, Result, SolveStats; result files (SPEC §4): HDF5 layout, atomic writes, `show`'s JSON.

Every file write_atomic writes (results and checkpoints) starts with a 512-byte HDF5 user
block: CHECKSUM_MAGIC, the SHA-256 (hex) of all the bytes after the block, a newline, zeros.
verify_checksum checks it before h5py opens the file, so any damage (a flipped byte
anywhere, a truncation) is found, also in bytes h5py would never read. Result files
written before checksums (no user block: they start with the HDF5 signature) are still
read, with a note on stderr.

Layout of RESULT.h5
    /                attrs: name, dim, m, complete, mu_c (NaN = null), mu_c_status,
                     version, scene_hash, inputs (JSON {"model.file k.npz": SHA-256 of
                     its bytes}: Scene.input_digests), stages (JSON), timings (JSON),
                     stats (JSON), scene_dir (absolute folder of the scene file: its file
                     paths are relative to it)
    /scene_text      the scene file, verbatim
    /model/          coords, contact_nodes, normals, cells_<kind> (when a model was built)
    /runs/<k>/       attrs: mu, n_wedged_rays, n_trivial_rays, n_cones, n_patterns
                     (an attribute absent = null); datasets rays, trivial_rays,
                     ray_zero, cones_json (JSON list), patterns_json (3D: JSON list of
                     {"contact", "mu_c", "undecided"}, canonical order: contact bits)
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import re
import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, fields, is_dataclass
from typing import TYPE_CHECKING

import h5py
import numpy as np

from . import __version__

if TYPE_CHECKING:
    from .model import Model
    from .problem import ContactProblem
    from .scene import Scene


def _count(name: str) -> property:
    """A read-only property: len(self.<name>), None while that field is None."""
    return property(lambda self: None if getattr(self, name) is None else len(getattr(self, name)),
                    doc=f"len({name}), None when the scene did not ask for it")


@dataclass
class Run:
    """The answers at one mu; a field the scene did not ask for is None."""

    mu: float
    rays: np.ndarray | None = None            # (R, 2n) wedged rays [u, r], sum(r_n) = 1
    trivial_rays: np.ndarray | None = None    # (T, 2n) rigid lift-offs, sum(u_n) = 1
    ray_zero: np.ndarray | None = None        # (R, 3m) zero flags of the wedged rays
    cones: list[dict] | None = None           # {"rays", "trivial_rays", "zero_u", "zero_r", "mu_c"}
    patterns: list[dict] | None = None        # {"contact", "mu_c"}

    n_wedged_rays = _count("rays")
    n_trivial_rays = _count("trivial_rays")
    n_cones = _count("cones")
    n_patterns = _count("patterns")


@dataclass
class Result:
    """Every answer of one scene (pipeline.run_scene): one Run per listed mu, the global mu^c,
    the stages run, their timings and the solve's stats (SolveStats.as_dict())."""

    scene: Scene
    m: int
    runs: list[Run]
    mu_c: float | None = None
    mu_c_status: str | None = None     # "found" | "none_at_any_mu" | "none_up_to_mu_max" | None
    complete: bool = True
    stages: list[str] = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    model: Model | None = None
    problem: ContactProblem | None = None

    def to_dict(self, with_rays: bool = True) -> dict:
        """The `hpcwedge show --json` object of this result (SPEC §4): written to a temporary
        result file and read back by results.read_result, the one JSON writer (so the two
        never differ; it costs a write and a read of the file)."""
        with tempfile.TemporaryDirectory(prefix="hpcwedge-") as folder:
            path = os.path.join(folder, "result.h5")
            write_result(path, self)
            return read_result(path, with_rays=with_rays)


@dataclass
class TreeStats:
    """stats.bnb of the patterns stage: a sign-pattern tree's counters summed over every mu
    (the same for every split of the work) and partitions (2^m per mu: a brute force's solves)."""

    nodes: int
    solves: int
    skipped: int
    pruned: int
    undecided: int
    partitions: int

    @classmethod
    def of(cls, counters: dict, partitions: int) -> TreeStats:
        """From a patterns job's counters (absent: 0)."""
        return cls(*(counters.get(f.name, 0) for f in fields(cls)[:-1]), partitions=partitions)


@dataclass
class GlobalRouteStats:
    """stats.bnb after a global mu^c search (patterns.global_mu_critical's BnBStats, its route
    "tree" or "milp" and MILP counts); it replaces the patterns stage's TreeStats."""

    solves: int = 0
    skipped: int = 0
    undecided: int = 0
    nodes: int = 0
    route: str = "tree"
    milp_solves: int = 0
    milp_nodes: int = 0


@dataclass
class SymmetryStats:
    """stats.symmetry: the node symmetry group's order; representatives: the orbit
    representatives found per mu (patterns stage, order > 1; else None)."""

    order: int
    representatives: list[int] | None = None


@dataclass
class SolveStats:
    """The statistics of one solve; Result.stats is as_dict(), the stats object of the result
    file (SPEC §4). Fields in the file's key order; None: absent from the file."""

    dd: list = field(default_factory=list)   # 2D rays: per mu {"mu", **dd.DDResult.stats}
    lp_solves: int = 0                       # mu^c stage: LP/SOCP solves
    mu_c_polished: int = 0                   # mu^c values polished (pencil / KKT)
    mu_c_unpolished: int = 0                 # ... left at a bisection bracket's end
    lp_undecided: int = 0                    # mu^c stage solves no solver decided
    symmetry: SymmetryStats | None = None
    patterns_undecided: int | None = None    # patterns kept undecided (flagged)
    bnb: TreeStats | GlobalRouteStats | None = None
    socp_statuses: dict | None = None        # 3D patterns: {solver status: count}
    numerics: dict | None = None             # numerics.Numerics.as_dict()
    parallel: dict | None = None             # Engine.summary()
    environment: dict | None = None          # environment.environment()

    def add(self, lps: int = 0, undecided: int = 0, polished: int = 0, unpolished: int = 0) -> None:
        """Count mu^c computations: LP/SOCP solves, undecided solves, values (un)polished."""
        self.lp_solves += lps
        self.lp_undecided += undecided
        self.mu_c_polished += polished
        self.mu_c_unpolished += unpolished

    def as_dict(self) -> dict:
        """The stats object: the fields that are not None, records as dicts (theirs likewise)."""
        def plain(r):
            return {f.name: plain(v) if is_dataclass(v) else v for f in fields(r)
                    if (v := getattr(r, f.name)) is not None}
        return plain(self)


class FileError(ValueError):
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


#: the user block at the start of every file write_atomic writes (see the module doc)
USERBLOCK_SIZE = 512
CHECKSUM_MAGIC = b"hpcwedge-sha256 "
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_CHUNK = 8 << 20


def _body_digest(fh) -> str:
    """SHA-256 (hex) of the bytes of the open binary file fh after the user block."""
    h = hashlib.sha256()
    fh.seek(USERBLOCK_SIZE)
    while chunk := fh.read(_CHUNK):
        h.update(chunk)
    return h.hexdigest()


def seal(path: str) -> None:
    """Write the checksum user block of the closed HDF5 file `path` (made with
    userblock_size=USERBLOCK_SIZE, or changed in place after it was sealed) and fsync it."""
    with open(path, "rb+") as fh:
        block = CHECKSUM_MAGIC + _body_digest(fh).encode() + b"\n"
        fh.seek(0)
        fh.write(block.ljust(USERBLOCK_SIZE, b"\0"))
        fh.flush()
        os.fsync(fh.fileno())


def verify_checksum(path: str) -> bool:
    """Check the checksum user block of `path` against its bytes. True: verified; False: an
    HDF5 file without one (written before checksums). FileError when the file is damaged
    (digest differs, truncated, block altered), is not an HDF5 file, or cannot be read."""
    try:
        with open(path, "rb") as fh:
            block = fh.read(USERBLOCK_SIZE)
            if block[:len(_HDF5_SIGNATURE)] == _HDF5_SIGNATURE:
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


def write_atomic(path: str, fill, tmp_path: str | None = None, verify=None) -> None:
    """Write an HDF5 file through `fill(h5file)`: temp file in the same folder, closed,
    sealed with its checksum (module doc) and fsynced, optionally `verify(tmp)` (raises if
    the file is bad), then os.replace and an fsync of the folder, so a crash never leaves a
    half-written file and a bad file never replaces a good one. tmp_path: a fixed temp name
    (a stale one from a killed writer is simply overwritten); default: a fresh one.
    A failed write (OSError: full disk, read-only folder...) raises and leaves `path` as it was."""
    folder = os.path.dirname(os.path.abspath(path)) or "."
    os.makedirs(folder, exist_ok=True)
    if tmp_path is None:
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".h5", dir=folder)
        os.close(fd)
    else:
        tmp = tmp_path
    try:
        with h5py.File(tmp, "w", userblock_size=USERBLOCK_SIZE) as f:
            fill(f)
        seal(tmp)
        if verify is not None:
            verify(tmp)
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


def compression(arr: np.ndarray) -> str | None:
    """The h5py filter for a dataset: gzip for large integer/bool/bytes arrays (zero sets,
    bit words, flags), none for floats (rays): gzip shrank float rays by ~8 % at 10x the
    write time (plug2d m = 16: 76 MB in 2.9 s against 82 MB in 0.3 s; m = 20: 1.20 GB
    against 1.28 GB, 40 s against ~2 s)."""
    return "gzip" if arr.size > 4096 and arr.dtype.kind not in "fc" else None


def write_result(path: str, result) -> None:
    """Store a Result (see module doc)."""

    def fill(f):
        s = result.scene
        f.attrs.update({"name": s.name, "dim": s.dim, "m": result.m, "complete": result.complete,
                        "mu_c": np.nan if result.mu_c is None else result.mu_c,
                        "mu_c_status": result.mu_c_status or "",
                        "version": __version__, "scene_hash": s.hash,
                        "inputs": json.dumps(s.input_digests),
                        "scene_dir": os.path.abspath(s.base_dir),
                        "stages": json.dumps(result.stages), "timings": json.dumps(result.timings),
                        "stats": json.dumps(result.stats, default=_plain)})
        f.create_dataset("scene_text", data=s.text)
        if result.model is not None:
            g = f.create_group("model")
            mdl = result.model
            g["coords"], g["contact_nodes"], g["normals"] = mdl.coords, mdl.contact_nodes, mdl.normals
            for kind, cells in mdl.cells.items():
                g[f"cells_{kind}"] = np.asarray(cells)
        runs = f.create_group("runs")
        for k, run in enumerate(result.runs):
            g = runs.create_group(f"{k:03d}")
            g.attrs["mu"] = run.mu
            for name in ("n_wedged_rays", "n_trivial_rays", "n_cones", "n_patterns"):
                v = getattr(run, name)
                if v is not None:
                    g.attrs[name] = v
            for name in ("rays", "trivial_rays", "ray_zero"):
                v = getattr(run, name)
                if v is not None:
                    g.create_dataset(name, data=v, compression=compression(v))
            if run.cones is not None:
                g.create_dataset("cones_json", data=json.dumps(run.cones, default=_plain))
            if run.patterns is not None:
                g.create_dataset("patterns_json", data=json.dumps(run.patterns, default=_plain))

    write_atomic(path, fill)


#: what h5py, numpy and json raise on a file whose structure is not a result's
STRUCTURE_ERRORS = (KeyError, TypeError, ValueError, IndexError, AttributeError, OSError)


@contextmanager
def open_result(path: str, passthrough: tuple = ()):
    """The result file `path` opened read-only (an h5py.File) after verify_checksum (a file
    written before checksums is read, with a note on stderr once it has been read; a file
    verified before in this process and unchanged since is not hashed again: _VERIFIED).
    Every problem of the file, also one met in the caller's with block (a missing dataset, a
    wrong type or shape, bad JSON), is a FileError naming the file; exceptions of the
    classes in `passthrough` (the caller's own one-line errors) pass as they are."""
    if not os.path.exists(path):
        raise FileError(f"{path}: no such file")
    try:
        st = os.stat(path)
    except OSError as e:
        raise FileError(f"{path}: cannot read ({error_reason(e)})") from None
    ident = (os.path.realpath(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
    verified = ident in _VERIFIED or verify_checksum(path)
    if verified and time.time() - max(st.st_mtime, st.st_ctime) > STABLE_S:
        _VERIFIED.add(ident)
    try:
        with h5py.File(path, "r") as f:
            yield f
    except (FileError, *passthrough):
        raise
    except STRUCTURE_ERRORS as e:
        reason = " ".join(str(e).split()) or type(e).__name__
        raise FileError(f"{path}: not a hpcwedge result ({reason})") from None
    if not verified and path not in _NOTED:
        _NOTED.add(path)
        print(f"hpcwedge: note: {path} has no checksum (written by an hpcwedge older than "
              f"checksummed results): read without verification", file=sys.stderr)


#: the files without checksum open_result has read in this process (one note each)
_NOTED: set = set()
#: (path, device, inode, size, mtime, ctime) of the files open_result verified in this process
#: that had not changed for STABLE_S seconds. Any later change gives such a file new times
#: (far beyond the clock's granularity), hence a new identity that is verified again. show,
#: plot and export open a result up to three times; a pass over a 1.3 GB result costs ~2 s.
_VERIFIED: set = set()
STABLE_S = 2.0


def read_result(path: str, with_rays: bool = True) -> dict:
    """The `show --json` object of a result file (SPEC §4), rays as nested lists.
    FileError (one line) for a missing, damaged or malformed file."""
    with open_result(path) as f:
        return _result_object(f, (lambda ds: ds[()].tolist()) if with_rays else None)


def dump_result_json(path: str, out, with_rays: bool = True) -> None:
    """Write read_result(path, with_rays) as one JSON object to the text stream `out`, the
    ray arrays streamed RAY_CHUNK rows at a time: a result with millions of rays (plug2d
    m = 20: 2e6 x 80) never exists as Python lists or as one string. FileError as read_result
    (found before anything is written, as the checksum covers the whole file)."""
    with open_result(path, passthrough=(BrokenPipeError,)) as f:
        _dump(_result_object(f, _Rows if with_rays else None), out)
        out.write("\n")


#: rows per read when streaming ray arrays to JSON
RAY_CHUNK = 16384


class _Rows:
    """A 2D dataset to be written as a JSON list of lists, chunk by chunk."""

    def __init__(self, ds):
        self.ds = ds

    def write(self, out) -> None:
        out.write("[")
        n = self.ds.shape[0]
        for lo in range(0, n, RAY_CHUNK):
            rows = self.ds[lo:min(n, lo + RAY_CHUNK)].tolist()
            out.write(("," if lo else "") + ",".join("[" + ",".join(map(repr, r)) + "]" for r in rows))
        out.write("]")


def _dump(obj, out) -> None:
    if isinstance(obj, _Rows):
        obj.write(out)
    elif isinstance(obj, dict):
        out.write("{")
        for i, (k, v) in enumerate(obj.items()):
            out.write(("," if i else "") + json.dumps(k) + ":")
            _dump(v, out)
        out.write("}")
    elif isinstance(obj, list) and any(isinstance(v, (dict, _Rows)) for v in obj):
        out.write("[")
        for i, v in enumerate(obj):
            out.write("," if i else "")
            _dump(v, out)
        out.write("]")
    else:
        out.write(json.dumps(obj))


def _result_object(f, rays) -> dict:
    """The show object of the open file f; rays(dataset) gives the value of a ray array
    (None: not read, null in the output)."""
    a = f.attrs
    mu_c = float(a["mu_c"])
    out = {"name": str(a["name"]), "dim": int(a["dim"]), "m": int(a["m"]),
           "complete": bool(a["complete"]),
           "mu_c": None if math.isnan(mu_c) else mu_c,
           "mu_c_status": str(a["mu_c_status"]) or None,
           "runs": [], "timings": json.loads(a["timings"]),
           "stages": json.loads(a["stages"]), "stats": json.loads(a["stats"]),
           "version": str(a["version"]), "scene_hash": str(a["scene_hash"]),
           "inputs": json.loads(a["inputs"]) if "inputs" in a else None}
    for k in sorted(f["runs"]):
        g = f["runs"][k]
        run = {"mu": float(g.attrs["mu"])}
        for name in ("n_wedged_rays", "n_trivial_rays", "n_cones", "n_patterns"):
            run[name] = int(g.attrs[name]) if name in g.attrs else None
        for name in ("rays", "trivial_rays"):
            if name in g and (g[name].ndim != 2 or g[name].dtype.kind != "f"):
                raise TypeError(f"/runs/{k}/{name}: {g[name].ndim}-D {g[name].dtype}, expected 2-D floats")
            run[name] = rays(g[name]) if (name in g and rays is not None) else None
        run["cones"] = json.loads(_text(g["cones_json"])) if "cones_json" in g else None
        run["patterns"] = json.loads(_text(g["patterns_json"])) if "patterns_json" in g else None
        n_rays = g["rays"].shape[0] if "rays" in g else int(g.attrs.get("n_wedged_rays", 0))
        check_items(run["cones"], run["patterns"], n_rays, out["m"])
        out["runs"].append(run)
    return out


def check_items(cones, patterns, n_rays: int, m: int) -> None:
    """ValueError unless a run's cones and patterns (parsed cones_json, patterns_json; None
    passes) have the layout of the module doc: cones {"rays": wedged-ray indices < n_rays,
    "zero_u", "zero_r": node indices < m, "mu_c": number or null}, patterns {"contact": node
    indices < m, "mu_c"}. Readers check before using them, so a malformed file is one line."""
    def indices(v, n):
        return isinstance(v, list) and all(type(i) is int and 0 <= i < n for i in v)

    def number(v):
        return v is None or type(v) in (int, float)
    if cones is not None and not (isinstance(cones, list) and all(
            isinstance(c, dict) and indices(c.get("rays"), n_rays) and indices(c.get("zero_u"), m)
            and indices(c.get("zero_r"), m) and number(c.get("mu_c")) for c in cones)):
        raise ValueError("cones_json: not the cones of this run")
    if patterns is not None and not (isinstance(patterns, list) and all(
            isinstance(p, dict) and indices(p.get("contact"), m) and number(p.get("mu_c")) for p in patterns)):
        raise ValueError("patterns_json: not the sign patterns of this run")


def index(i: int, n: int) -> int | None:
    """Python-style index i into n items (0..n-1 or -n..-1) as 0..n-1, or None when out of range."""
    i = int(i)
    return i % n if -n <= i < n else None


def index_range(n: int) -> str:
    """The valid indices into n items, for messages: "0..n-1 or -n..-1" (or "none")."""
    return f"0..{n - 1} or -{n}..-1" if n else "none"


def _text(ds) -> str:
    v = ds[()]
    return v.decode() if isinstance(v, bytes) else str(v)


def _plain(o):
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))
