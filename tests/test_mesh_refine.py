"""Local refinement of a mesh around probe sites (warptissue.mesh.refine_near_sites, issue 34):
the same body (volume, surface), small triangles within the zone and the file's own far away,
a closed conforming surface, the surface node sets carried, bad input refused."""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.mesh import (
    TetMesh,
    block_mesh,
    boundary_faces,
    check_closed_surface,
    check_mesh,
    edge_lengths,
    refine_near_sites,
)

SITE = (0.004, 0.004, 0.008)


@pytest.fixture(scope="module")
def cube() -> TetMesh:
    """An 8 mm cube of 2 mm cells (one region), indented at the centre of its top face."""
    grid = np.linspace(0.0, 0.008, 5)
    mesh = block_mesh(grid, grid, grid)
    return TetMesh(mesh.points, mesh.tets, node_sets=dict(mesh.node_sets))


@pytest.fixture(scope="module")
def refined(cube) -> TetMesh:
    return refine_near_sites(cube, sites_m=[SITE], zone_radii_m=[0.001], sizes_m=[0.0005])


def _surface_edges(mesh: TetMesh) -> tuple[np.ndarray, np.ndarray]:
    """(midpoints, lengths) of the boundary's edges."""
    faces = boundary_faces(mesh.tets[:, :4])
    edges = np.unique(np.sort(faces[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1), axis=0)
    ends = mesh.points[edges]
    return ends.mean(axis=1), np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)


def test_the_refined_mesh_is_the_same_body_with_small_triangles_at_the_site(cube, refined):
    quality = check_mesh(refined)
    assert quality.total_volume_m3 == pytest.approx(0.008**3, rel=1e-12)
    faces = boundary_faces(refined.tets)
    check_closed_surface(refined.points, faces)  # conforming: no hanging node
    # The surface is the cube's: every boundary node on one of its faces.
    on_face = np.isclose(refined.points[np.unique(faces)], 0.0, atol=1e-12) | np.isclose(
        refined.points[np.unique(faces)], 0.008, atol=1e-12
    )
    assert on_face.any(axis=1).all()
    middle, length = _surface_edges(refined)
    distance = np.linalg.norm(middle - SITE, axis=1)
    assert length[distance < 0.001].max() <= 0.0005 + 1e-12
    assert length[distance < 0.001].size > 20
    assert refined.node_count > cube.node_count


def test_the_size_grows_away_from_the_zone_to_the_mesh_s_own(cube):
    """With a grading of 1 (the size allowed grows by 1 m per m beyond the zone), the cube's
    own 2 mm cells (their 2.8 mm diagonals) are left as they were far from the site."""
    mesh = refine_near_sites(
        cube, sites_m=[SITE], zone_radii_m=[0.001], sizes_m=[0.0005], grading=1.0
    )
    middle, length = _surface_edges(mesh)
    distance = np.linalg.norm(middle - SITE, axis=1)
    assert length[distance > 0.008].max() == pytest.approx(0.002 * np.sqrt(2.0), rel=1e-9)
    assert length[distance < 0.001].max() <= 0.0005 + 1e-12


def test_surface_node_sets_travel_with_the_refined_surface(refined):
    top = refined.node_sets["zmax"]
    np.testing.assert_allclose(refined.points[top, 2], 0.008, atol=1e-12)
    on_top = np.flatnonzero(np.isclose(refined.points[:, 2], 0.008, atol=1e-12))
    np.testing.assert_array_equal(np.sort(top), on_top)  # the new midpoints too
    assert "zmax" in refined.face_sets and "surface" in refined.node_sets


def test_zones_grade_away_from_two_sites(cube):
    corner = (0.008, 0.008, 0.008)
    mesh = refine_near_sites(
        cube, sites_m=[SITE, corner], zone_radii_m=[0.001, 0.0005], sizes_m=[0.0005, 0.00025]
    )
    middle, length = _surface_edges(mesh)
    near_corner = np.linalg.norm(middle - corner, axis=1) < 0.0005
    assert length[near_corner].max() <= 0.00025 + 1e-12
    lengths = edge_lengths(mesh.points, mesh.tets)
    assert lengths.min() > 0.0


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"zone_radii_m": [0.001, 0.001]}, "one zone radius and one size per site"),
        ({"sizes_m": [0.0]}, "must be positive"),
    ],
)
def test_bad_zones_are_refused(cube, options, message):
    arguments = {"sites_m": [SITE], "zone_radii_m": [0.001], "sizes_m": [0.0005], **options}
    with pytest.raises(InputError, match=message):
        refine_near_sites(cube, **arguments)


def test_a_mesh_of_several_regions_is_refused(cube):
    regions = np.arange(cube.tet_count) % 2
    two = TetMesh(cube.points, cube.tets, node_sets=dict(cube.node_sets), tet_regions=regions)
    with pytest.raises(InputError, match="several material regions"):
        refine_near_sites(two, sites_m=[SITE], zone_radii_m=[0.001], sizes_m=[0.0005])
