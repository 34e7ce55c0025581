"""A run stopped and resumed on another rank count ends with the uninterrupted serial run's
answers bit for bit (issue 42, SPEC §5): stopped under 9 ranks and resumed under 3, stopped
serially and resumed under 5. And SIGTERM to jobs/wedge-mpirun.sh (what a user or a batch
system signals) stops the run with a checkpoint and exit status 75 at 3 and 9 ranks (3 to 65:
scripts/bench_sigterm.py, results/bench_sigterm.json) — the script sends SIGTERM to the
ranks; Open MPI 4's mpirun, signalled itself, exits 1 whatever the ranks do
(docs/parallel.md)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
from mpi_helpers import ROOT, STOP_SCENE, answers, launch, needs_mpirun, run, show_json, wait_for_checkpoint

from hpcwedge.parallel.checkpoint import read_checkpoint

pytestmark = [pytest.mark.mpi, needs_mpirun]

MPIRUN_SH = os.path.join(ROOT, "jobs", "wedge-mpirun.sh")


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    """(scene, show JSON of an uninterrupted serial run)."""
    tmp = tmp_path_factory.mktemp("plain")
    scene = tmp / "scene.toml"
    scene.write_text(STOP_SCENE)
    run(None, "run", str(scene), "-o", str(tmp / "plain.h5"), "-q", timeout=300)
    return str(scene), show_json(str(tmp / "plain.h5"))


def mu_c_bits(d: dict) -> list:
    """Every pattern's mu^c of a show --json object, as the bytes of its float64."""
    import struct
    return [struct.pack("<d", p["mu_c"]) if p["mu_c"] is not None else None
            for r in d["runs"] for p in r["patterns"]]


def stop_script(ranks: int, scene: str, out: str) -> tuple[int, str, float]:
    """jobs/wedge-mpirun.sh -n ranks, SIGTERM to it once a checkpoint is written: (its exit
    status, its stderr, seconds from the signal to its exit)."""
    env = {**os.environ, "HPCWEDGE_PYTHON": sys.executable}
    p = subprocess.Popen([MPIRUN_SH, "-n", str(ranks), scene, out], env=env, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, text=True)
    try:
        assert wait_for_checkpoint(out + ".ckpt", 0.0, p, timeout=240), p.communicate()[1]
        t = time.monotonic()
        p.send_signal(signal.SIGTERM)
        _, err = p.communicate(timeout=180)
        return p.returncode, err, time.monotonic() - t
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()


def test_stopped_under_9_ranks_resumed_under_3_same_bits(tmp_path, plain):
    scene, want = plain
    out = str(tmp_path / "r.h5")
    rc, err, _ = stop_script(9, scene, out)
    assert rc == 75, err
    assert read_checkpoint(out + ".ckpt")["attrs"]["reason"] == "SIGTERM"
    run(3, "run", scene, "-o", out, "-q", "--resume", timeout=300)
    got = show_json(out)
    assert got["stats"]["parallel"]["resumes"] == 1 and got["stats"]["parallel"]["ranks"] == 3
    assert answers(got) == answers(want)
    assert mu_c_bits(got) == mu_c_bits(want) and len(mu_c_bits(want)) > 200


def test_stopped_serially_resumed_under_5_same_bits(tmp_path, plain):
    scene, want = plain
    out = str(tmp_path / "r.h5")
    p = launch(None, "run", scene, "-o", out, "-q")
    assert wait_for_checkpoint(out + ".ckpt", 0.0, p, timeout=120), p.communicate()
    p.send_signal(signal.SIGTERM)
    assert p.wait(timeout=120) == 75, p.stderr.read()
    run(5, "run", scene, "-o", out, "-q", "--resume", timeout=300)
    got = show_json(out)
    assert got["stats"]["parallel"]["resumes"] == 1 and got["stats"]["parallel"]["ranks"] == 5
    assert answers(got) == answers(want)
    assert mu_c_bits(got) == mu_c_bits(want)


@pytest.mark.parametrize("ranks", [3, 9])
def test_sigterm_to_the_launcher_exits_75(tmp_path, plain, ranks):
    scene, _ = plain
    out = str(tmp_path / "r.h5")
    rc, err, took = stop_script(ranks, scene, out)
    assert rc == 75, err
    assert "checkpoint written (exit 75)" in err and "Traceback" not in err
    assert read_checkpoint(out + ".ckpt")["attrs"]["reason"] == "SIGTERM"
    print(f"{ranks} ranks: SIGTERM -> exit {took:.1f} s")
