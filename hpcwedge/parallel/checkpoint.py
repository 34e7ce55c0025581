"""Checkpoints (SPEC §5): the master's state in one HDF5 file, written atomically.

Path: ``RESULT.h5.ckpt`` beside the result (``checkpoint_path``); it is
written to ``RESULT.h5.ckpt.tmp``, flushed, fsynced, read back and checked,
then renamed onto the old checkpoint (and the folder fsynced), so a crash at
any moment leaves the previous good checkpoint in place. It is removed once
the result file is written. Like a result, it carries the SHA-256 of its bytes
(files.write_atomic), verified before anything is read: a damaged checkpoint
is a CheckpointError, and nothing here deletes or rewrites it.

Checkpointer: the checkpoints of one run — the run's identity (scene hash and
input digests: a resume from another scene or changed inputs is refused), the
timer, the job states restored from the checkpoint, the time of all sessions.

Layout (every job state is plain arrays and attributes; the jobs (jobs.py)
fill them, this module never interprets them):

    /                attrs: format = "hpcwedge-checkpoint", format_version,
                     version (program), scene_hash, inputs (JSON: Scene.input_digests,
                     the bytes of the files the scene names), elapsed_s (all sessions),
                     resumes, ranks, reason ("timer" | "SIGUSR1" | "SIGTERM" | ...),
                     written_unix
    /scene_text      the scene file, verbatim
    /jobs            attrs: order (JSON list of job names, in the order they ran)
    /jobs/<name>/    attrs: kind, finished, counters (JSON), job attributes;
                     datasets: the job's arrays (see jobs.SubtreeJob / TaskJob)
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
import tomllib

import numpy as np

from hpcwedge.files import CHECKPOINT_FORMAT as FORMAT
from hpcwedge.files import FileError, compression, error_reason, verify_checksum, write_atomic
from hpcwedge.version import __version__

#: 2: checksummed (files.write_atomic), with the scene's input digests
FORMAT_VERSION = 2


class CheckpointError(FileError):
    """A checkpoint that cannot be used: one line naming the file and the reason."""


def write_checkpoint(path: str, header: dict, scene_text: str, jobs: list[tuple[str, dict]]) -> None:
    """header: root attributes (scene_hash, inputs, elapsed_s, resumes, ranks, reason);
    jobs: (name, {"attrs": {...}, "data": {name: array}}) in the order they ran."""

    def fill(f):
        f.attrs.update({"format": FORMAT, "format_version": FORMAT_VERSION,
                        "version": __version__, "written_unix": time.time()})
        f.attrs.update(header)
        f.create_dataset("scene_text", data=scene_text)
        g = f.create_group("jobs")
        g.attrs["order"] = json.dumps([name for name, _ in jobs])
        for name, state in jobs:
            jg = g.create_group(name)
            jg.attrs.update(state["attrs"])
            for key, arr in state["data"].items():
                arr = np.asarray(arr)
                jg.create_dataset(key, data=arr, compression=compression(arr))

    write_atomic(path, fill, tmp_path=path + ".tmp", verify=read_checkpoint)


def read_checkpoint(path: str) -> dict:
    """{"attrs", "scene_text", "jobs": {name: {"attrs", "data"}}, "order"}; every
    problem (unreadable, damaged: its checksum does not verify, not a checkpoint, other
    format) is a CheckpointError; the file is left as it is."""
    try:
        verified = verify_checksum(path)
    except FileError as e:
        raise CheckpointError(f"{path}: unreadable checkpoint ({str(e).removeprefix(path + ': ')})") from None
    if not verified:
        raise CheckpointError(f"{path}: unreadable checkpoint (no checksum: written by an older hpcwedge); "
                              f"finish the run with that version, or remove it to start afresh")
    try:
        import h5py  # HDF5 only where a checkpoint is read or written
        with h5py.File(path, "r") as f:
            attrs = {k: _plain(v) for k, v in f.attrs.items()}
            if attrs.get("format") != FORMAT:
                raise CheckpointError(f"{path}: not a hpcwedge checkpoint")
            if attrs.get("format_version") != FORMAT_VERSION:
                raise CheckpointError(f"{path}: checkpoint format {attrs.get('format_version')}, "
                                      f"this program reads format {FORMAT_VERSION}")
            for key in ("version", "scene_hash", "inputs", "elapsed_s", "resumes"):
                if key not in attrs:
                    raise CheckpointError(f"{path}: checkpoint lacks the attribute {key!r}")
            text = f["scene_text"][()]
            text = text.decode() if isinstance(text, bytes) else str(text)
            order = json.loads(f["jobs"].attrs["order"])
            jobs = {}
            for name in order:
                g = f["jobs"][name]
                jobs[name] = {"attrs": {k: _plain(v) for k, v in g.attrs.items()},
                              "data": {k: g[k][()] for k in g}}
    except CheckpointError:
        raise
    except Exception as e:  # h5py raises OSError, KeyError, ValueError... on damaged files
        reason = " ".join(str(e).split()) or type(e).__name__
        raise CheckpointError(f"{path}: unreadable checkpoint (truncated or corrupt: {reason})") from None
    return {"attrs": attrs, "scene_text": text, "jobs": jobs, "order": order}


def checkpoint_summary(path: str, describe=None) -> dict:
    """How far the run of a checkpoint got (`hpcwedge show RESULT.h5.ckpt`), after
    read_checkpoint's checks (CheckpointError as there): {"checkpoint": true, "name" (the
    scene's, None if its text does not parse), "version", "scene_hash", "written_unix",
    "reason", "elapsed_s" (all sessions), "resumes", "ranks", "jobs": [{"name", "kind",
    "finished", "counters"} + subtree jobs: "mu" (list), "found" (patterns, orbit
    representatives where a tree uses a symmetry), "open" (subtrees left);
    task jobs: "tasks", "done"; + what describe says], in the order they ran}.
    describe(attrs, data) -> dict | None: what the job's owner says of a job's saved state
    (None: nothing more)."""
    ck = read_checkpoint(path)
    a = ck["attrs"]
    try:
        name = tomllib.loads(ck["scene_text"]).get("name")
    except tomllib.TOMLDecodeError:
        name = None
    jobs = []
    try:
        for job_name in ck["order"]:
            ja, data = ck["jobs"][job_name]["attrs"], ck["jobs"][job_name]["data"]
            job = {"name": job_name, "kind": ja["kind"], "finished": bool(ja["finished"]),
                   "counters": json.loads(ja["counters"])}
            if "n_tasks" in ja:
                job.update(tasks=int(ja["n_tasks"]), done=len(data["done"]))
            extra = describe(ja, data) if describe is not None else None
            job.update(extra or {})
            jobs.append(job)
    except (KeyError, TypeError, ValueError) as e:
        raise CheckpointError(f"{path}: unreadable checkpoint (a job lacks {e})") from None
    return {"checkpoint": True, "name": name, "version": a["version"], "scene_hash": a["scene_hash"],
            "written_unix": float(a.get("written_unix", math.nan)), "reason": a.get("reason"),
            "elapsed_s": float(a["elapsed_s"]), "resumes": int(a["resumes"]),
            "ranks": int(a.get("ranks", 1)), "jobs": jobs}


class Checkpointer:
    """The checkpoints of one run (master only): inactive until use() names a file.

    restored: name -> saved job state the run has not reached yet in this session;
    resumes: sessions before this one; written / reason: checkpoints written by
    this session and why the last one was."""

    def __init__(self):
        self.path: str | None = None
        self.scene_hash, self.scene_text, self.inputs = "", "", {}
        self.every_s = math.inf
        self.next_at = math.inf          # time.monotonic() of the next timer checkpoint
        self.restored: dict = {}
        self.restored_order: list = []
        self.t0 = time.monotonic()
        self.elapsed_before = 0.0
        self.resumes = 0
        self.written = 0
        self.reason: str | None = None
        #: SETTINGS in which the scene differs from the checkpoint's (a resume under new ones)
        self.changed_settings: list[str] = []

    @property
    def active(self) -> bool:
        return self.path is not None

    def use(self, path: str, scene_hash: str, scene_text: str, every_s: float,
            resume: bool, inputs: dict[str, str] | None = None, changed_settings=None) -> bool:
        """Write checkpoints to `path`; with resume, continue from it if it exists. The
        checkpoint's identity is the scene's hash and `inputs` (Scene.input_digests: the
        bytes of the files the scene names): a damaged file, another scene or a changed input
        file is a CheckpointError, and the file is left untouched. changed_settings(saved
        text, this text) -> the run settings in which they differ, or None when they are
        another scene (None: any other hash is another scene). Returns True when a
        checkpoint was loaded."""
        inputs = dict(inputs or {})
        self.path, self.scene_hash, self.scene_text = path, scene_hash, scene_text
        self.every_s, self.inputs = float(every_s), inputs
        self.next_at = time.monotonic() + float(every_s)
        if not (resume and os.path.exists(path)):
            return False
        ck = read_checkpoint(path)
        a = ck["attrs"]
        changed = [] if a["scene_hash"] == scene_hash else (
            changed_settings(ck["scene_text"], scene_text) if changed_settings is not None else None)
        if changed is None:
            raise CheckpointError(f"{path}: the checkpoint belongs to another scene (scene hash "
                                  f"{a['scene_hash'][:12]}..., this scene {scene_hash[:12]}...); "
                                  f"use the scene it was started with, or remove it to start afresh")
        self.changed_settings = changed
        try:
            saved = json.loads(a["inputs"])
            changed = sorted(k for k in saved.keys() | inputs.keys() if saved.get(k) != inputs.get(k))
        except (TypeError, ValueError, AttributeError):
            raise CheckpointError(f"{path}: unreadable checkpoint (bad attribute 'inputs')") from None
        if changed:
            raise CheckpointError(f"{path}: {changed[0]} changed since the checkpoint was written (SHA-256 "
                                  f"{(saved.get(changed[0]) or 'none')[:12]}... then, "
                                  f"{(inputs.get(changed[0]) or 'none')[:12]}... now); put the file back "
                                  f"as it was, or remove the checkpoint to start afresh")
        if a["version"] != __version__:
            raise CheckpointError(f"{path}: written by hpcwedge {a['version']}, this is {__version__}; "
                                  f"finish the run with that version, or remove it to start afresh")
        self.restored = ck["jobs"]
        self.restored_order = list(ck["order"])
        self.elapsed_before = float(a["elapsed_s"])
        self.resumes = int(a["resumes"]) + 1
        return True

    def elapsed(self) -> float:
        """Seconds of this run, every session."""
        return self.elapsed_before + time.monotonic() - self.t0

    def due(self) -> bool:
        """The timer asks for a checkpoint."""
        return time.monotonic() >= self.next_at

    def write(self, jobs: list[tuple[str, dict]], ranks: int, reason: str) -> bool:
        """Write the run's job states (finished and current, in the order they ran; the
        restored jobs not reached yet are kept after them); True if written. A write
        that fails (OSError: full disk, read-only folder...) keeps the previous
        checkpoint, says so in one line on stderr and returns False: the run goes on
        and the next timer or signal tries again."""
        if self.path is None:
            return False
        names = {n for n, _ in jobs}
        jobs = list(jobs) + [(name, self.restored[name]) for name in self.restored_order
                             if name not in names and name in self.restored]
        header = {"scene_hash": self.scene_hash, "inputs": json.dumps(self.inputs), "elapsed_s": self.elapsed(),
                  "resumes": self.resumes, "ranks": ranks, "reason": reason}
        try:
            write_checkpoint(self.path, header, self.scene_text, jobs)
        except (OSError, CheckpointError) as e:   # full disk, read-only folder...: the run goes on
            kept = "the previous one is kept" if os.path.isfile(self.path) else "there is no earlier one"
            print(f"hpcwedge: warning: checkpoint not written to {self.path} ({error_reason(e)}); {kept}, "
                  "the next timer or signal tries again", file=sys.stderr)
            self.next_at = time.monotonic() + self.every_s
            return False
        self.written += 1
        self.reason = reason
        self.next_at = time.monotonic() + self.every_s
        return True

    def remove(self) -> None:
        """The result is written: the checkpoint (and a stale temp) are no longer needed. One
        that cannot be removed is said in one line (harmless: a later --resume from it ends
        with the same result)."""
        if self.path is None:
            return
        for p in (self.path, self.path + ".tmp"):
            try:
                os.unlink(p)
            except FileNotFoundError:
                pass
            except OSError as e:
                print(f"hpcwedge: warning: cannot remove {p} ({error_reason(e)})", file=sys.stderr)


def _plain(v):
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.generic):
        return v.item()
    return v
