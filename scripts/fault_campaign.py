#!/usr/bin/env python3
"""Fault campaign: a catalogue of bad inputs and faults, run through the real command line.

Every case states what a user must get and records what happened:

    error   exit 2, exactly one line on stderr, starting "hpcwedge: error:" and naming the key
            or file at fault, no traceback, no result file (and no input touched)
    ok      exit 0 (and, where given, mu^c within 1e-9 of the reference value)
    stop    exit 75 with a checkpoint left, then --resume exits 0 with the answers of an
            uninterrupted run (counts, cones, patterns, rays and mu^c, bit for bit)
    kept    exit 2 with one line, and the refused checkpoint left in place byte for byte
    quiet   no traceback and at most one line on stderr (`show | head`)

A case that does not finish within --timeout seconds is a hang. Writes OUT.csv (case, category,
expected, observed, verdict, seconds) and OUT.json (the same rows and the environment) and
prints the counts per category. Exit status 1 when any case fails.

    python scripts/fault_campaign.py                    # every case, results/faults.{csv,json}
    python scripts/fault_campaign.py --only output      # the cases whose name contains "output"
    python scripts/fault_campaign.py --list             # the catalogue, one case a line

Uses the hpcwedge importable from this checkout (it puts the repository first on PYTHONPATH);
the mount cases (read-only and full file systems) need root and are skipped without it.
"""
from __future__ import annotations

import argparse
import contextlib
import csv
import json
import math
import os
import random
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from typing import Callable

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MPIRUN = shutil.which("mpirun")
TAN10 = math.tan(math.radians(10.0))


# ---------------------------------------------------------------------------------- running

@dataclass
class Outcome:
    code: int | None                    # None: still running at the time limit (killed)
    stderr: str
    stdout: str
    seconds: float


def _env(extra: dict | None = None) -> dict:
    e = dict(os.environ)
    e["PYTHONPATH"] = ROOT + (os.pathsep + e["PYTHONPATH"] if e.get("PYTHONPATH") else "")
    for k in ("SLURM_NTASKS", "HPCWEDGE_MPI", "HPCWEDGE_DEBUG"):
        e.pop(k, None)
    e.update(extra or {})
    return e


def command(args: list[str], ranks: int | None = None) -> list[str]:
    py = [sys.executable, "-m", "hpcwedge", *args]
    if ranks is None:
        return py
    return [MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks), "-x", "PYTHONPATH", *py]


def cli(args: list[str], timeout: float, ranks: int | None = None) -> Outcome:
    """Run `hpcwedge ARGS` (under mpirun -n ranks) to its end or the time limit."""
    t = time.perf_counter()
    return finish(launch(args, ranks), timeout, t)


def launch(args: list[str], ranks: int | None = None) -> subprocess.Popen:
    """Start `hpcwedge ARGS` in a session of its own (so a hang can be killed whole)."""
    return subprocess.Popen(command(args, ranks), env=_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, errors="replace", start_new_session=True)


def finish(p: subprocess.Popen, timeout: float, t0: float) -> Outcome:
    """Wait for p until `timeout`; past it, kill its whole session (code None: a hang)."""
    try:
        out, err = p.communicate(timeout=timeout)
        code = p.returncode
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(p.pid, signal.SIGKILL)
        out, err = p.communicate()
        code = None
    return Outcome(code, err, out, time.perf_counter() - t0)


def stderr_lines(o: Outcome) -> list[str]:
    return [ln for ln in o.stderr.splitlines() if ln.strip()]


def describe(o: Outcome) -> str:
    if o.code is None:
        return f"hang (killed after {o.seconds:.0f} s)"
    lines = stderr_lines(o)
    tb = " traceback;" if "Traceback" in o.stderr else ""
    first = lines[0][:160] if lines else ""
    return f"exit {o.code};{tb} {len(lines)} stderr line(s): {first}"


def is_one_line_error(o: Outcome, token: str | None) -> str | None:
    """None when o is a proper user error (exit 2, one line naming token), else what is wrong."""
    if o.code is None:
        return "hang"
    if "Traceback" in o.stderr:
        return "traceback"
    if o.code != 2:
        return f"exit {o.code}"
    lines = [ln for ln in stderr_lines(o) if not ln.startswith("[hpcwedge]")]
    if len(lines) != 1 or not lines[0].startswith("hpcwedge: error:"):
        return f"{len(lines)} error lines"
    if token and token.lower() not in lines[0].lower():
        return f"does not name {token!r}"
    return None


# ---------------------------------------------------------------------------------- scenes

def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        if isinstance(v, float) and math.isnan(v):
            return "nan"
        if isinstance(v, float) and math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    raise TypeError(type(v))


def toml_text(d: dict) -> str:
    """A scene dict as TOML: scalars first, then one [table] per dict value, then [[arrays]]."""
    lines = [f"{k} = {toml_value(v)}" for k, v in d.items() if not isinstance(v, (dict, list))
             or (isinstance(v, list) and not (v and all(isinstance(x, dict) for x in v)))]
    for k, v in d.items():
        if isinstance(v, dict):
            lines.append(f"[{k}]")
            lines += [f"{kk} = {toml_value(vv)}" for kk, vv in v.items()]
    for k, v in d.items():
        if isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            for item in v:
                lines.append(f"[[{k}]]")
                lines += [f"{kk} = {toml_value(vv)}" for kk, vv in item.items()]
    return "\n".join(lines) + "\n"


def plug(rows: int = 3, **compute) -> dict:
    return {"name": "plug", "dim": 2, "model": {"kind": "plug2d", "rows": rows},
            "friction": {"mu": [0.65]}, "compute": {"mu_c": "cones", **compute}}


def node2d() -> dict:
    return {"name": "node2d", "dim": 2, "model": {"kind": "stiffness", "K": [[2.0, 0.5], [0.5, 1.0]]},
            "friction": {"mu": [2.5]}}


def truss() -> dict:
    """plug2d rows 3 as a truss, pinned inside (no rigid mode left)."""
    from hpcwedge.models.library import plug2d
    mdl = plug2d(rows=3)
    return {"name": "truss", "dim": 2,
            "model": {"kind": "truss", "nodes": mdl.coords.tolist(), "bars": mdl.cells["line"].tolist(),
                      "EA": 1.0, "supports": [[4, 0], [4, 1], [7, 0]]},
            "contact": {"nodes": mdl.contact_nodes.tolist(), "normals": mdl.normals.tolist()},
            "friction": {"mu": [2.0]}}


def mesh_scene(folder: str) -> dict:
    """The Gmsh cork of scripts/examples (its .msh copied beside the scene)."""
    import tomllib
    src = os.path.join(ROOT, "scripts", "examples")
    shutil.copy(os.path.join(src, "cork2d.msh"), os.path.join(folder, "cork2d.msh"))
    with open(os.path.join(src, "cork2d.toml"), "rb") as f:
        return tomllib.load(f)


def plug3d(ring: int = 4, levels: int = 2) -> dict:
    return {"name": "plug3d", "dim": 3, "model": {"kind": "plug3d", "ring": ring, "levels": levels},
            "friction": {"mu": [0.65]}, "run": {"symmetry": False}}


def with_(d: dict, path: str, value=..., delete: bool = False) -> dict:
    """A copy of scene d with d[path] set to value (path "table.key" or "key"), or deleted."""
    d = json.loads(json.dumps(d, allow_nan=True))
    *tables, key = path.split(".")
    t = d
    for name in tables:
        t = t.setdefault(name, {})
    if delete:
        t.pop(key, None)
    else:
        t[key] = value
    return d


# ---------------------------------------------------------------------------------- the catalogue

@dataclass
class Case:
    name: str
    category: str
    expected: str
    run: Callable[["Context"], tuple[bool, str]]   # -> (as expected, what was observed)


class Context:
    """A fresh folder per case, shared artefacts made once (a result, a checkpoint, references)."""

    def __init__(self, root: str, timeout: float):
        self.root, self.timeout = root, timeout
        self._cache: dict = {}
        self.folder = root

    def new_folder(self, name: str) -> str:
        self.folder = tempfile.mkdtemp(prefix=name[:40].replace("/", "_") + "-", dir=self.root)
        return self.folder

    def write(self, name: str, text: str | bytes) -> str:
        p = os.path.join(self.folder, name)
        with open(p, "wb" if isinstance(text, bytes) else "w") as f:
            f.write(text)
        return p

    def cached(self, key: str, make: Callable[[], object]):
        if key not in self._cache:
            self._cache[key] = make()
        return self._cache[key]


def scene_error(scene: dict | Callable[[Context], dict], token: str | None) -> Callable:
    """A bad scene: exit 2, one line naming token, nothing written."""
    def run(ctx: Context):
        d = scene(ctx) if callable(scene) else scene
        path = ctx.write("s.toml", toml_text(d))
        out = os.path.join(ctx.folder, "r.h5")
        o = cli(["run", path, "-o", out, "-q"], ctx.timeout)
        bad = is_one_line_error(o, token)
        written = [f for f in os.listdir(ctx.folder) if f.startswith("r.h5")]
        if bad is None and written:
            bad = f"left {written}"
        return bad is None, describe(o) + ("" if bad is None else f" [{bad}]")
    return run


def raw_error(content: bytes | None, token: str | None, is_dir: bool = False) -> Callable:
    """A scene file that is not a scene (missing when content is None)."""
    def run(ctx: Context):
        path = os.path.join(ctx.folder, "s.toml")
        if is_dir:
            os.mkdir(path)
        elif content is not None:
            ctx.write("s.toml", content)
        o = cli(["run", path, "-o", os.path.join(ctx.folder, "r.h5"), "-q"], ctx.timeout)
        bad = is_one_line_error(o, token)
        return bad is None, describe(o) + ("" if bad is None else f" [{bad}]")
    return run


def solved_ok(scene: Callable[[Context], dict] | dict, mu_c: float | Callable[[Context], float] | None
              ) -> Callable:
    """A scene that must solve (exit 0) with mu^c within 1e-9 relative of the reference
    (or a clear one-line error, which counts as right only when mu_c is None)."""
    def run(ctx: Context):
        d = scene(ctx) if callable(scene) else scene
        path = ctx.write("s.toml", toml_text(d))
        out = os.path.join(ctx.folder, "r.h5")
        o = cli(["run", path, "-o", out, "-q"], ctx.timeout)
        if o.code != 0 or "Traceback" in o.stderr:
            return False, describe(o)
        got = show_json(out)["mu_c"]
        want = mu_c(ctx) if callable(mu_c) else mu_c
        if want is None:
            return True, f"exit 0, mu_c {got}"
        good = got is not None and math.isclose(got, want, rel_tol=1e-9)
        return good, f"exit 0, mu_c {got!r} (reference {want!r})"
    return run


def show_json(path: str) -> dict:
    o = cli(["show", path, "--json"], 120)
    if o.code != 0:
        raise RuntimeError(f"show {path}: {describe(o)}")
    return json.loads(o.stdout)


def answers(d: dict) -> dict:
    """What must not depend on interruptions: everything but timings and the statistics."""
    return {k: v for k, v in d.items() if k not in ("timings", "stats")}


# shared artefacts ---------------------------------------------------------------------------

def result_file(ctx: Context) -> str:
    """A pristine small 2D result (plug2d rows 3, cones and mu^c)."""
    def make():
        folder = os.path.join(ctx.root, "_result")
        os.makedirs(folder, exist_ok=True)
        path = os.path.join(folder, "s.toml")
        with open(path, "w") as f:
            f.write(toml_text(plug(3)))
        out = os.path.join(folder, "r.h5")
        o = cli(["run", path, "-o", out, "-q"], 120)
        if o.code != 0:
            raise RuntimeError(f"making the reference result: {describe(o)}")
        return out
    return ctx.cached("result", make)


LONG_ROWS = 9        # plug2d rows 9 (m = 18): long enough to be interrupted, short enough to finish


def long_scene(folder: str, every: float = 0.2, raw: str | None = None) -> str:
    """A 2D scene that runs several seconds and checkpoints every `every` s; raw: the name
    of a .npz file holding its condensed K (kind = "stiffness"), else the built-in plug."""
    d = plug(LONG_ROWS, mu_c="global")
    d["run"] = {"checkpoint_every_s": every}
    if raw:
        d["model"] = {"kind": "stiffness", "file": raw}
    path = os.path.join(folder, "long.toml")
    with open(path, "w") as f:
        f.write(toml_text(d))
    return path


def write_raw(folder: str, rows: int, name: str, scale: float = 1.0, taper_deg: float = 10.0) -> str:
    import numpy as np

    from hpcwedge.contact.build import contact_problem
    from hpcwedge.scene.parse import parse_scene
    sc = parse_scene({"name": "p", "dim": 2, "model": {"kind": "plug2d", "rows": rows, "taper_deg": taper_deg},
                      "friction": {"mu": 1.0}})
    prob = contact_problem(sc)
    K = prob.K * scale
    path = os.path.join(folder, name)
    np.savez(path, K=K, null_space=prob.N)
    return path


def reference_answers(ctx: Context, key: str, scene_path: str) -> dict:
    def make():
        out = os.path.join(os.path.dirname(scene_path), f"ref-{key}.h5")
        o = cli(["run", scene_path, "-o", out, "-q"], 600)
        if o.code != 0:
            raise RuntimeError(f"reference run: {describe(o)}")
        return answers(show_json(out))
    return ctx.cached("ref-" + key, make)


def reference_mu_c(ctx: Context, key: str, scene: dict) -> float | None:
    """The mu^c of a reference scene, solved once per campaign."""
    def make():
        folder = os.path.join(ctx.root, "_" + key)
        os.makedirs(folder, exist_ok=True)
        path = os.path.join(folder, "s.toml")
        with open(path, "w") as f:
            f.write(toml_text(scene))
        out = os.path.join(folder, "r.h5")
        o = cli(["run", path, "-o", out, "-q"], 300)
        if o.code != 0:
            raise RuntimeError(f"reference {key}: {describe(o)}")
        return show_json(out)["mu_c"]
    return ctx.cached("mu_c-" + key, make)


def interrupted(ctx: Context, scene_path: str, out: str, sig: int, ranks: int | None = None,
                need_checkpoint: bool = True) -> Outcome:
    """Start a run, wait for its first checkpoint (or 1.5 s), send `sig` to the serial process
    or to every rank of an mpirun job (kill -9: to mpirun), and collect the outcome."""
    t0 = time.perf_counter()
    p = launch(["run", scene_path, "-o", out], ranks)
    ckpt = out + ".ckpt"
    deadline = time.time() + 60
    while time.time() < deadline and p.poll() is None:
        if (os.path.exists(ckpt) if need_checkpoint else time.perf_counter() - t0 > 1.5):
            break
        time.sleep(0.05)
    if p.poll() is None:
        if ranks is None or sig == signal.SIGKILL:
            p.send_signal(sig)
        else:                           # as SLURM at the time limit: every process of the job
            for pid in descendants(p.pid):
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, sig)
    return finish(p, ctx.timeout, t0)


def descendants(pid: int) -> list[int]:
    """The processes below pid (the ranks under an mpirun), from /proc."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            with contextlib.suppress(OSError, IndexError, ValueError):
                with open(f"/proc/{entry}/stat") as f:
                    ppid = int(f.read().rsplit(")", 1)[1].split()[1])
                children.setdefault(ppid, []).append(int(entry))
    out, todo = [], [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.append(c)
            todo.append(c)
    return out


def stopped_checkpoint(ctx: Context) -> str:
    """A real checkpoint of the long scene, left by SIGTERM (pristine copy)."""
    def make():
        folder = os.path.join(ctx.root, "_ckpt")
        os.makedirs(folder, exist_ok=True)
        path = long_scene(folder)
        out = os.path.join(folder, "r.h5")
        o = interrupted(ctx, path, out, signal.SIGTERM)
        if o.code != 75 or not os.path.exists(out + ".ckpt"):
            raise RuntimeError(f"making a checkpoint: {describe(o)}")
        return out + ".ckpt"
    return ctx.cached("ckpt", make)


def read_bytes(path: str) -> bytes:
    with open(path, "rb") as f:
        return f.read()


# cases ----------------------------------------------------------------------------------------

def scene_cases() -> list[Case]:
    cases = []

    def add(name, scene, token):
        cases.append(Case(name, "scene key", f"error naming {token}", scene_error(scene, token)))

    P = plug(3)
    add("name missing", with_(P, "name", delete=True), "name")
    add("name a number", with_(P, "name", 5), "name")
    add("name empty", with_(P, "name", ""), "name")
    add("dim 2.0 (a float)", with_(P, "dim", 2.0), "dim")
    add("dim 4", with_(P, "dim", 4), "dim")
    add("dim true", with_(P, "dim", True), "dim")
    add("dim 3 for plug2d", with_(P, "dim", 3), "dim")
    add("unknown top-level key", with_(P, "frictoin", 1), "frictoin")
    add("top-level run = 5", with_(P, "run", 5), "run")
    add("compute not a table", with_(P, "compute", [1, 2]), "compute")
    add("friction a string", with_(P, "friction", "x"), "friction")
    add("model a number", with_(P, "model", 3), "model")
    add("model.kind missing", with_(P, "model.kind", delete=True), "kind")
    add("model.kind unknown", with_(P, "model.kind", "plug9"), "kind")
    add("plug2d rows 0", with_(P, "model.rows", 0), "rows")
    add("plug2d rows 2.5", with_(P, "model.rows", 2.5), "rows")
    add("plug2d rows a string", with_(P, "model.rows", "4"), "rows")
    add("plug2d rows true", with_(P, "model.rows", True), "rows")
    add("plug2d taper nan", with_(P, "model.taper_deg", float("nan")), "taper_deg")
    add("plug2d taper 90", with_(P, "model.taper_deg", 90.0), "taper_deg")
    add("plug2d taper negative", with_(P, "model.taper_deg", -5.0), "taper_deg")
    add("plug2d typo roes", with_(P, "model.roes", 4), "roes")
    add("plug2d [contact] key", with_(P, "contact.nodes", [0, 1]), "contact")
    add("friction.mu missing", with_(P, "friction.mu", delete=True), "mu")
    add("friction.mu empty", with_(P, "friction.mu", []), "mu")
    add("friction.mu zero", with_(P, "friction.mu", [0.0]), "mu")
    add("friction.mu negative", with_(P, "friction.mu", [-1.0]), "mu")
    add("friction.mu a string", with_(P, "friction.mu", ["0.5"]), "mu")
    add("friction.mu nan", with_(P, "friction.mu", [float("nan")]), "mu")
    add("friction.mu inf", with_(P, "friction.mu", [float("inf")]), "mu")
    add("friction.mu true", with_(P, "friction.mu", [True]), "mu")
    add("friction.mu listed twice", with_(P, "friction.mu", [0.65, 0.3, 0.65]), "mu")
    add("friction unknown key", with_(P, "friction.mu_s", 0.5), "mu_s")
    add("compute.enumerate 'x'", with_(P, "compute.enumerate", "x"), "enumerate")
    add("compute.enumerate 1 (not a bool)", with_(P, "compute.enumerate", 1), "enumerate")
    add("compute.mu_c 'all'", with_(P, "compute.mu_c", "all"), "mu_c")
    add("compute.mu_c_method unknown", with_(P, "compute.mu_c_method", "newton"), "mu_c_method")
    add("compute.mu_c_tol 0", with_(P, "compute.mu_c_tol", 0.0), "mu_c_tol")
    add("compute.mu_c_tol nan", with_(P, "compute.mu_c_tol", float("nan")), "mu_c_tol")
    add("compute.mu_max negative", with_(P, "compute.mu_max", -1.0), "mu_max")
    add("compute.mu_max inf", with_(P, "compute.mu_max", float("inf")), "mu_max")
    add("compute.exact 1", with_(P, "compute.exact", 1), "exact")
    add("compute.exact 'yes'", with_(P, "compute.exact", "yes"), "exact")
    add("compute.exact_fallback_max_m -1", with_(P, "compute.exact_fallback_max_m", -1), "exact_fallback_max_m")
    add("compute.exact_fallback_max_m 2.5", with_(P, "compute.exact_fallback_max_m", 2.5), "exact_fallback_max_m")
    add("compute unknown key", with_(P, "compute.enumrate", True), "enumrate")
    add("run.checkpoint_every_s nan", with_(P, "run.checkpoint_every_s", float("nan")), "checkpoint_every_s")
    add("run.checkpoint_every_s -1", with_(P, "run.checkpoint_every_s", -1.0), "checkpoint_every_s")
    add("run.checkpoint_every_s 0", with_(P, "run.checkpoint_every_s", 0.0), "checkpoint_every_s")
    add("run.checkpoint_every_s a string", with_(P, "run.checkpoint_every_s", "60"), "checkpoint_every_s")
    add("run.task_budget 0", with_(P, "run.task_budget", 0), "task_budget")
    add("run.task_budget 1.5", with_(P, "run.task_budget", 1.5), "task_budget")
    add("run.symmetry 'yes'", with_(P, "run.symmetry", "yes"), "symmetry")
    add("run.face_split -1", with_(P, "run.face_split", -1), "face_split")
    add("run.face_split 9", with_(P, "run.face_split", 9), "face_split")
    add("run.condense unknown", with_(P, "run.condense", "gpu"), "condense")
    add("run unknown key", with_(P, "run.checkpoint_every", 60.0), "checkpoint_every")
    add("run.max_memory_gb negative", with_(P, "run.max_memory_gb", -1.0), "max_memory_gb")
    add("run.max_memory_gb nan", with_(P, "run.max_memory_gb", float("nan")), "max_memory_gb")

    N = node2d()
    add("K not symmetric", with_(N, "model.K", [[2.0, 0.5], [0.4, 1.0]]), "K")
    add("K indefinite", with_(N, "model.K", [[1.0, 2.0], [2.0, 1.0]]), "K")
    add("K with nan", with_(N, "model.K", [[2.0, float("nan")], [float("nan"), 1.0]]), "K")
    add("K 3x3 in 2D", with_(N, "model.K", [[2.0, 0, 0], [0, 2.0, 0], [0, 0, 2.0]]), "K")
    add("K ragged", with_(N, "model.K", [[2.0, 0.5], [0.5]]), "K")
    add("K a string", with_(N, "model.K", "abc"), "K")
    add("K and file both", with_(N, "model.file", "k.npz"), "file")
    add("neither K nor file", with_(N, "model.K", delete=True), "K")
    add("K file missing", with_(with_(N, "model.K", delete=True), "model.file", "nothere.npz"), "nothere.npz")
    add("nearly singular K without null_space", with_(N, "model.K", [[1.0, 0.0], [0.0, 1e-13]]), "null_space")
    add("null_space wrong shape", with_(N, "model.null_space", [[1.0, 0.0, 0.0]]), "null_space")
    add("stiffness unknown model key", with_(N, "model.k", 1.0), "model.k")
    add("stiffness [contact] key", with_(N, "contact.nodes", [0]), "contact")

    def file_scene(content: bytes | None, name="k.npz", is_dir=False):
        def make(ctx: Context):
            p = os.path.join(ctx.folder, name)
            if is_dir:
                os.mkdir(p)
            elif content is not None:
                ctx.write(name, content)
            return with_(with_(N, "model.K", delete=True), "model.file", name)
        return make
    add("K file a directory", file_scene(None, is_dir=True), "k.npz")
    add("K file garbage .npz", file_scene(b"PK\x03\x04 not really a zip"), "k.npz")
    add("K file garbage .npy", file_scene(b"\x93NUMPY garbage", name="k.npy"), "k.npy")
    add("K file unknown extension", file_scene(b"1 2\n3 4\n", name="k.txt"), "k.txt")

    def npy_wrong_shape(ctx: Context):
        import numpy as np
        np.save(os.path.join(ctx.folder, "k.npy"), np.eye(3))
        return with_(with_(N, "model.K", delete=True), "model.file", "k.npy")
    add("K file of the wrong shape", npy_wrong_shape, "k.npy")

    T = truss()
    add("truss typo suports", with_(T, "model.suports", [[4, 0]]), "suports")
    add("truss bars out of range", with_(T, "model.bars", [[0, 99]]), "bars")
    add("truss EA 0", with_(T, "model.EA", 0.0), "EA")
    add("truss EA nan", with_(T, "model.EA", float("nan")), "EA")
    add("truss EA wrong length", with_(T, "model.EA", [1.0, 2.0]), "EA")
    add("truss support dof 5", with_(T, "model.supports", [[4, 5]]), "supports")
    add("truss nodes missing", with_(T, "model.nodes", delete=True), "nodes")
    add("truss nodes ragged", with_(T, "model.nodes", [[0.0, 0.0], [1.0]]), "nodes")
    add("truss contact duplicate node", lambda c: with_(T, "contact.nodes", [0, 0] + T["contact"]["nodes"][2:]),
        "nodes")
    add("truss contact node out of range", lambda c: with_(T, "contact.nodes",
                                                           [99] + T["contact"]["nodes"][1:]), "nodes")
    add("truss zero normal", lambda c: with_(T, "contact.normals", [[0.0, 0.0]] + T["contact"]["normals"][1:]),
        "normals")
    add("truss normals count", lambda c: with_(T, "contact.normals", T["contact"]["normals"][:2]), "normals")
    add("truss contact typo normal", with_(T, "contact.normal", [[1.0, 0.0]]), "normal")

    def mesh_with(path, value=..., delete=False):
        return lambda ctx: with_(mesh_scene(ctx.folder), path, value, delete)
    add("mesh file missing", mesh_with("model.file", "nothere.msh"), "nothere.msh")
    add("mesh file garbage", lambda ctx: (ctx.write("bad.msh", b"$MeshFormat\ngarbage\n"),
                                          with_(mesh_scene(ctx.folder), "model.file", "bad.msh"))[1], "bad.msh")
    add("mesh E 0", mesh_with("model.E", 0.0), "E")
    add("mesh nu 0.5", mesh_with("model.nu", 0.5), "nu")
    add("mesh nu a string", mesh_with("model.nu", "x"), "nu")
    add("mesh unknown contact group", mesh_with("contact.group", "nosuchgroup"), "nosuchgroup")
    add("mesh unknown model key", mesh_with("model.Young", 1.0), "Young")
    add("mesh group and nodes", mesh_with("contact.nodes", [0, 1]), "contact")
    add("obstacle unknown key", lambda ctx: (lambda d: (d["obstacle"][0].update(colour="red"), d)[1])(
        mesh_scene(ctx.folder)), "colour")
    add("obstacle half angle 95", lambda ctx: (lambda d: (d["obstacle"][0].update(half_angle_deg=95.0), d)[1])(
        mesh_scene(ctx.folder)), "half_angle_deg")
    add("obstacle on a built-in", with_(P, "obstacle", [{"type": "plane"}]), "obstacle")
    return cases


def matrix_body(folder: str, K=None, nodes=None) -> dict:
    """kind = "matrix": plug2d rows 3 (a truss) written as body.mtx and nodes.csv in folder
    (K, nodes: other arrays to write instead); the scene table."""
    import numpy as np
    import scipy.io
    import scipy.sparse as sp

    from hpcwedge.models.library import plug2d
    mdl = plug2d(rows=3)
    scipy.io.mmwrite(os.path.join(folder, "body.mtx"), sp.coo_matrix(mdl.K if K is None else K))
    np.savetxt(os.path.join(folder, "nodes.csv"), mdl.coords if nodes is None else nodes, delimiter=",")
    return {"name": "matrix", "dim": 2, "model": {"kind": "matrix", "K": "body.mtx", "nodes": "nodes.csv"},
            "contact": {"nodes": mdl.contact_nodes.tolist(), "normals": mdl.normals.tolist()},
            "friction": {"mu": [0.65]}}


def matrix_cases() -> list[Case]:
    """Bad input of a kind = "matrix" scene: every one a line naming the key, exit 2, nothing written."""
    import numpy as np
    import scipy.sparse as sp

    from hpcwedge.models.library import plug2d
    cases = []
    mdl = plug2d(rows=3)
    K, n = sp.csr_matrix(mdl.K), mdl.K.shape[0]

    def add(name, make, token):
        cases.append(Case(f"matrix {name}", "matrix", f"error naming {token}", scene_error(make, token)))

    def with_matrix(M=None, nodes=None, **changes):
        def make(ctx: Context):
            d = matrix_body(ctx.folder, M, nodes)
            for path, value in changes.items():
                d = with_(d, path.replace("__", "."), value)
            return d
        return make

    def garbage(name, data):
        return lambda ctx: (ctx.write(name, data), with_(matrix_body(ctx.folder), "model.K", name))[1]

    asym, nan = K.tolil(), K.tolil()
    asym[0, 1] += 0.01
    nan[2, 2] = float("nan")
    add("K missing", with_matrix(model__K="nothere.mtx"), "nothere.mtx")
    add("K garbage .mtx", garbage("bad.mtx", b"%%MatrixMarket garbage\n"), "bad.mtx")
    add("K garbage .petsc", garbage("bad.petsc", b"\0" * 64), "bad.petsc")
    add("K a directory", lambda ctx: (os.mkdir(os.path.join(ctx.folder, "d.mtx")),
                                      with_(matrix_body(ctx.folder), "model.K", "d.mtx"))[1], "d.mtx")
    add("K not square", with_matrix(sp.random(n, n + 2, density=0.2, random_state=1)), "model.K")
    add("K of the wrong size", with_matrix(sp.eye(n + 2)), "model.K")
    add("K not symmetric", with_matrix(asym.tocsr()), "model.K")
    add("K NaN", with_matrix(nan.tocsr()), "model.K")
    add("K a mechanism", with_matrix(sp.block_diag([K, sp.csr_matrix((2, 2))]),
                                     np.vstack([mdl.coords, [[0.0, 0.5]]])), "model.K")
    add("nodes missing", with_matrix(model__nodes="nothere.csv"), "nothere.csv")
    add("contact node out of range", with_matrix(contact__nodes=[99] + mdl.contact_nodes.tolist()[1:]),
        "contact.nodes")
    add("normals of the wrong count", with_matrix(contact__normals=mdl.normals.tolist()[1:]), "contact.normals")
    add("unknown model key", with_matrix(model__Kfile="x"), "model.Kfile")
    return cases


def file_cases() -> list[Case]:
    def add(name, content, token, is_dir=False):
        return Case(name, "scene file", f"error naming {token}", raw_error(content, token, is_dir))
    return [
        add("scene missing", None, "s.toml"),
        add("scene a directory", None, "s.toml", is_dir=True),
        add("scene not UTF-8", b"name = \"\xff\xfe\"\n", "s.toml"),
        add("scene in Latin-1", "# plug\nname = \"caf\xe9\"\n".encode("latin-1"), "line 2"),
        add("scene not TOML", b"name = [unclosed\n", "s.toml"),
        add("scene empty", b"", "name"),
        add("scene random bytes", bytes(random.Random(1).randrange(256) for _ in range(300)), "s.toml"),
        Case("scene with a byte-order mark", "scene file", "exit 0, mu^c of the scene without it", _bom_scene),
    ]


def _bom_scene(ctx: Context):
    """A scene saved with a UTF-8 byte-order mark (Windows editors) solves like the same text
    without it."""
    path = ctx.write("s.toml", b"\xef\xbb\xbf" + toml_text(plug(3)).encode())
    out = os.path.join(ctx.folder, "r.h5")
    o = cli(["run", path, "-o", out, "-q"], ctx.timeout)
    if o.code != 0 or "Traceback" in o.stderr:
        return False, describe(o)
    got, want = show_json(out)["mu_c"], math.tan(math.radians(10.0))
    return got is not None and math.isclose(got, want, rel_tol=1e-9), f"exit 0, mu_c {got!r} (tan 10 deg {want!r})"


def output_cases() -> list[Case]:
    """Run/plot/export outputs that are bad: refused before any work, inputs untouched."""
    cases = []

    def run_to(make_out, token, name, expect_same_file=None):
        def run(ctx: Context):
            scene = ctx.write("s.toml", toml_text(plug(3)))
            before = read_bytes(scene)
            out = make_out(ctx, scene)
            o = cli(["run", scene, "-o", out, "-q"], ctx.timeout)
            bad = is_one_line_error(o, token)
            if bad is None and read_bytes(scene) != before:
                bad = "scene file changed"
            if bad is None and expect_same_file and not expect_same_file(out):
                bad = "output target damaged"
            return bad is None, describe(o) + ("" if bad is None else f" [{bad}]")
        cases.append(Case(name, "output", f"error naming {token}, inputs untouched", run))

    run_to(lambda c, s: "", "-o", "run -o empty string")
    run_to(lambda c, s: c.folder, "directory", "run -o a directory")
    run_to(lambda c, s: os.path.join(c.folder, "no", "such", "r.h5"), "no/such", "run -o missing parent")
    run_to(lambda c, s: s, "s.toml", "run -o the scene itself")
    def device(c, s):
        """A character device of our own (like /dev/null: never the real one, which an old
        program would replace); a FIFO where mknod is not permitted."""
        p = os.path.join(c.folder, "null")
        try:
            os.mknod(p, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
        except OSError:
            os.mkfifo(p)
        return p
    run_to(device, "null", "run -o a device node",
           expect_same_file=lambda out: not os.path.isfile(out))

    def hard_link(c, s):
        os.link(s, os.path.join(c.folder, "link.h5"))
        return os.path.join(c.folder, "link.h5")
    run_to(hard_link, "link.h5", "run -o a hard link to the scene")

    def sym_link(c, s):
        os.symlink(s, os.path.join(c.folder, "sym.h5"))
        return os.path.join(c.folder, "sym.h5")
    run_to(sym_link, "sym.h5", "run -o a symlink to the scene")

    def fifo(c, s):
        p = os.path.join(c.folder, "fifo.h5")
        os.mkfifo(p)
        return p
    run_to(fifo, "fifo.h5", "run -o a named pipe")

    def k_file(ctx: Context):
        import numpy as np
        np.savez(os.path.join(ctx.folder, "k.npz"), K=np.array([[2.0, 0.5], [0.5, 1.0]]))
        scene = ctx.write("s.toml", toml_text(with_(with_(node2d(), "model.K", delete=True),
                                                     "model.file", "k.npz")))
        before = read_bytes(os.path.join(ctx.folder, "k.npz"))
        o = cli(["run", scene, "-o", os.path.join(ctx.folder, "k.npz"), "-q"], ctx.timeout)
        bad = is_one_line_error(o, "k.npz")
        if bad is None and read_bytes(os.path.join(ctx.folder, "k.npz")) != before:
            bad = "K file changed"
        return bad is None, describe(o) + ("" if bad is None else f" [{bad}]")
    cases.append(Case("run -o the scene's K file", "output", "error naming k.npz, K file untouched", k_file))

    def plot_like(argv_of, token, name):
        def run(ctx: Context):
            res = os.path.join(ctx.folder, "r.h5")
            shutil.copy(result_file(ctx), res)
            before = read_bytes(res)
            o = cli(argv_of(ctx, res), ctx.timeout)
            bad = is_one_line_error(o, token)
            if bad is None and read_bytes(res) != before:
                bad = "result file changed"
            return bad is None, describe(o) + ("" if bad is None else f" [{bad}]")
        cases.append(Case(name, "output", f"error naming {token}, result untouched", run))

    plot_like(lambda c, r: ["plot", r, "-o", r], "r.h5", "plot -o the result itself")
    plot_like(lambda c, r: ["export", r, "--ray", "0", "-o", r], "r.h5", "export -o the result itself")
    plot_like(lambda c, r: ["plot", r, "-o", c.folder], "directory", "plot -o a directory")
    plot_like(lambda c, r: ["plot", r, "-o", os.path.join(c.folder, "f.jpg")], "f.jpg",
              "plot -o a suffix of no figure format")
    plot_like(lambda c, r: ["export", r, "--ray", "0", "-o", os.path.join(c.folder, "c.vtk")], "c.vtk",
              "export -o a name not ending in .vtu")
    plot_like(lambda c, r: ["plot", r, "-o", os.path.join(c.folder, "no", "f.png")], "no/f.png",
              "plot -o missing parent")
    plot_like(lambda c, r: ["export", r, "--ray", "0", "-o", device(c, r)], "null", "export -o a device node")
    plot_like(lambda c, r: ["export", r, "--ray", "999", "-o", os.path.join(c.folder, "x.vtu")], "999",
              "export --ray out of range")
    plot_like(lambda c, r: ["export", r, "--run", "7", "--ray", "0", "-o", os.path.join(c.folder, "x.vtu")],
              "run", "export --run out of range")
    plot_like(lambda c, r: ["export", r, "--pattern", "0", "-o", os.path.join(c.folder, "x.vtu")], "pattern",
              "export --pattern of a rays result")
    plot_like(lambda c, r: ["plot", r, "--ray", "999", "-o", os.path.join(c.folder, "x.png")], "999",
              "plot --ray out of range")
    plot_like(lambda c, r: ["plot", r, "--run", "5", "-o", os.path.join(c.folder, "x.png")], "run",
              "plot --run out of range")
    return cases


def mounted(kind: str) -> Callable:
    """A run whose -o lies on a read-only or a (nearly) full file system; needs root."""
    def run(ctx: Context):
        if os.geteuid() != 0:
            return True, "skipped (needs root to mount)"
        mnt = os.path.join(ctx.folder, "mnt")
        os.mkdir(mnt)
        opts = "size=64k" if kind == "full" else "size=1m"
        if subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", mnt], capture_output=True).returncode:
            return True, "skipped (mount not permitted here)"
        try:
            if kind == "readonly":
                subprocess.run(["mount", "-o", "remount,ro", mnt], check=True, capture_output=True)
            else:
                with contextlib.suppress(OSError), open(os.path.join(mnt, "filler"), "wb") as f:
                    f.write(b"\0" * (62 * 1024))
            scene = ctx.write("s.toml", toml_text(plug(4)))
            o = cli(["run", scene, "-o", os.path.join(mnt, "r.h5"), "-q"], ctx.timeout)
            bad = is_one_line_error(o, "r.h5")
            return bad is None, describe(o) + ("" if bad is None else f" [{bad}]")
        finally:
            subprocess.run(["umount", "-l", mnt], capture_output=True)
    return run


def result_cases() -> list[Case]:
    cases = []

    def show_of(make, token, name, argv=("show", "{}", "--json")):
        def run(ctx: Context):
            path = make(ctx)
            before = read_bytes(path) if os.path.isfile(path) else None
            o = cli([a.format(path) for a in argv], ctx.timeout)
            bad = is_one_line_error(o, token)
            if bad is None and before is not None and read_bytes(path) != before:
                bad = "file changed"
            return bad is None, describe(o) + ("" if bad is None else f" [{bad}]")
        cases.append(Case(name, "result file", f"error naming {token}", run))

    show_of(lambda c: os.path.join(c.folder, "none.h5"), "none.h5", "show a missing file")
    show_of(lambda c: c.folder, None, "show a directory")
    show_of(lambda c: c.write("x.h5", b"not hdf5 at all\n" * 10), "x.h5", "show a text file")

    def other_h5(c):
        import h5py
        p = os.path.join(c.folder, "o.h5")
        with h5py.File(p, "w") as f:
            f["x"] = [1, 2, 3]
        return p
    show_of(other_h5, "o.h5", "show an HDF5 file that is not a result")
    def ckpt_as(c):
        p = os.path.join(c.folder, "c.h5")
        shutil.copy(stopped_checkpoint(c), p)
        return p
    show_of(ckpt_as, "c.h5", "plot a checkpoint", argv=("plot", "{}", "-o", "{}.png"))

    def show_ckpt(ctx: Context):
        o = cli(["show", ckpt_as(ctx)], ctx.timeout)
        good = (o.code == 0 and not stderr_lines(o)
                and o.stdout.startswith(os.path.join(ctx.folder, "c.h5") + ": checkpoint of an unfinished run"))
        return good, describe(o) + f" [{o.stdout.splitlines()[0] if o.stdout else 'no output'}]"
    cases.append(Case("show a checkpoint", "result file", "exit 0, how far its run got", show_ckpt))

    rng = random.Random(11)
    for k in range(12):
        kind = "truncated" if k % 3 == 2 else "byte flip"
        seed = rng.randrange(1 << 30)
        cmd = [("show", "{}", "--json"), ("show", "{}"), ("plot", "{}", "-o", "{}.png"),
               ("export", "{}", "--ray", "0", "-o", "{}.vtu")][k % 4]

        def make(c, seed=seed, kind=kind):
            p = os.path.join(c.folder, "r.h5")
            shutil.copy(result_file(c), p)
            corrupt(p, kind, random.Random(seed))
            return p
        show_of(make, "r.h5", f"{cmd[0]} of a damaged result ({kind} #{k})", argv=cmd)

    def pipe(ctx: Context):
        res = result_file(ctx)
        t = time.perf_counter()
        cmd = " ".join(command(["show", res, "--json"])) + " | head -c 10 >/dev/null"
        p = subprocess.run(["bash", "-c", "set -o pipefail; " + cmd], env=_env(), capture_output=True,
                           text=True, timeout=ctx.timeout)
        o = Outcome(p.returncode, p.stderr, "", time.perf_counter() - t)
        good = "Traceback" not in o.stderr and len(stderr_lines(o)) == 0 and o.code in (0, 141)
        return good, describe(o)
    cases.append(Case("show --json | head (broken pipe)", "result file", "quiet: no traceback, no message", pipe))
    return cases


def corrupt(path: str, kind: str, rng: random.Random) -> None:
    size = os.path.getsize(path)
    if kind == "truncated":
        with open(path, "r+b") as f:
            f.truncate(rng.randrange(1, size))
        return
    with open(path, "r+b") as f:
        for _ in range(rng.choice((1, 1, 4, 16))):
            off = rng.randrange(size)
            f.seek(off)
            b = f.read(1)[0]
            f.seek(off)
            f.write(bytes([b ^ rng.randrange(1, 256)]))


def checkpoint_cases() -> list[Case]:
    cases = []

    def resume_refused(prepare, token, name):
        """prepare(ctx) -> scene path; its output r.h5 has a checkpoint that must be refused and kept."""
        def run(ctx: Context):
            scene = prepare(ctx)
            out = os.path.join(ctx.folder, "r.h5")
            ckpt = out + ".ckpt"
            before = read_bytes(ckpt) if os.path.isfile(ckpt) else None
            o = cli(["run", scene, "-o", out, "--resume", "-q"], ctx.timeout)
            bad = is_one_line_error(o, token)
            if bad is None and before is not None and (not os.path.isfile(ckpt) or read_bytes(ckpt) != before):
                bad = "checkpoint not kept as it was"
            if bad is None and os.path.exists(out):
                bad = "a result was written"
            return bad is None, describe(o) + ("" if bad is None else f" [{bad}]")
        cases.append(Case(name, "checkpoint", "exit 2, checkpoint kept byte for byte", run))

    def with_ckpt(ctx: Context, scene_path: str | None = None) -> str:
        path = scene_path or long_scene(ctx.folder)
        shutil.copy(stopped_checkpoint(ctx), os.path.join(ctx.folder, "r.h5.ckpt"))
        return path

    rng = random.Random(2026)
    for k in range(20):
        kind = "truncated" if k % 4 == 3 else "byte flip"
        seed = rng.randrange(1 << 30)

        def prep(ctx, seed=seed, kind=kind):
            path = with_ckpt(ctx)
            corrupt(os.path.join(ctx.folder, "r.h5.ckpt"), kind, random.Random(seed))
            return path
        resume_refused(prep, "r.h5.ckpt", f"resume from a damaged checkpoint ({kind} #{k})")

    def other_scene(ctx):
        with_ckpt(ctx)
        d = plug(LONG_ROWS, mu_c="global")
        d["friction"]["mu"] = [0.7]
        d["run"] = {"checkpoint_every_s": 0.2}
        return ctx.write("long.toml", toml_text(d))
    resume_refused(other_scene, "r.h5.ckpt", "resume with the checkpoint of another scene")

    def empty(ctx):
        path = long_scene(ctx.folder)
        ctx.write("r.h5.ckpt", b"")
        return path
    resume_refused(empty, "r.h5.ckpt", "resume from an empty checkpoint")

    def directory(ctx):
        path = long_scene(ctx.folder)
        os.mkdir(os.path.join(ctx.folder, "r.h5.ckpt"))
        return path
    resume_refused(directory, "r.h5.ckpt", "resume where the checkpoint is a directory")

    def data_changed(what: str):
        def run(ctx: Context):
            write_raw(ctx.folder, LONG_ROWS, "k.npz")
            scene = long_scene(ctx.folder, raw="k.npz")
            out = os.path.join(ctx.folder, "r.h5")
            o = interrupted(ctx, scene, out, signal.SIGTERM)
            if o.code != 75:
                return False, "setup: " + describe(o)
            if what == "replaced":
                write_raw(ctx.folder, LONG_ROWS, "k.npz", taper_deg=12.0)
            else:
                write_raw(ctx.folder, LONG_ROWS, "k.npz", scale=2.0)
            before = read_bytes(out + ".ckpt")
            o = cli(["run", scene, "-o", out, "--resume", "-q"], ctx.timeout)
            bad = is_one_line_error(o, "k.npz")
            if bad is None and read_bytes(out + ".ckpt") != before:
                bad = "checkpoint not kept"
            return bad is None, describe(o) + ("" if bad is None else f" [{bad}]")
        return run
    cases.append(Case("resume after the K file was replaced", "checkpoint", "error naming k.npz, kept",
                      data_changed("replaced")))
    cases.append(Case("resume after the K file was rescaled", "checkpoint", "error naming k.npz, kept",
                      data_changed("scaled")))

    def resume_missing(ctx: Context):
        scene = ctx.write("s.toml", toml_text(plug(3)))
        o = cli(["run", scene, "-o", os.path.join(ctx.folder, "r.h5"), "--resume", "-q"], ctx.timeout)
        return o.code == 0 and "Traceback" not in o.stderr, describe(o)
    cases.append(Case("--resume with no checkpoint (starts afresh)", "checkpoint", "exit 0", resume_missing))
    return cases


def signal_cases() -> list[Case]:
    cases = []

    def stop_then_resume(sig, ranks=None, dim=2, kill9=False):
        def run(ctx: Context):
            if ranks and not MPIRUN:
                return True, "skipped (no mpirun)"
            if dim == 2:
                scene = long_scene(ctx.folder)
                ref = reference_answers(ctx, "long2d", long_scene(ctx.new_folder("ref2d")))
            else:
                d = plug3d(ring=8, levels=2)
                d["friction"]["mu"] = [0.65]
                d["compute"] = {"mu_c": "cones"}
                d["run"]["checkpoint_every_s"] = 0.2
                ref_dir = os.path.join(ctx.root, "_ref3d")
                os.makedirs(ref_dir, exist_ok=True)
                with open(os.path.join(ref_dir, "p3.toml"), "w") as f:
                    f.write(toml_text(d))
                ref = reference_answers(ctx, "p3d", os.path.join(ref_dir, "p3.toml"))
                scene = ctx.write("p3.toml", toml_text(d))
            out = os.path.join(ctx.folder, "r.h5")
            o = interrupted(ctx, scene, out, signal.SIGKILL if kill9 else sig, ranks)
            want = None if kill9 else 75
            if kill9:
                if o.code == 0:
                    return True, "run finished before the kill (nothing to test)"
            elif o.code != want or "Traceback" in o.stderr:
                return False, "stop: " + describe(o)
            if not kill9 and o.seconds > 30:
                return False, f"stop took {o.seconds:.1f} s"
            r = cli(["run", scene, "-o", out, "--resume", "-q"], ctx.timeout, ranks)
            if r.code != 0:
                return False, "resume: " + describe(r)
            same = answers(show_json(out)) == ref
            return same, f"stopped {describe(o)}; resumed exit 0; answers {'equal' if same else 'DIFFER'}"
        return run

    cases.append(Case("SIGTERM, serial 2D, then resume", "signal", "75, then the same answers",
                      stop_then_resume(signal.SIGTERM)))
    cases.append(Case("SIGINT, serial 2D, then resume", "signal", "75, then the same answers",
                      stop_then_resume(signal.SIGINT)))
    cases.append(Case("kill -9, serial 2D, then resume", "signal", "resume gives the same answers",
                      stop_then_resume(signal.SIGKILL, kill9=True)))
    cases.append(Case("SIGTERM, serial 3D patterns, then resume", "signal", "75 promptly, then the same answers",
                      stop_then_resume(signal.SIGTERM, dim=3)))
    cases.append(Case("SIGTERM, mpirun -n 3 2D, then resume", "signal", "75, then the same answers",
                      stop_then_resume(signal.SIGTERM, ranks=3)))
    cases.append(Case("SIGTERM, mpirun -n 3 3D, then resume", "signal", "75, then the same answers",
                      stop_then_resume(signal.SIGTERM, ranks=3, dim=3)))

    def prompt_3d(ring: int):
        """SIGTERM inside the 3D pattern tree of a big ring: stop within a few seconds."""
        def run(ctx: Context):
            d = plug3d(ring=ring, levels=2)
            scene = ctx.write("p.toml", toml_text(d))
            out = os.path.join(ctx.folder, "r.h5")
            p = launch(["run", scene, "-o", out, "-q"])
            time.sleep(4.0)
            if p.poll() is not None:
                return False, "finished before the signal (choose a bigger ring)"
            t = time.perf_counter()
            p.send_signal(signal.SIGTERM)
            o = finish(p, ctx.timeout, t)
            good = o.code == 75 and o.seconds < 3.0 and "Traceback" not in o.stderr
            return good, f"{describe(o)}; stopped {o.seconds:.1f} s after SIGTERM"
        return run
    cases.append(Case("SIGTERM in a long 3D task (plug3d ring 14)", "signal", "75 within 3 s", prompt_3d(14)))

    def usr1(ctx: Context):
        scene = long_scene(ctx.folder, every=3600.0)
        out = os.path.join(ctx.folder, "r.h5")
        t0 = time.perf_counter()
        p = launch(["run", scene, "-o", out, "-q"])
        time.sleep(1.5)
        if p.poll() is None:
            p.send_signal(signal.SIGUSR1)
        o = finish(p, ctx.timeout, t0)
        if o.code != 0:
            return False, describe(o)
        reason = show_json(out)["stats"]["parallel"].get("last_checkpoint_reason")
        return reason == "SIGUSR1", f"exit 0; last checkpoint reason {reason!r}"
    cases.append(Case("SIGUSR1 writes a checkpoint and the run goes on", "signal", "exit 0, checkpoint by SIGUSR1",
                      usr1))

    def concurrent(ctx: Context):
        scene = long_scene(ctx.folder)
        out = os.path.join(ctx.folder, "r.h5")
        t0 = time.perf_counter()
        first = launch(["run", scene, "-o", out, "-q"])
        time.sleep(1.5)
        second = cli(["run", scene, "-o", out, "-q"], ctx.timeout)
        o = finish(first, ctx.timeout, t0)
        bad = is_one_line_error(second, "r.h5")
        if bad is None and o.code != 0:
            bad = f"the first run ended {describe(o)}"
        if bad is None:
            ref = reference_answers(ctx, "long2d", long_scene(ctx.new_folder("ref2d")))
            if answers(show_json(out)) != ref:
                bad = "the first run's answers differ"
        return bad is None, f"second: {describe(second)}; first: exit {o.code}" + ("" if bad is None else
                                                                                   f" [{bad}]")
    cases.append(Case("two runs on the same output", "concurrency",
                      "the second refused (exit 2), the first unharmed", concurrent))
    return cases


def mpi_cases() -> list[Case]:
    def mpi_error(scene: dict | None, token: str | None, name: str):
        def run(ctx: Context):
            if not MPIRUN:
                return True, "skipped (no mpirun)"
            path = os.path.join(ctx.folder, "s.toml")
            if scene is not None:
                ctx.write("s.toml", toml_text(scene))
            o = cli(["run", path, "-o", os.path.join(ctx.folder, "r.h5"), "-q"], min(ctx.timeout, 60), ranks=3)
            good = o.code not in (None, 0) and "Traceback" not in o.stderr and \
                sum(ln.startswith("hpcwedge: error:") for ln in stderr_lines(o)) >= 1 and \
                (token is None or token in o.stderr)
            return good, describe(o)
        return Case(name, "mpirun", "ends promptly with the one-line error, no traceback", run)
    return [mpi_error(with_(plug(3), "run", 5), "run", "mpirun -n 3, top-level run = 5"),
            mpi_error(with_(plug(3), "friction.mu", [-1.0]), "mu", "mpirun -n 3, mu negative"),
            mpi_error(None, "s.toml", "mpirun -n 3, scene missing"),
            mpi_error(with_(plug(3), "dim", 2.0), "dim", "mpirun -n 3, dim 2.0"),
            mpi_error(with_(with_(node2d(), "model.K", delete=True), "model.file", "none.npz"), "none.npz",
                      "mpirun -n 3, K file missing")]


def magnitude_cases() -> list[Case]:
    cases = []

    def block(E):
        d = {"name": "block", "dim": 2, "model": {"kind": "block2d", "rows": 3, "E": E},
             "friction": {"mu": [0.65]}, "compute": {"mu_c": "cones"}}
        return d

    for E in (1e308, 1e250, 1e200, 1e-200, 1e-300):
        cases.append(Case(f"block2d E = {E:g}", "magnitude", "exit 0, mu_c of E = 1 to 1e-9",
                          solved_ok(block(E), lambda ctx: reference_mu_c(ctx, "block", block(1.0)))))
    for s in (1e-300, 1e-150, 1e150, 1e300):
        cases.append(Case(f"node2d K x {s:g}", "magnitude", "exit 0, mu_c = 2 to 1e-9",
                          solved_ok(with_(node2d(), "model.K", [[2.0 * s, 0.5 * s], [0.5 * s, 1.0 * s]]), 2.0)))

    def truss_ea(ea):
        d = truss()
        d["model"]["EA"] = ea
        d["compute"] = {"enumerate": False, "mu_c": "global"}
        return d

    for ea in (1e250, 1e-250):
        cases.append(Case(f"truss EA = {ea:g}", "magnitude", "exit 0, mu_c of EA = 1 to 1e-9",
                          solved_ok(truss_ea(ea), lambda ctx: reference_mu_c(ctx, "truss", truss_ea(1.0)))))
    cases.append(Case("plug2d analytic mu_c (control)", "magnitude", "exit 0, mu_c = tan 10 deg",
                      solved_ok(plug(4, enumerate=False, mu_c="global"), TAN10)))
    return cases


def size_cases() -> list[Case]:
    def guard(extra: dict, name: str):
        def run(ctx: Context):
            d = plug(20)
            d["run"] = extra
            path = ctx.write("s.toml", toml_text(d))
            o = cli(["run", path, "-o", os.path.join(ctx.folder, "r.h5"), "-q"], min(ctx.timeout, 180))
            bad = is_one_line_error(o, "max_memory_gb")
            return bad is None, describe(o) + ("" if bad is None else f" [{bad}]")
        return Case(name, "size guard", "refused with an estimate naming run.max_memory_gb", run)
    return [guard({}, "plug2d rows 20 (m = 40) on this machine"),
            guard({"max_memory_gb": 0.5}, "plug2d rows 20 with run.max_memory_gb = 0.5")]


def catalogue() -> list[Case]:
    cases = (scene_cases() + matrix_cases() + file_cases() + output_cases()
             + [Case("run -o on a read-only file system", "output", "error naming r.h5", mounted("readonly")),
                Case("run -o on a full file system", "output", "error naming r.h5", mounted("full"))]
             + result_cases() + checkpoint_cases() + signal_cases() + mpi_cases() + magnitude_cases()
             + size_cases())
    names = [c.name for c in cases]
    assert len(names) == len(set(names)), "case names must be unique"
    return cases


# ---------------------------------------------------------------------------------- main

def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "results", "faults"),
                    help="output stem (writes STEM.csv and STEM.json)")
    ap.add_argument("--only", action="append", default=[], help="run the cases whose name or category "
                    "contains this text (repeatable)")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds before a case counts as a hang")
    ap.add_argument("--list", action="store_true", help="print the catalogue and exit")
    ap.add_argument("--keep", action="store_true", help="keep the scratch folder")
    args = ap.parse_args(argv)
    sys.path.insert(0, ROOT)
    cases = catalogue()
    if args.only:
        cases = [c for c in cases if any(s.lower() in (c.name + " " + c.category).lower() for s in args.only)]
    if args.list:
        for c in cases:
            print(f"{c.category:12s} {c.name:55s} {c.expected}")
        return 0
    scratch = tempfile.mkdtemp(prefix="hpcwedge-faults-")
    ctx = Context(scratch, args.timeout)
    rows = []
    t_all = time.perf_counter()
    try:
        for i, case in enumerate(cases, 1):
            ctx.new_folder(case.name)
            t = time.perf_counter()
            try:
                ok, observed = case.run(ctx)
            except Exception as e:  # noqa: BLE001  (a case that cannot be set up is a failed case)
                ok, observed = False, f"campaign error: {type(e).__name__}: {' '.join(str(e).split())[:200]}"
            dt = time.perf_counter() - t
            verdict = "skip" if observed.startswith("skipped") else ("pass" if ok else "FAIL")
            rows.append({"case": case.name, "category": case.category, "expected": case.expected,
                         "observed": " ".join(observed.split()), "verdict": verdict, "seconds": round(dt, 2)})
            print(f"[{i:3d}/{len(cases)}] {verdict:4s} {case.category:12s} {case.name} ({dt:.1f} s)"
                  + ("" if verdict == "pass" else f": {observed}"), flush=True)
    finally:
        if not args.keep:
            shutil.rmtree(scratch, ignore_errors=True)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out + ".csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]) if rows else ["case"])
        w.writeheader()
        w.writerows(rows)
    summary: dict[str, dict[str, int]] = {}
    for r in rows:
        summary.setdefault(r["category"], {"pass": 0, "FAIL": 0, "skip": 0})[r["verdict"]] += 1
    doc = {"command": "python scripts/fault_campaign.py" + "".join(f" --only {s!r}" for s in args.only),
           "cases": len(rows), "seconds": round(time.perf_counter() - t_all, 1), "by_category": summary,
           "rows": rows}
    with contextlib.suppress(ImportError):
        from hpcwedge.environment import environment
        doc["environment"] = environment()
    with open(args.out + ".json", "w") as f:
        json.dump(doc, f, indent=1)
    total = {v: sum(s[v] for s in summary.values()) for v in ("pass", "FAIL", "skip")}
    print(f"\n{len(rows)} cases in {doc['seconds']:.0f} s: {total['pass']} pass, {total['FAIL']} fail, "
          f"{total['skip']} skipped; wrote {args.out}.csv and .json")
    for cat, s in summary.items():
        print(f"  {cat:12s} {s['pass']:3d} pass {s['FAIL']:3d} fail {s['skip']:3d} skipped")
    return 1 if total["FAIL"] else 0


if __name__ == "__main__":
    sys.exit(main())
