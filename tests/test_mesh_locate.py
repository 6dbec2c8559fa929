"""Points located in a tet mesh (warptissue.mesh.locate_points): the barycentric coordinates
rebuild the points, and a point outside is refused (the interpolation to them:
tests/test_fem_elements.py)."""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import MeshError
from warptissue.mesh import block_mesh, locate_points


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


def test_a_point_outside_the_mesh_is_refused(block):
    with pytest.raises(MeshError, match="1 point\\(s\\) lie outside the mesh"):
        locate_points(block, [[5e-3, 5e-3, 6e-3]])
