"""Points located in a tet mesh and nodal values interpolated to them (warptissue.mesh
locate_points, interpolation_matrix): the barycentric coordinates rebuild the points, a
quadratic field is exact on TET10 and a linear one on TET4, nodes and faces count as inside,
and a point outside is refused."""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import MeshError
from warptissue.mesh import block_mesh, interpolation_matrix, locate_points, to_tet10


@pytest.fixture
def block():
    grid = np.linspace(0.0, 1e-2, 4)
    return block_mesh(grid, grid, np.linspace(0.0, 5e-3, 3))


def _inside(rng, count: int) -> np.ndarray:
    return rng.uniform([0.0, 0.0, 0.0], [1e-2, 1e-2, 5e-3], size=(count, 3))


def test_the_coordinates_rebuild_the_points(block, rng):
    points = _inside(rng, 300)
    tets, lam = locate_points(block, points)
    corners = block.points[block.tets[tets, :4]]
    np.testing.assert_allclose(np.einsum("nc,ncx->nx", lam, corners), points, atol=1e-15)
    assert lam.min() >= -1e-9
    np.testing.assert_allclose(lam.sum(axis=1), 1.0)


def test_tet10_interpolates_a_quadratic_field_and_tet4_a_linear_one(block, rng):
    points = np.vstack([_inside(rng, 200), block.points])  # nodes of the surface too
    quadratic = to_tet10(block)

    def field(x):
        return np.column_stack([x[:, 0] * x[:, 1], x[:, 2] ** 2 - x[:, 0], 3.0 * x[:, 1]])

    values = interpolation_matrix(quadratic, points) @ field(quadratic.points)
    np.testing.assert_allclose(values, field(points), atol=1e-15)
    linear = interpolation_matrix(block, points) @ (block.points @ np.diag([1.0, -2.0, 3.0]))
    np.testing.assert_allclose(linear, points @ np.diag([1.0, -2.0, 3.0]), atol=1e-15)


def test_a_point_outside_the_mesh_is_refused(block):
    with pytest.raises(MeshError, match="1 point\\(s\\) lie outside the mesh"):
        locate_points(block, [[5e-3, 5e-3, 6e-3]])
