"""warptissue.mesh.coarsen_mesh: a coarser TET4 mesh of the same body."""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import InputError, MeshError
from warptissue.mesh import ball_mesh, boundary_faces, check_mesh, coarsen_mesh


@pytest.fixture(scope="module")
def ball():
    return ball_mesh(0.01, pole_size_m=0.001, far_size_m=0.0015)


def test_a_coarser_ball_keeps_its_shape_within_max_tets(ball):
    """The coarse mesh honours max_tets, passes the mesh check, is closed, and keeps the
    ball's volume (4/3 pi R^3) within the chords' loss and its surface near the sphere."""
    assert ball.tet_count > 1500
    coarse = coarsen_mesh(ball, max_tets=600)
    assert 100 < coarse.tet_count <= 600
    assert coarse.nodes_per_tet == 4
    check_mesh(coarse)
    exact = 4.0 / 3.0 * np.pi * 0.01**3
    assert 0.85 * exact < coarse.volumes().sum() < exact
    centre = 0.5 * (ball.points.min(axis=0) + ball.points.max(axis=0))
    radii = np.linalg.norm(coarse.points[coarse.node_set("surface")] - centre, axis=1)
    # quadric collapse places a merged vertex where the planes of its faces meet, so on a
    # sphere decimated to ~60 boundary triangles vertices stand up to about a tenth out
    assert np.all((radii > 0.0085) & (radii < 0.0115))
    assert len(boundary_faces(coarse.tets)) > 0


def test_a_mesh_within_max_tets_comes_back_as_its_corners(ball):
    same = coarsen_mesh(ball, max_tets=ball.tet_count)
    assert same.nodes_per_tet == 4 and same.tet_count == ball.tet_count


def test_bad_or_unreachable_max_tets_are_refused(ball):
    for bad in (0, 3, 2.5, True):
        with pytest.raises(InputError, match="max_tets"):
            coarsen_mesh(ball, max_tets=bad)
    with pytest.raises(MeshError, match="at most 4 tets"):
        coarsen_mesh(ball, max_tets=4)
