"""VTU export (hpcwedge.post.export): the file read back with meshio against the configuration."""
import meshio
import numpy as np
import pytest
from test_recovery import BLOCK2D, PLUG3D, solve

from hpcwedge.post.export import write_vtu
from hpcwedge.post.recovery import AXIAL_FORCE, VON_MISES, load_configuration


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    d = tmp_path_factory.mktemp("export")
    return {k: solve(d, text, f"{k}.toml", f"{k}.h5") for k, text in (("block2d", BLOCK2D), ("plug3d", PLUG3D))}


def test_vtu_round_trip(results, tmp_path):
    for kind, item, name, block in (("block2d", {"cone": 0}, VON_MISES, "quad"),
                                    ("plug3d", {"pattern": 1}, AXIAL_FORCE, "line")):
        cfg = load_configuration(results[kind], **item)
        path = tmp_path / f"{kind}.vtu"
        write_vtu(cfg, str(path))
        got = meshio.read(str(path))
        mdl = cfg.model
        n, dim = mdl.coords.shape
        assert got.points.shape == (n, 3)
        np.testing.assert_allclose(got.points[:, :dim], mdl.coords)
        assert got.point_data["displacement"].shape == (n, 3) and got.point_data["reaction"].shape == (n, 3)
        np.testing.assert_allclose(got.point_data["displacement"][:, :dim], cfg.displacement)
        assert not got.point_data["displacement"][:, dim:].any()
        assert sorted(np.flatnonzero(np.abs(got.point_data["reaction"]).sum(1))) == sorted(mdl.contact_nodes)
        assert (got.point_data["contact"][mdl.contact_nodes] == np.arange(mdl.m)).all()
        assert [c.type for c in got.cells] == [block] and len(got.cells[0].data) == len(mdl.cells[block])
        np.testing.assert_allclose(got.cell_data[name][0], cfg.element_values[name][block])
        assert list(got.cell_data) == [name]
