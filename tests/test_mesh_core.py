import numpy as np
import pytest

from warptissue.errors import MeshError
from warptissue.mesh import TetMesh, block_mesh, boundary_faces, signed_volumes, to_tet10


def test_tet10_midpoints_and_sets(unit_cube_tet4):
    mesh = to_tet10(unit_cube_tet4)
    assert mesh.element_type == "TET10"
    corners = mesh.points[mesh.tets[:, :4]]
    mids = mesh.points[mesh.tets[:, 4:]]
    expected = 0.5 * (corners[:, [0, 1, 0, 0, 1, 2]] + corners[:, [1, 2, 2, 3, 3, 3]])
    np.testing.assert_allclose(mids, expected)
    assert np.allclose(mesh.points[mesh.node_sets["xmax"], 0], 1.0)
    assert len(mesh.node_sets["xmax"]) == 25  # 5 x 5 nodes on a 2 x 2 quadratic face


def test_tet10_node_count_is_corners_plus_edges(unit_cube_tet4):
    # Euler for a 2x2x2 Kuhn-split cube: 27 nodes; edges counted independently by a set.
    edges = {
        tuple(sorted((int(t[i]), int(t[j]))))
        for t in unit_cube_tet4.tets
        for i, j in ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))
    }
    mesh = to_tet10(unit_cube_tet4)
    assert mesh.node_count == unit_cube_tet4.node_count + len(edges)
    # Neighbouring tets share their mid-edge nodes: no two mid nodes at the same place.
    assert len(np.unique(mesh.points.round(12), axis=0)) == mesh.node_count


def test_signed_volume_of_reference_tet():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    assert signed_volumes(points, np.array([[0, 1, 2, 3]]))[0] == pytest.approx(1 / 6)
    assert signed_volumes(points, np.array([[0, 2, 1, 3]]))[0] == pytest.approx(-1 / 6)


def test_boundary_faces_of_single_tet_point_outward():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    faces = boundary_faces(np.array([[0, 1, 2, 3]]))
    assert len(faces) == 4
    p = points[faces]
    normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    outward = p.mean(axis=1) - points.mean(axis=0)
    assert np.all(np.einsum("ij,ij->i", normals, outward) > 0)


def test_boundary_faces_of_block_cover_its_surface():
    grid = np.linspace(0.0, 1.0, 4)
    mesh = block_mesh(grid, grid, grid)
    faces = boundary_faces(mesh.tets)
    assert len(faces) == 6 * 3 * 3 * 2
    corners = mesh.points[faces]  # (k, 3 corners, 3 coordinates)
    on_a_side = np.isclose(corners, 0.0).all(axis=1) | np.isclose(corners, 1.0).all(axis=1)
    assert np.all(on_a_side.any(axis=1))


def test_bad_connectivity_names_element():
    with pytest.raises(MeshError, match="element 1"):
        TetMesh(points=np.zeros((4, 3)), tets=[[0, 1, 2, 3], [0, 1, 2, 7]])
