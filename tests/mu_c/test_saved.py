"""What `show` says of a checkpoint's mu^c jobs (mu_c/saved.py): the least certified mu^c so far,
on a real run stopped by SIGTERM in its settling tree and on saved job data."""
import signal
import time

import numpy as np
import pytest
from instances import curved_neck, scene_param
from mpi_helpers import launch, run, show_json, wait_for_checkpoint

from hpcwedge.files import checkpoint_path
from hpcwedge.mu_c.critical import mu_critical
from hpcwedge.mu_c.saved import describe_saved
from hpcwedge.scene.parse import Scene
from hpcwedge.parallel.checkpoint import read_checkpoint


def test_show_of_a_checkpoint_in_the_settling_tree_tells_the_brackets_value_as_an_upper_bound(tmp_path):
    """A real run of a curved neck (elasticity sets mu^c, so a settling tree follows the
    bracket) stopped by SIGTERM once its checkpoint holds the settling tree in progress: `show`
    of the checkpoint says "global mu^c so far: at most X" (JSON "mu_c_at_most"), X the
    certified mu^c of the bracket's saved pattern computed here again; the resumed run's
    progress lines tell X as the settling tree starts, and its answer is no more than X."""
    data = curved_neck(4, 6, 0, mu=0.5)
    data.update(compute={"enumerate": False, "mu_c": "global"},
                run={"symmetry": False, "checkpoint_every_s": 0.05})
    scene, out = tmp_path / "neck.toml", str(tmp_path / "r.h5")
    scene.write_text(Scene.from_dict(data).text)
    ckpt = checkpoint_path(out)
    proc = launch(None, "run", str(scene), "-o", out, "-q")
    try:
        settling = False
        while wait_for_checkpoint(ckpt, 0.0, proc) and not settling:
            try:
                jobs = read_checkpoint(ckpt)["jobs"]
            except Exception:       # caught between writes: read again
                jobs = {}
            settling = "global_patterns" in jobs and not jobs["global_patterns"]["attrs"]["finished"]
            time.sleep(0.02)
        assert settling, "the run ended before its settling tree was checkpointed"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=60) == 75, proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    saved = read_checkpoint(ckpt)["jobs"]["global_bracket"]["data"]
    p, m = scene_param(data)
    again = mu_critical(p, m, np.asarray(saved["zero_u"], dtype=bool), np.asarray(saved["zero_r"], dtype=bool),
                        mu_max=100.0)
    assert again.mu_c is not None and again.polished
    at_most = show_json(ckpt)["mu_c_at_most"]
    assert at_most == pytest.approx(again.mu_c, rel=1e-9)
    text = run(None, "show", ckpt).stdout
    assert f"global mu^c so far: at most {at_most:.12g} (the least certified mu^c of a pattern found" in text
    resumed = run(None, "run", str(scene), "-o", out, "--resume").stderr
    assert f"] global mu^c: at most {at_most:.12g} (the certified mu^c of a pattern); a tree" in resumed, resumed
    assert show_json(out)["mu_c"] <= at_most * (1 + 1e-12)


def test_saved_mu_c_jobs_bound_the_global_mu_c_by_their_least_certified_value():
    """describe_saved: the least polished, finite mu^c of a saved "mu_c" job (an unpolished or
    undecided value is no certified bound), the best of a finished "global_bracket" (NaN: no
    pattern found), None without one, None for another kind of job."""
    kind = {"kind": "mu_c"}
    said = describe_saved(kind, {"mu_c": np.array([0.3, 0.2, np.nan, 0.25]),
                                 "polished": np.array([True, False, False, True])})
    assert said == {"mu_c_at_most": 0.25}
    assert describe_saved(kind, {"mu_c": np.array([0.2]), "polished": np.array([False])}) == {"mu_c_at_most": None}
    assert describe_saved(kind, {"done": np.array([], dtype=np.int64)}) == {"mu_c_at_most": None}
    bracket = {"kind": "global_bracket"}
    assert describe_saved(bracket, {"best": np.array([0.4]), "status": np.array([0])}) == {"mu_c_at_most": 0.4}
    assert describe_saved(bracket, {"best": np.array([np.nan])}) == {"mu_c_at_most": None}
    assert describe_saved(bracket, {"done": np.array([], dtype=np.int64)}) == {"mu_c_at_most": None}
    assert describe_saved({"kind": "subtree"}, {}) is None
