"""The benchmarks' harness: every case under a time limit, one record (a dict) per case,
the records written to results/ with the environment, and same-answer checks.

    from harness import Checks, run_call, run_command, write_records

run_call(fn, ..., limit=s)       fn in a forked child: its value, wall and CPU seconds, or
                                 OVERRUN (the child killed at the limit) or "error"
run_command(cmd, limit=s)        a command (`hpcwedge run`, `mpirun -n K ...`) likewise
write_records(base, records)     base.json ({"records", **extra, "environment"}) and base.csv
answer(result)                   a Result's answers: counts per mu, pattern-set hash, mu^c
Checks                           same-answer comparisons: counts and hashes equal, mu^c to a
                                 tolerance; failures printed and counted (exit status 1)

A case that overruns is recorded as such and the script goes on: nothing hangs.
"""
from __future__ import annotations

import contextlib
import csv
import hashlib
import json
import math
import multiprocessing
import os
import shutil
import signal
import subprocess
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(ROOT, "results")
#: a case's status; an overrun is "timeout", the word results/*.json and docs_pages already use
OK, OVERRUN, ERROR = "ok", "timeout", "error"


def _child(conn, fn, args, kwargs) -> None:
    """The forked side of run_call: fn's value and its clocks back through the pipe."""
    os.setpgrp()                        # its own process group: an overrun kills what it started too
    t, c = time.perf_counter(), time.process_time()
    try:
        value = fn(*args, **kwargs)
        out = {"status": OK, "value": value}
    except BaseException as e:          # noqa: BLE001  (reported to the parent, never raised there)
        out = {"status": ERROR, "error": f"{type(e).__name__}: {e}", "traceback": traceback.format_exc()}
    out.update(seconds=time.perf_counter() - t, cpu_seconds=time.process_time() - c)
    conn.send(out)
    conn.close()


def run_call(fn: Callable, *args, limit: float | None = None, **kwargs) -> dict:
    """fn(*args, **kwargs) in a forked child process, bounded by `limit` seconds (None: no
    bound). Returns {"status": "ok", "value": fn's value (picklable), "seconds": wall,
    "cpu_seconds": the child's CPU}, {"status": "error", "error": "Type: message", ...} or
    {"status": OVERRUN, "seconds": limit} (the child's process group killed). The parent's state
    is untouched."""
    ctx = multiprocessing.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(child, fn, args, kwargs), daemon=True)
    t = time.perf_counter()
    proc.start()
    child.close()
    try:
        ready = parent.poll(limit)
        out = parent.recv() if ready else None
    except EOFError:                    # the child died without a word (a signal, os._exit)
        out = {"status": ERROR, "error": "the case's process ended without a result",
               "seconds": time.perf_counter() - t}
    if out is None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        out = {"status": OVERRUN, "seconds": limit}
    proc.join()
    parent.close()
    if out["status"] == ERROR and proc.exitcode not in (0, None):
        out["exitcode"] = proc.exitcode
    return out


def run_command(cmd: Sequence[str], limit: float | None = None, env: Mapping | None = None,
                cwd: str | None = None) -> dict:
    """A command bounded by `limit` seconds: {"status", "seconds" (wall), "returncode",
    "stdout", "stderr"}; OVERRUN when killed at the limit (its whole process group: mpirun's
    ranks, a worker's children), "error" on a non-zero exit. The command gets PYTHONPATH with
    the repository first, so it runs this checkout."""
    env = dict(os.environ if env is None else env)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    t = time.perf_counter()
    proc = subprocess.Popen(list(cmd), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            cwd=cwd, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=limit)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        return {"status": OVERRUN, "seconds": limit, "returncode": None, "stdout": out, "stderr": err}
    return {"status": OK if proc.returncode == 0 else ERROR, "seconds": time.perf_counter() - t,
            "returncode": proc.returncode, "stdout": out, "stderr": err}


def python_command(*args: str) -> list[str]:
    """This interpreter running `args` (e.g. "-m", "hpcwedge", "run", path)."""
    return [sys.executable, *args]


def mpirun_command(ranks: int, *args: str, env: Mapping | None = None) -> list[str]:
    """python_command(*args) under `mpirun -n ranks` (oversubscribed; PYTHONPATH and the BLAS
    thread variables set in `env` (default os.environ) passed on to every rank)."""
    env = os.environ if env is None else env
    root = ["--allow-run-as-root"] if os.geteuid() == 0 else []
    passed = [x for v in ("PYTHONPATH", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
              if v in env or v == "PYTHONPATH" for x in ("-x", v)]
    return [shutil.which("mpirun") or "mpirun", *root, "--oversubscribe", "-n", str(ranks), *passed,
            *python_command(*args)]


# ---------------------------------------------------------------------------- records

def environment() -> dict:
    """The environment record of the product (hpcwedge.environment.environment)."""
    from hpcwedge.environment import environment as record
    return record()


def write_records(base: str, records: list[dict], columns: Sequence[str] | None = None,
                  extra: Mapping | None = None, csv_file: bool = True) -> tuple[str, str | None]:
    """base.json: {"records": records, **extra, "environment": environment()}; base.csv: one row
    per record, `columns` (default: every key of the records in first-seen order, nested
    values as JSON). Directories are made; returns the two paths (csv None when not written)."""
    write_json(base + ".json", {"records": records, **(extra or {})})
    if not csv_file:
        return base + ".json", None
    write_csv(base + ".csv", records, columns)
    return base + ".json", base + ".csv"


def write_json(path: str, payload: Mapping, default: Callable = str) -> str:
    """payload with "environment" (environment()) added, as indented JSON at path (`default`:
    json.dump's, for values JSON has no type for)."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as f:
        json.dump({**payload, "environment": environment()}, f, indent=1, default=default)
    return path


def write_csv(path: str, records: list[dict], columns: Sequence[str] | None = None) -> str:
    """One row per record under `columns` (default: every key, first seen first)."""
    if columns is None:
        columns = list(dict.fromkeys(k for r in records for k in r))
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for r in records:
            w.writerow([_cell(r.get(c)) for c in columns])
    return path


def _cell(v: Any) -> Any:
    return json.dumps(v, default=str) if isinstance(v, (dict, list, tuple)) else ("" if v is None else v)


# ---------------------------------------------------------------------------- same answers

def pattern_hash(sets: Iterable[Iterable[int]]) -> str:
    """A short hash of a set of node sets (patterns' contact nodes, cones' zero sets), independent
    of their order: equal hashes, equal sets."""
    canon = sorted(tuple(sorted(int(i) for i in s)) for s in sets)
    return hashlib.sha256(json.dumps(canon).encode()).hexdigest()[:16]


def answer(result) -> dict:
    """The answers of a hpcwedge Result (or of its show --json dict) to compare across engines:
    per mu the counts, and hashes of the patterns and of the cones' zero sets; the global mu^c."""
    d = result if isinstance(result, Mapping) else result.to_dict()
    runs = []
    for run in d["runs"]:
        rec = {"mu": run["mu"]}
        for key in ("n_wedged_rays", "n_trivial_rays", "n_cones", "n_patterns"):
            if run.get(key) is not None:
                rec[key] = run[key]
        if run.get("patterns") is not None:
            rec["patterns_hash"] = pattern_hash(p["contact"] for p in run["patterns"])
        if run.get("cones") is not None:
            rec["cones_hash"] = pattern_hash(tuple(c["zero_u"]) + tuple(-1 - i for i in c["zero_r"])
                                             for c in run["cones"])
        runs.append(rec)
    return {"runs": runs, "mu_c": d.get("mu_c"), "mu_c_status": d.get("mu_c_status")}


class Checks:
    """Same-answer checks of a benchmark: compare() each pair of answers, failures printed (to
    stderr) and kept; ok is True while none failed; exit_status() 1 after a failure."""

    def __init__(self, rel_tol: float = 1e-9):
        self.rel_tol = rel_tol
        self.failures: list[str] = []

    @property
    def ok(self) -> bool:
        return not self.failures

    def compare(self, what: str, got: Any, want: Any, close: Iterable[str] = ("mu_c",)) -> bool:
        """got and want equal (dicts and lists compared item by item), the keys in `close`
        (mu^c values) to rel_tol; a failure is reported with `what` and the first differences."""
        diffs = _differences(got, want, set(close), self.rel_tol, "")
        if diffs:
            msg = f"different answers: {what}: " + "; ".join(diffs[:5]) + (" ..." if len(diffs) > 5 else "")
            self.failures.append(msg)
            print(msg, file=sys.stderr, flush=True)
        return not diffs

    def exit_status(self) -> int:
        """0 when every check passed, 1 (reported) otherwise."""
        if self.failures:
            print(f"{len(self.failures)} same-answer check(s) failed", file=sys.stderr)
        return 0 if self.ok else 1


def _differences(a: Any, b: Any, close: set, rel_tol: float, where: str) -> list[str]:
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        out = [f"{where}{k}: only in one" for k in sorted(set(a) ^ set(b), key=str)]
        for k in (k for k in a if k in b):
            if k not in close:
                out += _differences(a[k], b[k], close, rel_tol, f"{where}{k}.")
            elif not _close(a[k], b[k], rel_tol):
                out.append(f"{where}{k}: {a[k]!r} != {b[k]!r}")
        return out
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        if len(a) != len(b):
            return [f"{where}len {len(a)} != {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in _differences(x, y, close, rel_tol, f"{where}{i}.")]
    return [] if a == b else [f"{where.rstrip('.')}: {a!r} != {b!r}"]


def _close(a, b, rel_tol: float) -> bool:
    if a is None or b is None:
        return a is b
    return math.isclose(a, b, rel_tol=rel_tol, abs_tol=0.0)
