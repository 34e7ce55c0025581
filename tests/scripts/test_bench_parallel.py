"""scripts/bench_parallel.py's scenes: the curved neck it writes as a scene file (--neck) is
tests/instances.py's body, bit for bit, through the real parser."""
import os
import sys
import tomllib

import numpy as np
from instances import curved_neck

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "scripts"))
import bench_parallel  # noqa: E402

from hpcwedge.contact.build import contact_problem  # noqa: E402
from hpcwedge.scene.parse import parse_scene  # noqa: E402


def test_neck_scene_file_is_the_instance():
    """The TOML of --neck parses to the contact problem of curved_neck's dict (K and N equal to
    the bit: every float written by repr), with the global search alone and no symmetry."""
    data = tomllib.loads(bench_parallel.neck_text(3, 5, 0.5))
    assert data["compute"] == {"enumerate": False, "mu_c": "global"} and data["run"]["symmetry"] is False
    want = contact_problem(parse_scene(curved_neck(3, 5, 0, mu=0.5)))
    got = contact_problem(parse_scene(data))
    assert got.m == want.m == 15
    assert np.array_equal(got.K, want.K) and np.array_equal(got.N, want.N)
