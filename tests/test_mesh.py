import numpy as np
import pytest

from warptissue.errors import MeshError
from warptissue.mesh import TetMesh, block_mesh, graded_coordinates, to_tet10


@pytest.mark.parametrize(("split", "per_cell"), [("five", 5), ("six", 6)])
def test_block_volume_orientation_and_conformity(split, per_cell):
    x = graded_coordinates(0.03, 3, ratio=0.5)
    y = np.linspace(0.0, 0.02, 4)
    z = np.linspace(0.0, 0.01, 3)
    mesh = block_mesh(x, y, z, split=split)
    assert mesh.tet_count == 3 * 3 * 2 * per_cell
    volumes = mesh.volumes()
    assert np.all(volumes > 0)
    assert volumes.sum() == pytest.approx(0.03 * 0.02 * 0.01, rel=1e-12)
    # A conforming mesh's boundary is the box surface alone: its area is the box's.
    faces = np.concatenate(list(mesh.face_sets.values()))
    p = mesh.points[faces]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
    assert area == pytest.approx(2 * (0.03 * 0.02 + 0.03 * 0.01 + 0.02 * 0.01), rel=1e-12)
    assert np.allclose(mesh.points[mesh.node_sets["zmax"], 2], 0.01)


def test_graded_coordinates_ratio():
    x = graded_coordinates(1.0, 4, ratio=0.25)
    sizes = np.diff(x)
    assert x[-1] == pytest.approx(1.0)
    assert sizes[-1] / sizes[0] == pytest.approx(0.25)


def test_tet10_midpoints_and_sets(unit_cube_tet4):
    mesh = to_tet10(unit_cube_tet4)
    assert mesh.element_type == "TET10"
    corners = mesh.points[mesh.tets[:, :4]]
    mids = mesh.points[mesh.tets[:, 4:]]
    expected = 0.5 * (corners[:, [0, 1, 0, 0, 1, 2]] + corners[:, [1, 2, 2, 3, 3, 3]])
    np.testing.assert_allclose(mids, expected)
    assert np.allclose(mesh.points[mesh.node_sets["xmax"], 0], 1.0)
    assert len(mesh.node_sets["xmax"]) == 25  # 5 x 5 nodes on a 2 x 2 quadratic face


def test_bad_connectivity_names_element():
    with pytest.raises(MeshError, match="element 1"):
        TetMesh(points=np.zeros((4, 3)), tets=[[0, 1, 2, 3], [0, 1, 2, 7]])
