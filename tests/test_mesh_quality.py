import numpy as np
import pytest

from warptissue.errors import MeshError
from warptissue.mesh import TetMesh, block_mesh, indentation_disc, to_tet10
from warptissue.mesh.quality import (
    check_mesh,
    dihedral_angles,
    edge_lengths,
    fix_orientation,
    move_midnodes_keeping_jacobian,
    radius_ratios,
    tet10_jacobian_determinants,
)

REGULAR = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)


def test_regular_tet_is_perfect():
    tets = np.array([[0, 1, 2, 3]])
    assert radius_ratios(REGULAR, tets)[0] == pytest.approx(1.0)
    np.testing.assert_allclose(np.degrees(dihedral_angles(REGULAR, tets)), 70.528779, atol=1e-5)


def test_edge_lengths_of_the_unit_corner_tet():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    # Edges (0,1), (1,2), (0,2), (0,3), (1,3), (2,3): the legs are 1, the others sqrt(2).
    np.testing.assert_allclose(
        edge_lengths(points, np.array([[0, 1, 2, 3]]))[0],
        [1.0, np.sqrt(2.0), 1.0, 1.0, np.sqrt(2.0), np.sqrt(2.0)],
    )


def test_radius_ratio_matches_spheres_solved_directly(rng):
    points = rng.normal(size=(4, 3))
    tets = np.array([[0, 1, 2, 3]])
    # Circumcentre c solves 2 (x_i - x_0) . c = |x_i|^2 - |x_0|^2.
    lhs = 2 * (points[1:] - points[0])
    rhs = (points[1:] ** 2).sum(1) - (points[0] ** 2).sum()
    centre = np.linalg.solve(lhs, rhs)
    circumradius = np.linalg.norm(points[0] - centre)
    volume = abs(np.linalg.det(points[1:] - points[0])) / 6
    faces = [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]
    area = sum(
        0.5 * np.linalg.norm(np.cross(points[b] - points[a], points[c] - points[a]))
        for a, b, c in faces
    )
    inradius = 3 * volume / area
    assert radius_ratios(points, tets)[0] == pytest.approx(3 * inradius / circumradius)


def test_kuhn_cube_dihedral_angles():
    grid = np.linspace(0.0, 1.0, 3)
    quality = check_mesh(block_mesh(grid, grid, grid, split="six"))
    # Each Kuhn tet has dihedral angles of 45, 60 (twice) and 90 (three times) degrees.
    assert quality.min_dihedral_deg == pytest.approx(45.0)
    assert quality.max_dihedral_deg == pytest.approx(90.0)
    assert quality.total_volume_m3 == pytest.approx(1.0)
    assert quality.min_volume_m3 == pytest.approx(1 / 48)
    assert quality.min_edge_m == pytest.approx(0.5)
    assert quality.max_edge_m == pytest.approx(np.sqrt(3) / 2)
    assert quality.tet_count == 48 and quality.node_count == 27
    assert quality.min_scaled_jacobian == 1.0


def test_inverted_element_is_named_and_fixed(unit_cube_tet4):
    tets = unit_cube_tet4.tets.copy()
    tets[[7, 30]] = tets[[7, 30]][:, [0, 2, 1, 3]]
    mesh = TetMesh(points=unit_cube_tet4.points, tets=tets)
    with pytest.raises(MeshError, match="element 7: inverted") as caught:
        check_mesh(mesh)
    assert caught.value.element == 7
    fixed = fix_orientation(mesh)
    assert np.all(fixed.volumes() > 0)
    assert check_mesh(fixed).total_volume_m3 == pytest.approx(1.0)
    assert np.any(mesh.volumes() < 0)  # the input is left alone


def test_fix_orientation_keeps_tet10_midnodes_on_their_edges(unit_cube_tet4):
    mesh = to_tet10(unit_cube_tet4)
    tets = mesh.tets.copy()
    # Invert every other tet by swapping corners 1 and 3 together with their mid-edge nodes
    # ((0,1) <-> (0,3), (1,2) <-> (2,3); (1,3) and (0,2) stay): a different swap from the one
    # fix_orientation applies, so the fix has to re-pair every mid node with its edge.
    tets[::2] = mesh.tets[::2][:, [0, 3, 2, 1, 7, 9, 6, 4, 8, 5]]
    inverted = TetMesh(points=mesh.points, tets=tets)
    assert np.all(inverted.volumes()[::2] < 0)
    fixed = fix_orientation(inverted)
    assert np.all(fixed.volumes() > 0)
    corners = fixed.points[fixed.tets[:, :4]]
    expected = 0.5 * (corners[:, [0, 1, 0, 0, 1, 2]] + corners[:, [1, 2, 2, 3, 3, 3]])
    np.testing.assert_allclose(fixed.points[fixed.tets[:, 4:]], expected)
    check_mesh(fixed)


def test_degenerate_element_is_named():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1e-12]], dtype=float)
    mesh = TetMesh(points=points, tets=[[0, 1, 2, 3], [0, 1, 2, 4]])
    with pytest.raises(MeshError, match="element 1: degenerate") as caught:
        check_mesh(mesh)
    assert caught.value.element == 1


def test_empty_mesh_is_an_error():
    with pytest.raises(MeshError, match="no tetrahedra"):
        check_mesh(TetMesh(points=np.zeros((0, 3)), tets=np.zeros((0, 4))))


def tet10_map(x, xi):
    """Isoparametric TET10 position at reference point xi, from its shape functions."""
    l1, l2, l3 = xi
    bary = [1 - l1 - l2 - l3, l1, l2, l3]
    n = [b * (2 * b - 1) for b in bary]
    n += [4 * bary[i] * bary[j] for i, j in ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))]
    return np.asarray(n) @ x


def test_tet10_jacobian_matches_finite_differences(rng):
    corners = REGULAR + rng.normal(scale=0.05, size=(4, 3))
    mids = 0.5 * (corners[[0, 1, 0, 0, 1, 2]] + corners[[1, 2, 2, 3, 3, 3]])
    x = np.vstack([corners, mids + rng.normal(scale=0.08, size=(6, 3))])
    determinants = tet10_jacobian_determinants(x, np.arange(10)[None])[0]
    samples = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
    samples += [(0.5, 0, 0), (0.5, 0.5, 0), (0, 0.5, 0), (0, 0, 0.5), (0.5, 0, 0.5)]
    samples += [(0, 0.5, 0.5), (0.25, 0.25, 0.25)]
    h = 1e-6
    for xi, determinant in zip(samples, determinants, strict=True):
        jacobian = np.column_stack(
            [
                (tet10_map(x, np.add(xi, h * e)) - tet10_map(x, np.subtract(xi, h * e))) / (2 * h)
                for e in np.eye(3)
            ]
        )
        assert determinant == pytest.approx(np.linalg.det(jacobian), rel=1e-6)


def test_tet10_with_midnode_past_its_corner_is_rejected():
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    mids = 0.5 * (corners[[0, 1, 0, 0, 1, 2]] + corners[[1, 2, 2, 3, 3, 3]])
    mids[0] = [1.2, 0.0, 0.0]  # the (0, 1) mid node beyond corner 1: det J < 0 near corner 1
    mesh = TetMesh(points=np.vstack([corners, mids]), tets=[np.arange(10)])
    with pytest.raises(MeshError, match="element 0: TET10 Jacobian"):
        check_mesh(mesh)


def test_curved_disc_tet10_is_valid_and_close_to_the_cylinder():
    mesh = indentation_disc(
        radius_m=0.01,
        thickness_m=0.005,
        probe_radius_m=0.003,
        element="TET10",
        size_near_m=0.001,
        size_far_m=0.003,
        curved_side=True,
    )
    quality = check_mesh(mesh)
    assert 0.5 < quality.min_scaled_jacobian < 1.0
    assert quality.min_radius_ratio > 0.1


def test_counts_and_overlapping_tets(unit_cube_tet4):
    quality = check_mesh(unit_cube_tet4)
    assert quality.boundary_face_count == 6 * 4 * 2
    assert quality.unused_node_count == 0
    extra = TetMesh(
        points=np.vstack([unit_cube_tet4.points, [[5.0, 5.0, 5.0]]]), tets=unit_cube_tet4.tets
    )
    assert check_mesh(extra).unused_node_count == 1
    # A third tet on an interior face (one shared by two tets already).
    tets = unit_cube_tet4.tets
    faces = np.sort(tets[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]].reshape(-1, 3), axis=1)
    keys, counts = np.unique(faces, axis=0, return_counts=True)
    interior = keys[np.flatnonzero(counts == 2)[0]]
    points = np.vstack([unit_cube_tet4.points, [[0.3, 0.7, 0.4]]])
    crowded = fix_orientation(
        TetMesh(points=points, tets=np.vstack([tets, [[*interior, len(points) - 1]]]))
    )
    with pytest.raises(MeshError, match="shared by 3 tets") as caught:
        check_mesh(crowded)
    assert caught.value.element is not None


def isoparametric_volume(mesh):
    """Volume of curved TET10s: det J integrated with a degree-3 exact rule (det J is cubic).

    Stroud T3:3-1 on the reference tet (volume 1/6): the centroid with weight -4/5 and the
    four points (1/2, 1/6, 1/6, 1/6) (and permutations) with weight 9/20 each.
    """
    points = np.vstack([[[0.25] * 4], np.full((4, 4), 1 / 6) + np.eye(4) / 3])
    weights = np.array([-4 / 5] + [9 / 20] * 4) / 6
    return tet10_jacobian_determinants(mesh.points, mesh.tets, barycentric=points) @ weights


def test_curved_disc_volume_converges_to_the_cylinder():
    radius, thickness = 0.01, 0.005
    options = {
        "radius_m": radius,
        "thickness_m": thickness,
        "probe_radius_m": 0.003,
        "element": "TET10",
        "size_near_m": 0.001,
        "size_far_m": 0.003,
    }
    cylinder = np.pi * radius**2 * thickness / 4
    straight = indentation_disc(**options)
    curved = indentation_disc(**options, curved_side=True)
    # Straight-sided: the quadrature reproduces the corner volumes (an inscribed polygon).
    np.testing.assert_allclose(isoparametric_volume(straight), straight.volumes(), rtol=1e-12)
    polygon_error = cylinder - straight.volumes().sum()
    curved_error = cylinder - isoparametric_volume(curved).sum()
    assert polygon_error > 0
    assert abs(curved_error) < 0.01 * polygon_error  # quadratic arcs: O(h^4) against O(h^2)


def test_a_midnode_that_would_invert_its_element_stops_short():
    """move_midnodes_keeping_jacobian on one tet: a mid node pushed past the opposite face
    would invert the element; it stops where det J / 6V >= 0.1 and a harmless move is whole."""
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 0.05]], dtype=float)
    mesh = to_tet10(TetMesh(points=corners, tets=np.array([[0, 1, 2, 3]], dtype=np.int32)))
    edge01 = mesh.tets[0, 4]  # the mid node of edge (0, 1)
    target = mesh.points[edge01] + [0.0, 0.0, 0.2]  # far past the tet's height of 0.05
    fraction = move_midnodes_keeping_jacobian(mesh, np.array([edge01]), target[None, :])
    assert 0.0 < fraction[0] < 1.0
    assert check_mesh(mesh).min_scaled_jacobian >= 0.1
    straight = to_tet10(TetMesh(points=corners, tets=np.array([[0, 1, 2, 3]], dtype=np.int32)))
    small = straight.points[edge01] + [0.0, 0.0, 0.001]
    assert move_midnodes_keeping_jacobian(straight, np.array([edge01]), small[None, :])[0] == 1
