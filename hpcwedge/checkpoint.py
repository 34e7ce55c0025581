"""Checkpoints (SPEC §5): the master's state in one HDF5 file, written atomically.

Path: ``RESULT.h5.ckpt`` beside the result (``checkpoint_path``); it is
written to ``RESULT.h5.ckpt.tmp``, flushed, fsynced, read back and checked,
then renamed onto the old checkpoint (and the folder fsynced), so a crash at
any moment leaves the previous good checkpoint in place. It is removed once
the result file is written. Like a result, it carries the SHA-256 of its bytes
(results.write_atomic), verified before anything is read: a damaged checkpoint
is a CheckpointError, and nothing here deletes or rewrites it.

Layout (every job state is plain arrays and attributes; parallel.py's jobs
fill them, this module never interprets them):

    /                attrs: format = "hpcwedge-checkpoint", format_version,
                     version (program), scene_hash, inputs (JSON: Scene.input_digests,
                     the bytes of the files the scene names), elapsed_s (all sessions),
                     resumes, ranks, reason ("timer" | "SIGUSR1" | "SIGTERM" | ...),
                     written_unix
    /scene_text      the scene file, verbatim
    /jobs            attrs: order (JSON list of job names, in the order they ran)
    /jobs/<name>/    attrs: kind, finished, counters (JSON), job attributes;
                     datasets: the job's arrays (see parallel.SubtreeJob / TaskJob)
"""
from __future__ import annotations

import json
import time

import h5py
import numpy as np

from . import __version__
from .files import FileError, verify_checksum, write_atomic
from .results import compression

FORMAT = "hpcwedge-checkpoint"
#: 2: checksummed (results.write_atomic), with the scene's input digests
FORMAT_VERSION = 2


class CheckpointError(FileError):
    """A checkpoint that cannot be used: one line naming the file and the reason."""


def checkpoint_path(output: str) -> str:
    """Where the checkpoint of the run writing `output` lives."""
    return output + ".ckpt"


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


def _plain(v):
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.generic):
        return v.item()
    return v
