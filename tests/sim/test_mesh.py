"""Tet mesh of the bag: node counts, orientation, tets-only VTK, handle nodes."""
import numpy as np
import pytest

from astrobee_sim.bags import handle_dirs
from astrobee_sim.bags.mesh import bag_mesh


@pytest.mark.parametrize("res", [200, 400, 1000, 1500])
def test_resolution_and_orientation(res):
    m = bag_mesh([0.5, 0.42, 0.25], handle_dirs("front"), res)
    assert 0.8 * res <= len(m.nodes) <= 1.1 * res
    assert np.all(m.volumes() > 0)
    body = 0.5 * 0.42 * 0.25
    assert body < m.volumes().sum() < body * 1.05       # box plus a small handle
    assert len(np.unique(m.tets)) == len(m.nodes)         # no unused node


@pytest.mark.parametrize("variant", ["front", "right", "top", "front_back", "right_left", "top_bottom"])
def test_handles(variant, tmp_path):
    dirs = handle_dirs(variant)
    m = bag_mesh([0.5, 0.42, 0.25], dirs, 300)
    assert len(m.handle_nodes) == len(dirs)
    size = np.array([0.5, 0.42, 0.25])
    for d, nodes in zip(dirs, m.handle_nodes):
        assert len(nodes) >= 4
        ax = int(np.argmax(np.abs(d)))
        assert np.allclose(m.nodes[nodes, ax] * d[ax], size[ax] / 2 + 0.04)
    path = tmp_path / "bag.vtk"
    m.write_vtk(str(path))
    text = path.read_text().split("CELL_TYPES")[1].split()
    assert int(text[0]) == len(m.tets) and set(text[1:]) == {"10"}
