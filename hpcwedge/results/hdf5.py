"""The result file (SPEC §4): the HDF5 layout of a results.Result, its writer, its reader
(read_result: the Result written), and the JSON of `show` (dump_result_json, streamed from
the file; Result.to_dict gives the same object from the record).

Results are written by files.write_atomic (checksummed user block, atomic rename) and
opened by open_result, which verifies the checksum first. Result files written before
checksums (no user block: they start with the HDF5 signature) are still read, with a note
on stderr. show, plot and export read a result through open_result and the small readers
below (read_run, read_rays, read_items, stored_scene, text).

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
                     ray_zero, cones_json (JSON list of Cone.to_dict()), patterns_json (JSON
                     list of Pattern.to_dict(): {"contact", "mu_c", "undecided",
                     "mu_c_polished"}, canonical order: contact bits; mu_c_polished: the
                     value certified (pencil / KKT polish) or an upper bound (a bisection
                     bracket's end, a 3D point), null without a value, absent when no mu^c
                     stage ran)
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
import tomllib
from contextlib import contextmanager

import h5py
import numpy as np

from hpcwedge.errors import UserError
from hpcwedge.files import (
    CHECKPOINT_FORMAT,
    CheckpointGiven,
    FileError,
    checkpoint_path,
    compression,
    error_reason,
    resume_hint,
    verify_checksum,
    write_atomic,
)
from hpcwedge.results.record import Cone, Pattern, Result, Run, StoredModel, plain_number
from hpcwedge.scene.parse import changed_settings, parse_scene
from hpcwedge.scene.values import SceneError


def write_result(path: str, result, tmp_path: str | None = None) -> None:
    """Store a results.Result (see module doc). tmp_path: the temp file's fixed name
    (files.replace_atomic; default: a fresh hidden name in the same folder)."""

    def fill(f):
        s = result.scene
        f.attrs.update({"name": s.name, "dim": s.dim, "m": result.m, "complete": result.complete,
                        "mu_c": np.nan if result.mu_c is None else result.mu_c,
                        "mu_c_status": result.mu_c_status or "",
                        "version": result.version, "scene_hash": s.hash,
                        "inputs": json.dumps(s.input_digests),
                        "scene_dir": os.path.abspath(s.base_dir),
                        "stages": json.dumps(result.stages), "timings": json.dumps(result.timings),
                        "stats": json.dumps(result.stats, default=plain_number)})
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
                g.create_dataset("cones_json", data=json.dumps([c.to_dict() for c in run.cones], default=plain_number))
            if run.patterns is not None:
                g.create_dataset("patterns_json", data=json.dumps([p.to_dict() for p in run.patterns],
                                                                  default=plain_number))

    write_atomic(path, fill, tmp_path)


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
        ckpt = checkpoint_path(path)
        if os.path.exists(ckpt):
            raise FileError(f"{path}: no such file; its run stopped with a checkpoint: `hpcwedge show {ckpt}` "
                            f"tells how far it got, `{resume_hint(ckpt)}` finishes it")
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
            if f.attrs.get("format") == CHECKPOINT_FORMAT:
                raise CheckpointGiven(f"{path}: a checkpoint of an unfinished run, not a result: `hpcwedge show "
                                f"{path}` tells how far it got, `{resume_hint(path)}` finishes it")
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


def read_result(path: str, with_rays: bool = True) -> Result:
    """The Result stored in a result file, equal field for field to the one written: the
    scene parsed from its stored text and folder, with the input digests the file recorded;
    rays as the arrays written, bit for bit (with_rays False: not read, their counts kept in
    Run.stored_counts); model the StoredModel of /model; problem None. FileError (one line)
    for a missing, damaged or malformed file, or a stored scene that no longer parses."""
    with open_result(path) as f:
        a = f.attrs
        text, scene_dir, inputs = stored_scene(f)
        try:
            scene = parse_scene(tomllib.loads(text), text=text, base_dir=scene_dir or os.path.dirname(
                os.path.abspath(path)))
        except (SceneError, tomllib.TOMLDecodeError) as e:
            raise FileError(f"{path}: its stored scene does not read ({str(e).splitlines()[0]})") from None
        if inputs is not None:                # Scene.input_digests is cached: the file's, not the bytes now
            scene.__dict__["input_digests"] = inputs
        if (str(a["name"]), int(a["dim"])) != (scene.name, scene.dim):
            raise ValueError("the name or dim attribute is not the stored scene's")
        m = int(a["m"])
        mu_c = float(a["mu_c"])
        return Result(scene=scene, m=m, runs=[_read_run(g, m, with_rays) for g in _run_groups(f)],
                      mu_c=None if math.isnan(mu_c) else mu_c, mu_c_status=str(a["mu_c_status"]) or None,
                      complete=bool(a["complete"]), stages=json.loads(a["stages"]),
                      timings=json.loads(a["timings"]), stats=json.loads(a["stats"]), model=read_model(f),
                      version=str(a["version"]))


def _run_groups(f) -> list:
    """The /runs/<k> groups in order."""
    return [f["runs"][k] for k in sorted(f["runs"])]


def _read_run(g, m: int, with_rays: bool) -> Run:
    """The Run of run group g (a result with m contact nodes)."""
    check_arrays(g)
    arrays = {name: g[name][()] if name in g else None for name in ("rays", "trivial_rays", "ray_zero")}
    n_rays = g["rays"].shape[0] if "rays" in g else int(g.attrs.get("n_wedged_rays", 0))
    cones, patterns = read_items(g, "cones", n_rays, m), read_items(g, "patterns", n_rays, m)
    if with_rays:
        return Run(float(g.attrs["mu"]), **arrays, cones=cones, patterns=patterns)
    counts = {name: int(g.attrs[attr]) for name, attr in (("rays", "n_wedged_rays"),
                                                          ("trivial_rays", "n_trivial_rays")) if attr in g.attrs}
    return Run(float(g.attrs["mu"]), cones=cones, patterns=patterns, stored_counts=counts)


def result_state(path: str, scene) -> str:
    """What the file at `path` is for `scene` (a scene.Scene): "missing"; "complete" or
    "incomplete", a result of this scene (its text, or one whose record, the part the answers
    depend on, is the same: scene.parse.changed_settings) and these input files' bytes; else
    "other-scene". FileError for a file that
    is not a readable result; SceneError when an input file cannot be read."""
    if not os.path.exists(path):
        return "missing"
    with open_result(path) as f:
        text, _, inputs = stored_scene(f)
        if str(f.attrs["scene_hash"]) != scene.hash and changed_settings(text, scene.text) is None:
            return "other-scene"
        if (inputs or {}) != scene.input_digests:
            return "other-scene"
        return "complete" if bool(f.attrs["complete"]) else "incomplete"


def dump_result_json(path: str, out, with_rays: bool = True) -> None:
    """Write the `show --json` object of a result file (SPEC §4: read_result(path,
    with_rays).to_dict(with_rays)) as one JSON object to the text stream `out`, the
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
        check_arrays(g)
        for name in ("rays", "trivial_rays"):
            run[name] = rays(g[name]) if (name in g and rays is not None) else None
        run["cones"], run["patterns"] = _items_json(g, "cones"), _items_json(g, "patterns")
        n_rays = g["rays"].shape[0] if "rays" in g else int(g.attrs.get("n_wedged_rays", 0))
        check_items(run["cones"], run["patterns"], n_rays, out["m"])
        out["runs"].append(run)
    return out


def check_arrays(g) -> None:
    """TypeError unless run group g's ray arrays (those stored) are 2-D floats."""
    for name in ("rays", "trivial_rays"):
        if name in g and (g[name].ndim != 2 or g[name].dtype.kind != "f"):
            raise TypeError(f"{g.name}/{name}: {g[name].ndim}-D {g[name].dtype}, expected 2-D floats")


def check_items(cones, patterns, n_rays: int, m: int) -> None:
    """ValueError unless a run's cones and patterns (parsed cones_json, patterns_json; None
    passes) have the layout of the module doc: cones {"rays": wedged-ray indices < n_rays,
    "zero_u", "zero_r": node indices < m, "mu_c": number or null, "mu_c_polished": bool or null
    or absent}, patterns {"contact": node indices < m, "mu_c", "mu_c_polished"}. Readers check before using them, so a malformed file is one line."""
    def indices(v, n):
        return isinstance(v, list) and all(type(i) is int and 0 <= i < n for i in v)

    def number(v):
        return v is None or type(v) in (int, float)

    def flag(v):
        return v is None or type(v) is bool
    if cones is not None and not (isinstance(cones, list) and all(
            isinstance(c, dict) and indices(c.get("rays"), n_rays) and indices(c.get("zero_u"), m)
            and indices(c.get("zero_r"), m) and number(c.get("mu_c")) and flag(c.get("mu_c_polished"))
            for c in cones)):
        raise ValueError("cones_json: not the cones of this run")
    if patterns is not None and not (isinstance(patterns, list) and all(
            isinstance(p, dict) and indices(p.get("contact"), m) and number(p.get("mu_c"))
            and flag(p.get("mu_c_polished")) for p in patterns)):
        raise ValueError("patterns_json: not the sign patterns of this run")


def index(i: int, n: int) -> int | None:
    """Python-style index i into n items (0..n-1 or -n..-1) as 0..n-1, or None when out of range."""
    i = int(i)
    return i % n if -n <= i < n else None


def index_range(n: int) -> str:
    """The valid indices into n items, for messages: "0..n-1 or -n..-1" (or "none")."""
    return f"0..{n - 1} or -{n}..-1" if n else "none"


# --------------------------------------------------------------------------- readers
# The small readers show, plot and export share, each for an open result file f (or one of
# its run groups g, from read_run). Run them inside open_result: a missing dataset or a
# value of the wrong type raises there and becomes a FileError naming the file.

class RangeError(UserError):
    """A run index outside a result's runs: one line, without the command's prefix."""


def text(v) -> str:
    """A string stored in a result (a dataset or an attribute value; bytes or str) as str."""
    v = v[()] if isinstance(v, h5py.Dataset) else v
    return v.decode() if isinstance(v, bytes) else str(v)


def read_run(f, run: int) -> tuple[int, int, h5py.Group]:
    """(k, the number of runs, the group /runs/<k>) of the Python-style run index `run`;
    RangeError when it is out of range."""
    keys = sorted(f["runs"])
    k = index(run, len(keys))
    if k is None:
        raise RangeError(f"run {run} out of range (the result has {len(keys)} run(s): "
                         f"{index_range(len(keys))})")
    return k, len(keys), f["runs"][keys[k]]


def read_counts(f, name: str) -> list[tuple[float, int | None]]:
    """(mu, the count attribute `name`, e.g. "n_patterns", or None when absent) of every run."""
    return [(float(g.attrs["mu"]), int(g.attrs[name]) if name in g.attrs else None)
            for g in (f["runs"][k] for k in sorted(f["runs"]))]


def read_rays(g, width: int) -> np.ndarray | None:
    """The wedged rays of run group g as an (n, width) float array (width = 2 dim m), or None
    when the run has none stored."""
    return np.asarray(g["rays"][()], dtype=float).reshape(-1, width) if "rays" in g else None


def read_items(g, kind: str, n_rays: int, m: int) -> list[Cone] | list[Pattern] | None:
    """The Cones (kind "cones") or Patterns ("patterns") of run group g, None when not
    stored; ValueError unless they fit a run of n_rays wedged rays and m nodes (check_items)."""
    items = _items_json(g, kind)
    if kind == "cones":
        check_items(items, None, n_rays, m)
        return None if items is None else [Cone.from_dict(c) for c in items]
    check_items(None, items, n_rays, m)
    return None if items is None else [Pattern.from_dict(p) for p in items]


def _items_json(g, kind: str) -> list | None:
    """The parsed JSON list of run group g's "cones" or "patterns" (None when not stored)."""
    name = f"{kind}_json"
    return json.loads(text(g[name])) if name in g else None


def read_model(f) -> StoredModel | None:
    """The /model group, or None when the result has none."""
    if "model" not in f:
        return None
    mg = f["model"]
    return StoredModel(coords=np.asarray(mg["coords"][()], dtype=float),
                       contact_nodes=np.asarray(mg["contact_nodes"][()], dtype=int),
                       normals=np.asarray(mg["normals"][()], dtype=float),
                       cells={name[len("cells_"):]: np.asarray(mg[name][()], dtype=int)
                              for name in mg if name.startswith("cells_")})


def stored_scene(f) -> tuple[str, str | None, dict | None]:
    """(the scene text, its folder scene_dir, the input digests) the result recorded; the
    last two are None in results written before they were recorded."""
    return (text(f["scene_text"]), text(f.attrs["scene_dir"]) if "scene_dir" in f.attrs else None,
            dict(json.loads(f.attrs["inputs"])) if "inputs" in f.attrs else None)

