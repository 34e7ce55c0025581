"""The Gmsh example bodies shipped in scripts/examples/ (scripts/make_examples.py): the
committed meshes have the structure recorded in examples.json, load as scenes, and run to
the recorded counts with global mu^c = tan(taper); with gmsh installed, make_examples.py
rebuilds meshes of the same structure."""
import importlib.util
import json
import math
import os

import pytest

from hpcwedge.contact.build import build_model
from hpcwedge.scene.parse import load_scene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_spec = importlib.util.spec_from_file_location("make_examples", os.path.join(ROOT, "scripts", "make_examples.py"))
mx = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(mx)

with open(os.path.join(mx.EXAMPLES, "examples.json")) as _f:
    RECORD = json.load(_f)
TAPER = {"cork2d": mx.TAPER_2D_DEG, "plug3d": mx.TAPER_3D_DEG}
NAMES = sorted(mx.BUILDERS)


def _structure(summary: dict) -> dict:
    """What must not depend on the gmsh version: dim, m, groups, cell types, contact points."""
    return {k: summary[k] for k in ("dim", "m", "groups", "contact_coords")} | {"cell_types": sorted(summary["cells"])}


def test_record_covers_the_examples():
    assert sorted(RECORD) == NAMES
    assert RECORD["cork2d"]["m"] == 2 * mx.SIDE_NODES_2D
    assert RECORD["plug3d"]["m"] == len(mx.RINGS_3D) * mx.RING_NODES_3D


@pytest.mark.parametrize("name", NAMES)
def test_committed_mesh_and_scene(name):
    """The committed .msh reads as recorded, is small, and its scene builds a free body
    (3 / 6 rigid modes) with the recorded contact nodes, all on the obstacle."""
    dim = mx.BUILDERS[name][0]
    path = os.path.join(mx.EXAMPLES, name + ".msh")
    assert os.path.getsize(path) < 1 << 20
    summary = mx.mesh_summary(path, dim)
    assert summary == {k: v for k, v in RECORD[name].items() if k != "result"}
    with open(os.path.join(mx.EXAMPLES, name + ".toml")) as f:
        assert f.read() == mx.SCENES[name]
    model = build_model(load_scene(os.path.join(mx.EXAMPLES, name + ".toml")))
    assert model.m == summary["m"]
    assert model.rigid_modes.shape[1] == (3 if dim == 2 else 6)


@pytest.mark.parametrize("name", NAMES)
def test_examples_run_to_the_recorded_counts(name):
    rec = RECORD[name]["result"]
    got = mx.run_counts(os.path.join(mx.EXAMPLES, name + ".toml"))
    assert got["m"] == rec["m"] and got["runs"] == rec["runs"]
    assert math.isclose(got["mu_c"], rec["mu_c"], rel_tol=1e-9)
    assert math.isclose(got["mu_c"], math.tan(math.radians(TAPER[name])), rel_tol=1e-9)


def test_make_examples_rebuilds_the_same_structure(tmp_path):
    pytest.importorskip("gmsh")
    mx.build(str(tmp_path))
    for name in NAMES:
        dim = mx.BUILDERS[name][0]
        new = mx.mesh_summary(str(tmp_path / (name + ".msh")), dim)
        old = mx.mesh_summary(os.path.join(mx.EXAMPLES, name + ".msh"), dim)
        assert _structure(new) == _structure(old), name
        assert (tmp_path / (name + ".toml")).read_text() == mx.SCENES[name]
