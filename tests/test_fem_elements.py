"""Element geometry and the patch test for TET4 and TET10."""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import MeshError
from warptissue.fem import (
    Assembler,
    DirichletConditions,
    NewtonOptions,
    element_geometry,
    solve_quasistatic,
)
from warptissue.fem.elements import (
    interpolation_matrix,
    quadrature_rule,
    shape_function_derivatives,
    shape_functions,
)
from warptissue.materials import LinearElastic, NeoHookean, Ogden
from warptissue.mesh import TetMesh, block_mesh, to_tet10


@pytest.mark.parametrize("npe", [4, 10])
def test_shape_functions_partition_unity_and_interpolate_nodes(npe, rng):
    points = rng.uniform(0, 0.3, size=(7, 3))
    values = shape_functions(npe, points)
    np.testing.assert_allclose(values.sum(axis=1), 1.0, rtol=0, atol=1e-14)
    np.testing.assert_allclose(shape_function_derivatives(npe, points).sum(axis=1), 0.0, atol=1e-13)
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    nodes = corners
    if npe == 10:
        edges = [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)]
        nodes = np.vstack([corners, [(corners[i] + corners[j]) / 2 for i, j in edges]])
    np.testing.assert_allclose(shape_functions(npe, nodes), np.eye(npe), atol=1e-14)
    # derivatives against central differences
    h = 1e-6
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = h
        fd = (shape_functions(npe, points + step) - shape_functions(npe, points - step)) / (2 * h)
        np.testing.assert_allclose(
            shape_function_derivatives(npe, points)[:, :, axis], fd, atol=1e-8
        )


@pytest.mark.parametrize("npe", [4, 10])
def test_quadrature_integrates_its_degree(npe):
    points, weights = quadrature_rule(npe)
    assert weights.sum() == pytest.approx(1.0 / 6.0)
    # int xi dV = 1/24 on the unit tet; degree 2 (TET10 rule): int xi^2 = 1/60, int xi eta = 1/120
    assert weights @ points[:, 0] == pytest.approx(1.0 / 24.0)
    if npe == 10:
        assert weights @ points[:, 0] ** 2 == pytest.approx(1.0 / 60.0)
        assert weights @ (points[:, 0] * points[:, 1]) == pytest.approx(1.0 / 120.0)


def _distorted_cube(rng: np.random.Generator, npe: int) -> TetMesh:
    grid = np.linspace(0.0, 2e-3, 4)
    mesh = block_mesh(grid, grid, grid)
    boundary = np.unique(np.concatenate([mesh.node_sets[s] for s in mesh.node_sets]))
    interior = np.setdiff1d(np.arange(mesh.node_count), boundary)
    mesh.points[interior] += rng.uniform(-1.5e-4, 1.5e-4, size=(len(interior), 3))
    return to_tet10(mesh) if npe == 10 else mesh


def test_geometry_volumes_and_gradients(rng):
    for npe in (4, 10):
        mesh = _distorted_cube(rng, npe)
        geometry = element_geometry(mesh)
        assert geometry.tet_volumes.sum() == pytest.approx(8e-9, rel=1e-12)
        np.testing.assert_allclose(geometry.tet_volumes, mesh.volumes(), rtol=1e-12)
        # grad of the coordinate field x is the identity at every quadrature point
        grad_x = np.einsum("mai,mqaj->mqij", mesh.points[mesh.tets], geometry.shape_gradients)
        np.testing.assert_allclose(grad_x, np.broadcast_to(np.eye(3), grad_x.shape), atol=1e-12)


def test_inverted_element_is_named():
    mesh = block_mesh(np.array([0.0, 1.0]), np.array([0.0, 1.0]), np.array([0.0, 1.0]))
    tets = mesh.tets.copy()
    tets[2, [1, 2]] = tets[2, [2, 1]]
    with pytest.raises(MeshError, match="element 2"):
        element_geometry(TetMesh(mesh.points, tets))


@pytest.mark.parametrize(
    ("npe", "formulation", "material"),
    [
        (4, "displacement", LinearElastic(3000.0, 0.3)),
        (10, "displacement", LinearElastic(3000.0, 0.3)),
        (4, "displacement", NeoHookean(500.0, 20000.0)),
        (10, "displacement", NeoHookean(500.0, 20000.0)),
        (10, "mixed", NeoHookean(500.0, 500000.0)),
        (10, "mixed", Ogden((400.0, 50.0), (4.0, -2.0), 500000.0)),
    ],
)
def test_patch_test_reproduces_affine_displacement(npe, formulation, material, rng):
    """Boundary nodes follow u = H X + c; every interior node must follow it too."""
    mesh = _distorted_cube(rng, npe)
    h = np.array([[-0.08, 0.03, 0.02], [0.01, 0.05, -0.04], [0.02, -0.03, 0.06]])
    if isinstance(material, LinearElastic):
        h *= 1e-3  # small strain
    affine = mesh.points @ h.T + np.array([1e-5, -2e-5, 3e-5])
    boundary = np.unique(np.concatenate([mesh.node_sets[s] for s in mesh.node_sets]))
    nodes = np.repeat(boundary, 3)
    components = np.tile(np.arange(3), len(boundary))
    conditions = DirichletConditions(nodes, components, affine[boundary].ravel())
    assembler = Assembler(mesh, material, formulation=formulation, device="cpu")
    path = solve_quasistatic(
        assembler, conditions, [0.5, 1.0], options=NewtonOptions(linear_solver="superlu")
    )
    assert path.completed, path.message
    interior = np.setdiff1d(np.arange(mesh.node_count), boundary)
    assert len(interior) > 0
    error = np.abs(path.displacement_m[-1] - affine).max()
    assert error <= 1e-10 * np.abs(affine).max()
    forces = assembler.assemble(path.displacement_m[-1], with_tangent=False).residual.numpy()
    assert np.abs(forces[interior]).max() <= 1e-9 * np.abs(forces).max()


def test_tet10_interpolates_a_quadratic_field_and_tet4_a_linear_one(rng):
    """interpolation_matrix at random points inside a block and at its nodes."""
    grid = np.linspace(0.0, 1e-2, 4)
    block = block_mesh(grid, grid, np.linspace(0.0, 5e-3, 3))
    inside = rng.uniform([0.0, 0.0, 0.0], [1e-2, 1e-2, 5e-3], size=(200, 3))
    points = np.vstack([inside, block.points])  # nodes of the surface too
    quadratic = to_tet10(block)

    def field(x):
        return np.column_stack([x[:, 0] * x[:, 1], x[:, 2] ** 2 - x[:, 0], 3.0 * x[:, 1]])

    values = interpolation_matrix(quadratic, points) @ field(quadratic.points)
    np.testing.assert_allclose(values, field(points), atol=1e-15)
    linear = interpolation_matrix(block, points) @ (block.points @ np.diag([1.0, -2.0, 3.0]))
    np.testing.assert_allclose(linear, points @ np.diag([1.0, -2.0, 3.0]), atol=1e-15)
