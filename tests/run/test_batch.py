"""One batch run's lifecycle in-process (run_batch; the command line, real signals and mpirun
are in tests/test_cli.py and tests/parallel/): the start-up's word to the workers, a stop
that came before the handlers, a complete result left as it is."""
import os
import signal

import pytest

from hpcwedge.parallel.engine import EXIT_INTERRUPTED
from hpcwedge.run import batch
from hpcwedge.run.batch import condense_on_ranks, run_batch
from hpcwedge.scene.parse import parse_scene

PLUG = 'name = "p"\ndim = 2\n[model]\nkind = "plug2d"\nrows = 2\n[friction]\nmu = [0.65]\n'


class Master:
    """rank 0 of a world whose other ranks agree with it: what it broadcasts is recorded."""

    rank, size = 0, 2

    def __init__(self, failed_elsewhere: int = 0):
        self.sent, self.failed_elsewhere = [], failed_elsewhere

    def bcast(self, obj, root=0):
        self.sent.append(obj)
        return obj

    def allreduce(self, n):
        return n + self.failed_elsewhere


@pytest.fixture
def handlers():
    """run_batch leaves its handlers SIG_IGN (as a finished program must): put them back."""
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGUSR1)}
    yield
    for sig, handler in saved.items():
        signal.signal(sig, handler)


def plug(condense: str = "auto"):
    return parse_scene({"name": "p", "dim": 2, "model": {"kind": "plug2d", "rows": 2},
                        "friction": {"mu": [0.65]}, "run": {"condense": condense}})


def test_no_run_or_a_serial_condensation_releases_the_workers():
    for scene in (None, plug("serial"),
                  parse_scene({"name": "k", "dim": 2, "model": {"kind": "stiffness", "K": [[2.0, 0.5], [0.5, 1.0]]},
                               "friction": {"mu": [2.5]}})):
        comm = Master()
        assert condense_on_ranks(scene, comm) is None and comm.sent == [None]


def test_auto_condenses_together_only_from_the_threshold_on(monkeypatch):
    """plug2d is far below DISTRIBUTED_MIN_DOFS: built on every rank, condensed by the master
    alone (None); a model that fails on any rank sends everyone on the same way."""
    scene = plug("auto")
    comm = Master()
    assert condense_on_ranks(scene, comm) is None and comm.sent == [scene]
    monkeypatch.setattr(batch, "DISTRIBUTED_MIN_DOFS", 0)
    monkeypatch.setattr(batch, "contact_problem", lambda *a: pytest.fail("condensed although a rank failed"))
    assert condense_on_ranks(scene, Master(failed_elsewhere=1)) is None


def test_a_stop_before_the_handlers_is_acted_on_once_they_are_in(tmp_path, capsys, handlers, monkeypatch):
    """A stop the caller's start-up handler files into `early_stops` up to the moment the
    run's handlers are in (here: as they go in) stops the run as a later one would."""
    scene = tmp_path / "s.toml"
    scene.write_text(PLUG)
    stops, install = [], batch.Engine.install_signals
    monkeypatch.setattr(batch.Engine, "install_signals", lambda self: (stops.append(signal.SIGTERM), install(self)))
    assert run_batch(str(scene), str(tmp_path / "r.h5"), quiet=True, early_stops=stops) == EXIT_INTERRUPTED
    assert stops == []
    assert capsys.readouterr().err == "[hpcwedge] SIGTERM: stopped before any checkpointable work\n"
    assert sorted(os.listdir(tmp_path)) == ["s.toml"]


def test_a_complete_result_is_left_as_it_is_on_resume(tmp_path, capsys, handlers):
    scene, out = tmp_path / "s.toml", str(tmp_path / "r.h5")
    scene.write_text(PLUG)
    assert run_batch(str(scene), out) == 0
    assert f"wrote {out}" in capsys.readouterr().err
    before = os.stat(out).st_mtime_ns, open(out, "rb").read()
    assert run_batch(str(scene), out, resume=True) == 0
    assert "is already complete for this scene" in capsys.readouterr().err
    assert (os.stat(out).st_mtime_ns, open(out, "rb").read()) == before
    assert sorted(os.listdir(tmp_path)) == ["r.h5", "s.toml"]
