"""Tetrahedral element geometry: quadrature, shape functions and reference gradients.

TET4: linear, one-point rule. TET10: quadratic (VTK node order: corners 0-3, then mid-edge
nodes on edges (0,1), (1,2), (0,2), (0,3), (1,3), (2,3)), four-point rule of degree 2 (the rule
of Abaqus C3D10). Elements are isoparametric: curved TET10 edges are handled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse

from warptissue.errors import MeshError
from warptissue.mesh import TetMesh, locate_points

__all__ = [
    "ElementGeometry",
    "element_geometry",
    "interpolation_matrix",
    "quadrature_rule",
    "shape_function_derivatives",
    "shape_functions",
]

_A = 0.5854101966249685
_B = 0.1381966011250105


def quadrature_rule(nodes_per_tet: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature points (barycentric xi, eta, zeta) and weights on the unit reference tet.

    Args:
        nodes_per_tet: 4 or 10.

    Returns:
        points (Q, 3) and weights (Q,) summing to 1/6 (the reference volume).
    """
    if nodes_per_tet == 4:
        return np.full((1, 3), 0.25), np.array([1.0 / 6.0])
    if nodes_per_tet == 10:
        points = np.array([[_B, _B, _B], [_A, _B, _B], [_B, _A, _B], [_B, _B, _A]])
        return points, np.full(4, 1.0 / 24.0)
    raise MeshError(f"elements must have 4 or 10 nodes, got {nodes_per_tet}")


def _barycentric(points: np.ndarray) -> np.ndarray:
    xi = np.atleast_2d(points)
    return np.column_stack([1.0 - xi.sum(axis=1), xi])


def shape_functions(nodes_per_tet: int, points: np.ndarray) -> np.ndarray:
    """Shape function values at reference points.

    Args:
        nodes_per_tet: 4 or 10.
        points: Reference coordinates (xi, eta, zeta), shape (Q, 3).

    Returns:
        N, shape (Q, nodes_per_tet).
    """
    lam = _barycentric(points)
    if nodes_per_tet == 4:
        return lam
    edges = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]])
    corners = lam * (2.0 * lam - 1.0)
    mids = 4.0 * lam[:, edges[:, 0]] * lam[:, edges[:, 1]]
    return np.hstack([corners, mids])


def shape_function_derivatives(nodes_per_tet: int, points: np.ndarray) -> np.ndarray:
    """Derivatives of the shape functions with respect to (xi, eta, zeta).

    Returns:
        dN/dxi, shape (Q, nodes_per_tet, 3).
    """
    lam = _barycentric(points)
    # d lambda_c / d xi_j for c = 0..3
    dlam = np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    q = lam.shape[0]
    if nodes_per_tet == 4:
        return np.broadcast_to(dlam, (q, 4, 3)).copy()
    edges = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]])
    corners = (4.0 * lam - 1.0)[:, :, None] * dlam[None]
    mids = 4.0 * (
        lam[:, edges[:, 0], None] * dlam[None, edges[:, 1]]
        + lam[:, edges[:, 1], None] * dlam[None, edges[:, 0]]
    )
    return np.concatenate([corners, mids], axis=1)


@dataclass(frozen=True)
class ElementGeometry:
    """Reference-configuration data of every element at every quadrature point.

    Attributes:
        shape_gradients: grad_X N_a, shape (tet_count, Q, nodes_per_tet, 3), 1/m.
        quadrature_volumes: det(dX/dxi) * weight, shape (tet_count, Q), m^3.
    """

    shape_gradients: np.ndarray
    quadrature_volumes: np.ndarray

    @property
    def tet_volumes(self) -> np.ndarray:
        """Element volumes, shape (tet_count,), m^3."""
        return self.quadrature_volumes.sum(axis=1)


def element_geometry(mesh: TetMesh) -> ElementGeometry:
    """Shape-function gradients and quadrature volumes in the reference configuration.

    Raises:
        MeshError: An element with a non-positive Jacobian at a quadrature point (inverted or
            degenerate), naming the first one.
    """
    npe = mesh.nodes_per_tet
    points, weights = quadrature_rule(npe)
    dn_dxi = shape_function_derivatives(npe, points)  # (Q, npe, 3)
    x = mesh.points[mesh.tets]  # (M, npe, 3)
    jac = np.einsum("mai,qaj->mqij", x, dn_dxi)  # dX_i/dxi_j
    det = np.linalg.det(jac)
    bad = np.flatnonzero((det <= 0.0).any(axis=1))
    if bad.size:
        raise MeshError(
            f"non-positive Jacobian {det[bad[0]].min():.3g} (inverted or degenerate tet)",
            element=int(bad[0]),
        )
    inv = np.linalg.inv(jac)  # dxi_j/dX_i as inv[..., j, i]
    grads = np.einsum("qaj,mqji->mqai", dn_dxi, inv)
    return ElementGeometry(
        shape_gradients=np.ascontiguousarray(grads),
        quadrature_volumes=np.ascontiguousarray(det * weights[None, :]),
    )


def interpolation_matrix(mesh: TetMesh, points_m: np.ndarray) -> scipy.sparse.csr_matrix:
    """``P`` with ``values_at_points = P @ nodal_values``: each point's tet
    (:func:`warptissue.mesh.locate_points`) and its :func:`shape_functions` at the point
    (TET4 linear; TET10 quadratic, at the corner tet's barycentric coordinates, exact where
    the mid-edge nodes lie at the edges' midpoints, as :func:`warptissue.mesh.to_tet10` puts
    them).

    Args:
        mesh: TET4 or TET10 mesh, metres.
        points_m: Points inside it, (n, 3), m.

    Returns:
        A sparse (n, node_count) matrix whose rows sum to 1.

    Raises:
        MeshError: A point outside the mesh.
    """
    tets, lam = locate_points(mesh, points_m)
    weights = shape_functions(mesh.nodes_per_tet, lam[:, 1:])
    rows = np.repeat(np.arange(len(tets)), mesh.nodes_per_tet)
    return scipy.sparse.csr_matrix(
        (weights.ravel(), (rows, mesh.tets[tets].ravel())),
        shape=(len(tets), mesh.node_count),
    )
