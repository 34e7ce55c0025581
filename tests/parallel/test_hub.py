"""Hubs (hpcwedge/parallel/hub.py), forced small with HPCWEDGE_HUB_WORKERS under the real
mpirun: the layout; a synthetic tree explored through hubs finds what the serial engine
finds, every node once, and a worker's failure reaches the master as one error; a real run
through hubs gives the serial answers bit for bit; a run stopped by SIGTERM inside the tree
job through hubs exits 75 and resumes under 3 ranks without hubs with the serial run's
answers, and a serial stop resumes through hubs."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pytest
from mpi_helpers import MPIRUN, ROOT, answers, command, env, needs_mpirun, run, show_json, wait_for_checkpoint

from hpcwedge.errors import UserError
from hpcwedge.parallel.checkpoint import read_checkpoint
from hpcwedge.parallel.hub import HUB_WORKERS, HUBS_FROM, layout

HUBS = {"HPCWEDGE_HUB_WORKERS": "2"}


# ---------------------------------------------------------------- layout


def test_layout_groups_a_hub_with_its_workers():
    assert layout(7, "2") == [(1, [2, 3]), (4, [5, 6])]
    assert layout(9, "2") == [(1, [2, 3]), (4, [5, 6]), (7, [8])]
    assert layout(8, "2") == [(1, [2, 3]), (4, [5, 6, 7])]        # a hub alone works for the group before
    assert layout(2, "2") is None and layout(65, "0") is None


def test_layout_by_default_only_at_scale():
    assert layout(HUBS_FROM, "") is None
    groups = layout(1024, "")
    assert all(len(ws) == HUB_WORKERS for _, ws in groups[:-1]) and len(groups) == 31
    ranks = sorted([h for h, _ in groups] + [w for _, ws in groups for w in ws])
    assert ranks == list(range(1, 1024))                            # every rank once


@pytest.mark.parametrize("bad", ["-1", "two", "1.5"])
def test_layout_refuses_a_bad_setting_in_one_line(bad):
    with pytest.raises(UserError, match="HPCWEDGE_HUB_WORKERS"):
        layout(9, bad)


# ---------------------------------------------------------------- a synthetic tree

TREE_SCRIPT = """
import collections, json, sys, os
from hpcwedge.parallel import mpi
from hpcwedge.parallel.engine import Engine
from hpcwedge.parallel.jobs import TreeJob
from hpcwedge.parallel.worker import serve

Node = collections.namedtuple("Node", "depth code")
DEPTH = 12

def explore(ctx, payload):
    group, node, budget, witness = payload
    stack, found, n = [node], [], 0
    while stack and n < budget:
        v = stack.pop()
        n += 1
        if ctx["fail"] is not None and v.code == ctx["fail"]:
            raise ValueError("node %d refused" % v.code)
        if v.depth == DEPTH:
            if v.code % 3 == group:
                found.append(v.code)
        else:
            stack += [Node(v.depth + 1, 2 * v.code), Node(v.depth + 1, 2 * v.code + 1)]
    return found, stack, {"nodes": n}, [], [None] * len(stack)

comm = mpi.world()
if comm is not None and comm.rank:
    serve(comm)
    sys.exit()
fail = int(sys.argv[1]) if len(sys.argv) > 1 else None
engine = Engine(comm)
job = TreeJob("tree", explore, {"fail": fail}, [Node(0, 1), Node(0, 1)], 4, {})
try:
    engine.run(job)
    print(json.dumps({"found": [sorted(f) for f in job.found], "nodes": job.counters["nodes"],
                      "use": engine.summary()["utilisation"]}))
except Exception as e:
    print("ERROR", str(e).splitlines()[0])
finally:
    engine.close()
"""


def _tree(ranks: int | None, *args: str, hubs: dict = HUBS) -> subprocess.CompletedProcess:
    py = [sys.executable, "-c", TREE_SCRIPT, *args]
    cmd = py if ranks is None else [MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks), *py]
    return subprocess.run(cmd, env=env(hubs), capture_output=True, text=True, timeout=120)


@pytest.mark.mpi
@needs_mpirun
def test_a_tree_through_hubs_finds_what_one_process_finds():
    serial = _tree(None)
    assert serial.returncode == 0, serial.stderr
    want = json.loads(serial.stdout.splitlines()[-1])
    leaves = range(2 ** 12, 2 ** 13)                 # the codes at depth 12
    assert want["found"] == [[c for c in leaves if c % 3 == g] for g in (0, 1)]
    assert want["nodes"] == 2 * (2 ** 13 - 1)
    for ranks in (7, 9):
        p = _tree(ranks)
        assert p.returncode == 0, p.stderr
        got = json.loads(p.stdout.splitlines()[-1])
        assert got["found"] == want["found"] and got["nodes"] == want["nodes"]   # every node once
        assert got["use"]["tree"]["workers"] == {7: 4, 9: 5}[ranks]           # the hubs' ranks run none


@pytest.mark.mpi
@needs_mpirun
def test_a_workers_failure_under_a_hub_is_one_error():
    p = _tree(7, "1234")
    assert p.returncode == 0, p.stderr
    assert p.stdout.splitlines()[-1].startswith("ERROR worker rank "), p.stdout
    assert "ValueError: node 1234 refused" in p.stdout


# ---------------------------------------------------------------- real runs

#: plug3d 3 x 5 at two mu, the tree only (~16 s serially): a stop lands inside the tree job
TREE_SCENE = """name = "plug3d-3x5"
dim = 3
[model]
kind = "plug3d"
levels = 3
ring = 5
[friction]
mu = [0.65, 1.0]
[compute]
mu_c = "none"
[run]
symmetry = false
checkpoint_every_s = 0.2
task_budget = 8
"""


@pytest.fixture(scope="module")
def tree_scene(tmp_path_factory):
    """(scene, show JSON of its uninterrupted serial run)."""
    tmp = tmp_path_factory.mktemp("hubtree")
    scene = tmp / "tree.toml"
    scene.write_text(TREE_SCENE)
    run(None, "run", str(scene), "-o", str(tmp / "plain.h5"), "-q", timeout=300)
    return str(scene), show_json(str(tmp / "plain.h5"))


def _stop(ranks: int | None, scene: str, out: str, hubs: dict | None) -> None:
    """Run (serially, or through jobs/wedge-mpirun.sh -n ranks), SIGTERM to it once its first
    checkpoint is written (inside the tree job): exit 75 and the stop's checkpoint."""
    if ranks is None:
        cmd, e = command(None, "run", scene, "-o", out, "-q"), env(hubs)
    else:
        cmd = [os.path.join(ROOT, "jobs", "wedge-mpirun.sh"), "-n", str(ranks), scene, out]
        e = {**env(hubs), "HPCWEDGE_PYTHON": sys.executable}
    p = subprocess.Popen(cmd, env=e, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        assert wait_for_checkpoint(out + ".ckpt", 0.0, p, timeout=240), p.communicate()[1]
        p.send_signal(signal.SIGTERM)
        _, err = p.communicate(timeout=120)
        assert p.returncode == 75, err
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    ckpt = read_checkpoint(out + ".ckpt")
    assert ckpt["attrs"]["reason"] == "SIGTERM" and not ckpt["jobs"]["patterns"]["attrs"]["finished"]


@pytest.mark.mpi
@needs_mpirun
def test_stopped_through_hubs_resumed_without_them(tmp_path, tree_scene):
    scene, want = tree_scene
    out = str(tmp_path / "r.h5")
    _stop(9, scene, out, HUBS)
    run(3, "run", scene, "-o", out, "-q", "--resume", timeout=300)
    got = show_json(out)
    assert got["stats"]["parallel"]["resumes"] == 1
    assert len(want["runs"][0]["patterns"]) > 50
    assert answers(got) == answers(want)


@pytest.mark.mpi
@needs_mpirun
def test_stopped_serially_resumed_through_hubs(tmp_path, tree_scene):
    scene, want = tree_scene
    out = str(tmp_path / "r.h5")
    _stop(None, scene, out, None)
    run(7, "run", scene, "-o", out, "-q", "--resume", timeout=300, caller=HUBS)
    got = show_json(out)
    assert got["stats"]["parallel"]["utilisation"]["patterns"]["workers"] == 4
    assert answers(got) == answers(want)


@pytest.mark.mpi
@needs_mpirun
def test_a_run_through_hubs_gives_the_serial_bits(tmp_path):
    """STOP_SCENE's tree through hubs, its mu^c tasks over every rank (hubs too)."""
    from mpi_helpers import STOP_SCENE
    from test_resume_ranks import mu_c_bits
    scene = tmp_path / "s.toml"
    scene.write_text(STOP_SCENE)
    run(None, "run", str(scene), "-o", str(tmp_path / "serial.h5"), "-q", timeout=300)
    run(7, "run", str(scene), "-o", str(tmp_path / "hubs.h5"), "-q", timeout=300, caller=HUBS)
    want, got = show_json(str(tmp_path / "serial.h5")), show_json(str(tmp_path / "hubs.h5"))
    assert answers(got) == answers(want) and mu_c_bits(got) == mu_c_bits(want)
    use = got["stats"]["parallel"]["utilisation"]
    assert use["patterns"]["workers"] == 4 and use["mu_c"]["workers"] == 6
    assert use["patterns"]["hubs"] == 2 and use["mu_c"]["hubs"] == 0
    assert sum(got["stats"]["parallel"]["tasks_per_rank"][h] for h in (1, 4)) > 0     # hubs run mu^c tasks
