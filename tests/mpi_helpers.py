"""Running the real command line (serially and under the real mpirun) for the
parallel and checkpoint tests: launch, find the ranks' pids, kill at chosen
moments, compare results."""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MPIRUN = shutil.which("mpirun")
needs_mpirun = pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")

#: a 2D scene whose sign-pattern trees (m = 8, two mu) have 268 nodes; budget 4
#: so that subtrees really move between ranks and come back as open subtrees
PATTERN_SCENE = """name = "plug8-patterns"
dim = 2
[model]
{model}
[friction]
mu = [0.65, 1.0]
[compute]
enumerate = "patterns"
mu_c = "cones"
[run]
checkpoint_every_s = {every}
task_budget = 4
"""
PLUG_MODEL = 'kind = "plug2d"\nrows = 4'
#: the same plug as a raw condensed K (no PETSc start-up: quicker kill/resume cycles)
RAW_MODEL = 'kind = "stiffness"\nfile = "plug8.npz"'
_RAW: dict = {}

#: plug3d 2 x 6 (m = 12) at two mu without its symmetry (stops at many rank counts:
#: tests/parallel/test_resume_ranks.py, scripts/bench_sigterm.py): a tree of subtree tasks, then
#: 223 mu^c tasks (~10 s serially), checkpoints every 0.2 s so that a stop lands mid-run
STOP_SCENE = """name = "plug3d-2x6"
dim = 3
[model]
kind = "plug3d"
levels = 2
ring = 6
[friction]
mu = [0.65, 1.0]
[compute]
mu_c = "cones"
[run]
symmetry = false
checkpoint_every_s = 0.2
task_budget = 8
"""

#: a 2D rays scene: plug2d (cols 3, taper 10 deg) as a raw condensed K, m = 2 rows
RAYS_SCENE = """name = "plug{m}-rays"
dim = 2
[model]
kind = "stiffness"
file = "plug{m}.npz"
[friction]
mu = {mus}
[compute]
enumerate = true
mu_c = "{mu_c}"
[run]
checkpoint_every_s = {every}
face_split = {split}
"""


def _write_raw_plug(tmp_path, rows: int) -> None:
    """plug{2 rows}.npz in tmp_path: plug2d's condensed K and rigid modes."""
    import numpy as np
    if rows not in _RAW:
        from hpcwedge.contact.build import contact_problem
        from hpcwedge.scene.parse import parse_scene
        sc = parse_scene({"name": "p", "dim": 2, "model": {"kind": "plug2d", "rows": rows},
                          "friction": {"mu": 1.0}})
        prob = contact_problem(sc)
        _RAW[rows] = {"K": prob.K, "null_space": prob.N}
    np.savez(tmp_path / f"plug{2 * rows}.npz", **_RAW[rows])


def write_rays_scene(tmp_path, rows: int, mus=(0.65,), every: float = 60.0, name: str = "rays.toml",
                     mu_c: str = "cones", split: int | str = "auto") -> str:
    """RAYS_SCENE for plug2d with `rows` rows (m = 2 rows) in tmp_path; run.face_split = split."""
    _write_raw_plug(tmp_path, rows)
    p = tmp_path / name
    p.write_text(RAYS_SCENE.format(m=2 * rows, mus=list(mus), every=every, mu_c=mu_c,
                                   split=f'"{split}"' if isinstance(split, str) else split))
    return str(p)


def scene_text(every: float = 0.02, raw: bool = True) -> str:
    return PATTERN_SCENE.format(every=every, model=RAW_MODEL if raw else PLUG_MODEL)


def write_scene(tmp_path, every: float = 0.02, name: str = "scene.toml", text: str | None = None,
                raw: bool = True, rows: int = 4) -> str:
    """The pattern scene in tmp_path (with plug{2 rows}.npz, the condensed K and rigid modes;
    the default scene names plug8.npz)."""
    _write_raw_plug(tmp_path, rows)
    p = tmp_path / name
    p.write_text(text if text is not None else scene_text(every, raw))
    return str(p)


#: BLAS thread settings a caller may have (for `caller=`): 2 threads (more than a bound
#: rank has), 1, or unset (OpenBLAS's default: every core it may run on); the program's
#: answers must not depend on them (SPEC §5, hpcwedge/environment.py)
THREADS_2, THREADS_1, THREADS_UNSET = ({k: v for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
                                       for v in ("2", "1", None))


def env(caller: dict | None = None) -> dict:
    """The tests' environment for the command line; `caller`: variables to set on top
    (a value None unsets the variable)."""
    e = dict(os.environ)
    e["PYTHONPATH"] = ROOT + (os.pathsep + e["PYTHONPATH"] if e.get("PYTHONPATH") else "")
    for k in ("SLURM_NTASKS", "HPCWEDGE_MPI"):
        e.pop(k, None)
    for k, v in (caller or {}).items():
        if v is None:
            e.pop(k, None)
        else:
            e[k] = v
    return e


def command(ranks: int | None, *args: str) -> list[str]:
    """`hpcwedge ...` in-process (ranks None) or under mpirun -n ranks."""
    py = [sys.executable, "-m", "hpcwedge", *args]
    if ranks is None:
        return py
    return [MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks), "-x", "PYTHONPATH", *py]


def run(ranks, *args, timeout=120, check=True, caller: dict | None = None) -> subprocess.CompletedProcess:
    p = subprocess.run(command(ranks, *args), env=env(caller), capture_output=True, text=True, timeout=timeout)
    if check and p.returncode != 0:
        raise AssertionError(f"exit {p.returncode}\nstdout:\n{p.stdout}\nstderr:\n{p.stderr}")
    return p


def launch(ranks, *args) -> subprocess.Popen:
    return subprocess.Popen(command(ranks, *args), env=env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def show_json(path: str, rays: bool = True) -> dict:
    """The object `hpcwedge show PATH --json [--no-rays]` prints (run in-process: the same code)."""
    import contextlib
    import io

    from hpcwedge.cli import main
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["show", path, "--json"] + ([] if rays else ["--no-rays"])) == 0
    return json.loads(buf.getvalue())


def ray_arrays(path: str) -> list:
    """Per run of a result file, its rays, trivial_rays and ray_zero datasets (for
    results with many rays, where the JSON of `show` is slow)."""
    import h5py
    with h5py.File(path, "r") as f:
        return [[f["runs"][k][name][()] for name in ("rays", "trivial_rays", "ray_zero")]
                for k in sorted(f["runs"])]


def answers(d: dict) -> dict:
    """A `show --json` object minus what may differ between splits of the work:
    the timings, stats.parallel (ranks, tasks, resumes; see README) and the
    solver-call counters (a handed-back subtree re-solves its root); the
    number of tree nodes visited stays."""
    d = json.loads(json.dumps(d))
    d.pop("timings")
    d["stats"].pop("parallel")
    d["stats"].pop("socp_statuses", None)
    d["stats"]["bnb"] = {k: v for k, v in d["stats"].get("bnb", {}).items() if k in ("nodes", "partitions")}
    return d


def rays_answers(d: dict) -> tuple[dict, list]:
    """A `show --json` object of a 2D rays scene split into what must be identical
    for every rank count — answers() without stats.dd (the DD's counters and
    seconds depend on the face split) and without the ray vectors — and the ray
    vectors per run ([rays, trivial_rays] as arrays), which a different face split
    reproduces to rounding only (a ray's floats depend on the DD's path to it)."""
    import numpy as np
    d = answers(d)
    d["stats"].pop("dd")
    vectors = []
    for run in d["runs"]:
        vectors.append([np.array(run.pop(k) or [], dtype=float) for k in ("rays", "trivial_rays")])
    return d, vectors


def show(path: str) -> dict:
    return answers(show_json(path))


def parallel_stats(path: str) -> dict:
    return show_json(path)["stats"]["parallel"]


def rank_pids(launcher_pid: int, ranks: int, timeout: float = 30.0,
              proc: subprocess.Popen | None = None) -> dict[int, int]:
    """{rank: pid} of the processes mpirun started (children with OMPI_COMM_WORLD_RANK).
    With `proc` (the launcher), what was found so far once it has ended: a run
    may finish between the caller's last poll and this search."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        ended = proc is not None and proc.poll() is not None
        found = {}
        for d in os.listdir("/proc"):
            if not d.isdigit():
                continue
            try:
                with open(f"/proc/{d}/stat") as f:
                    ppid = int(f.read().rsplit(")", 1)[1].split()[1])
                if ppid != launcher_pid:
                    continue
                with open(f"/proc/{d}/environ", "rb") as f:
                    envs = dict(kv.split(b"=", 1) for kv in f.read().split(b"\0") if b"=" in kv)
            except (OSError, ValueError, IndexError):
                continue
            if b"OMPI_COMM_WORLD_RANK" in envs:
                found[int(envs[b"OMPI_COMM_WORLD_RANK"])] = int(d)
        if len(found) == ranks or ended:
            return found
        time.sleep(0.02)
    raise AssertionError(f"mpirun {launcher_pid}: ranks not found")


def python_child(code: str) -> subprocess.Popen:
    """`python -c code` with the suite's environment, stdin closed, its stdout a text pipe."""
    return subprocess.Popen([sys.executable, "-c", code], env=env(), stdout=subprocess.PIPE, text=True,
                            stdin=subprocess.DEVNULL)


def stopped_by_sigterm(imports: str, call: str) -> str:
    """The code of a process whose SIGTERM handler exits 75 (as the engine's outside a task),
    that prints 'ready' and then runs `call` (after `imports`)."""
    return (f"import signal\n{imports}\n"
            "def stop(signum, frame):\n"
            "    raise SystemExit(75)\n"
            "signal.signal(signal.SIGTERM, stop)\n"
            "print('ready', flush=True)\n"
            f"{call}\n")


def children(pid: int) -> list[int]:
    """The pids of the processes whose parent is pid (from /proc)."""
    out = []
    for d in os.listdir("/proc"):
        try:
            with open(f"/proc/{d}/stat") as f:
                if int(f.read().rsplit(")", 1)[1].split()[1]) == pid:
                    out.append(int(d))
        except (OSError, ValueError, IndexError):
            pass
    return out


def cpu_seconds(pid: int) -> float:
    """utime + stime of a process, from /proc/PID/stat."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def wait_for_checkpoint(ckpt: str, since: float, proc: subprocess.Popen, timeout: float = 60.0) -> bool:
    """Wait until `ckpt` has been (re)written after `since` (the engine is at work);
    False if the process ended first."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc.poll() is not None:
            return False
        try:
            if os.stat(ckpt).st_mtime >= since:
                return True
        except FileNotFoundError:
            pass
        time.sleep(0.01)
    raise AssertionError("no checkpoint written in time")


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def usr1_handled(pid: int) -> bool:
    """SIGUSR1 is ignored or caught by the process (/proc/PID/status masks)."""
    bit = 1 << (signal.SIGUSR1 - 1)
    try:
        with open(f"/proc/{pid}/status") as f:
            masks = {k: int(v, 16) for k, v in (line.split(":") for line in f) if k in ("SigIgn", "SigCgt")}
    except OSError:
        return False
    return bool((masks.get("SigIgn", 0) | masks.get("SigCgt", 0)) & bit)


def all_gone(pids, timeout: float = 10.0) -> bool:
    end = time.monotonic() + timeout
    while any(alive(pid) for pid in pids) and time.monotonic() < end:
        time.sleep(0.05)
    return not any(alive(pid) for pid in pids)


def interrupt_cycles(tmp_path, ranks, n_cycles: int, how, rng, max_delay: float = 0.4,
                     max_runs: int = 60):
    """Run the scene with --resume again and again; in each run, once the engine
    has written a checkpoint, wait a random moment and interrupt it with
    how(proc) (which returns the pids that must be gone afterwards). A run that
    finishes first is simply restarted from scratch: its result is removed (--resume on a
    complete result does nothing), its checkpoint is gone, and the next delay is drawn
    from half the range (the scene's work after its first checkpoint is a fraction of a
    second, less on a fast machine: without the halving the loop could go on forever).
    Returns (interruptions, exit statuses of the interrupted runs)."""
    scene = write_scene(tmp_path)
    out = str(tmp_path / "r.h5")
    ckpt = out + ".ckpt"
    done, codes = 0, []
    for _ in range(max_runs):
        if done == n_cycles:
            break
        since = time.time()
        p = launch(ranks, "run", scene, "-o", out, "-q", "--resume")
        if not wait_for_checkpoint(ckpt, since, p):
            assert p.wait() == 0, p.stderr.read()
            os.remove(out)
            continue
        time.sleep(rng.uniform(0.0, max_delay))
        if p.poll() is not None:
            assert p.returncode == 0, p.stderr.read()
            os.remove(out)
            max_delay /= 2
            continue
        gone = how(p) or []
        code = p.wait(timeout=60)
        err = p.stderr.read()
        p.stdout.close()
        p.stderr.close()
        assert all_gone(gone), "ranks left behind"
        if code == 0 or not os.path.exists(ckpt):
            # it had finished (a signal after the result changes nothing), or it was killed
            # after the result was written and the checkpoint removed, before it exited
            assert os.path.exists(out) and not os.path.exists(ckpt), err
            os.remove(out)
            max_delay /= 2
            continue
        codes.append(code)
        done += 1
    assert done == n_cycles, f"{done} of {n_cycles} interruptions landed in {max_runs} runs"
    return scene, out, done, codes


def damaged(data: bytes, rng, i: int) -> bytes:
    """Damage number i of a file's bytes, drawn from rng: every 4th a truncation at a random
    offset, the others 1 or 16 bytes flipped at random offsets (anywhere in the file)."""
    data = bytearray(data)
    if i % 4 == 3:
        del data[rng.randrange(len(data)):]
    else:
        for k in rng.sample(range(len(data)), rng.choice((1, 16))):
            data[k] ^= rng.randrange(1, 256)
    return bytes(data)


@contextlib.contextmanager
def tmpfs(path, options: str):
    """A real tmpfs mounted at `path` (an empty folder) with mount `options` ("size=4M",
    "ro,size=64k"); mounting needs root, so the test is skipped where it is refused.
    Unmounted afterwards."""
    p = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)], capture_output=True,
                       text=True)
    if p.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs ({options}): {p.stderr.strip() or p.returncode}")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=True)   # -l: even if a test left a file open
