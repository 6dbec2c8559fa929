"""Rigid contact integrated over the indented surface's triangles (issue 44).

The node-to-surface penalty of :mod:`warptissue.fem.contact` presses each candidate node on
its own, so that the contact's edge jumps from one ring of nodes to the next and the force
follows the mesh (docs/fe.md "Contact"). Here the gap is evaluated at quadrature points of
the surface's triangles instead (a segment-to-analytical-surface formulation: the rigid
indenter is the analytic body of ``rigid_contact_point``), on the triangle's own geometry
(the 6-node triangle of a TET10 face, curved):

    Pi_c = integral over Gamma_0 of eps <-g(x(X))>^2 / 2 dA_0,

``g`` the signed distance of the current position ``x = sum_a N_a x_a`` to the body,
``eps`` the penalty (Pa/m) and ``Gamma_0`` the reference surface. Its first variation gives
the nodal forces ``f_a = -integral of eps g N_a n dA_0`` and its second the symmetric tangent
``K_ab = integral of eps N_a N_b (n n^T + g dn/dx) dA_0`` (the normal's turning over a curved
body included), so Newton, the line search's energy and the sensitivities stay exact.
Integrating over the reference area makes ``-eps g`` a nominal pressure (the difference from
the true pressure is of the order of the surface's stretch, and vanishes with the penalty's
penetration). The quadrature splits each triangle into ``s^2`` similar sub-triangles and uses
the three-point rule of degree 2 on each (:func:`triangle_rule`), so that the contact's edge
is resolved to a fraction ``1 / (2 s)`` of an element.

Device code: ``rigid_surface_contact_kernel`` in ``kernels/contact.py``; launched by
:class:`warptissue.fem.contact.RigidContacts` when a
:class:`~warptissue.fem.contact.RigidContact` carries a :class:`SurfaceQuadrature`
(``IndentationProblem(..., contact_integration="surface")``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from warptissue.errors import InputError
from warptissue.mesh import TET4_EDGES, TetMesh, boundary_faces

__all__ = [
    "CONTACT_INTEGRATIONS",
    "SURFACE_PENALTY_SCALE",
    "SURFACE_SUBDIVISIONS",
    "SurfaceQuadrature",
    "block_ids",
    "surface_triangles",
    "triangle_rule",
    "triangle_shape_functions",
]

CONTACT_INTEGRATIONS: tuple[str, ...] = ("nodes", "surface")
"""How a rigid contact is discretized: ``"nodes"`` (node-to-surface penalty, the default) or
``"surface"`` (integrated at quadrature points of the surface's triangles, this module)."""

SURFACE_PENALTY_SCALE = 10.0
"""The surface penalty per unit area is ``eps = SURFACE_PENALTY_SCALE beta mu0 / h``
(``beta`` the problem's penalty factor, ``h`` the mean edge under the indenter): with the
nodal ``k = beta mu0 h`` alone, ``eps = beta mu0 / h`` let the sphere in 24 times deeper
than the nodal penalty does and lowered the force by 1 % at d = 0.005 R (docs/design-notes/
surface-contact.md); ten times that gives 0.04 % of the depth at 9-12 Newton iterations."""

SURFACE_SUBDIVISIONS = 3
"""``s`` of :func:`triangle_rule`: each triangle is split into ``s^2`` sub-triangles of three
points each."""


def surface_triangles(mesh: TetMesh, nodes: np.ndarray) -> np.ndarray:
    """The boundary triangles of ``mesh`` whose corners all lie in ``nodes``.

    Args:
        mesh: A TET4 or TET10 mesh.
        nodes: Node indices, (k,).

    Returns:
        (F, 3) corners, or for TET10 (F, 6): corners then the mid-edge nodes of the edges
        (0, 1), (1, 2), (2, 0); int64. The corners are in the order of
        :func:`warptissue.mesh.boundary_faces` (outward normal).
    """
    member = np.zeros(mesh.node_count, dtype=bool)
    member[np.asarray(nodes, dtype=np.int64)] = True
    corners = boundary_faces(mesh.tets).astype(np.int64)
    corners = corners[member[corners].all(axis=1)]
    if mesh.nodes_per_tet == 4 or len(corners) == 0:
        return corners
    # Mid-edge node of each tet edge, looked up by the edge's sorted corner pair.
    n = np.int64(mesh.node_count)
    tet_edges = np.sort(mesh.tets[:, :4][:, TET4_EDGES].reshape(-1, 2).astype(np.int64), 1)
    keys = tet_edges[:, 0] * n + tet_edges[:, 1]
    mids = mesh.tets[:, 4:10].reshape(-1).astype(np.int64)
    order = np.argsort(keys)
    keys, mids = keys[order], mids[order]
    columns = []
    for a, b in ((0, 1), (1, 2), (2, 0)):
        pair = np.sort(corners[:, [a, b]], axis=1)
        columns.append(mids[np.searchsorted(keys, pair[:, 0] * n + pair[:, 1])])
    return np.column_stack([corners, *columns])


def triangle_rule(subdivisions: int = SURFACE_SUBDIVISIONS) -> tuple[np.ndarray, np.ndarray]:
    """A composite quadrature rule on the reference triangle ``xi_1, xi_2 >= 0``,
    ``xi_1 + xi_2 <= 1``.

    Args:
        subdivisions: ``s``: the triangle is split into ``s^2`` similar sub-triangles.

    Returns:
        ``(points, weights)``: (3 s^2, 2) and (3 s^2,), the weights summing to 1/2 (the
        reference triangle's area).

    Notes:
        Each sub-triangle carries the three-point rule of degree 2 (points at barycentric
        (2/3, 1/6, 1/6) and its permutations, weights 1/3 of its area; Strang and Fix).
        ``s = 1`` integrates polynomials up to degree 2 exactly; the composite rule
        converges as ``s^-2`` for smooth integrands beyond, and places a kink (the
        contact's edge) to within about ``1 / (2 s)`` of the triangle.
    """
    s = int(subdivisions)
    if s < 1:
        raise InputError("must be at least 1", key="subdivisions", value=subdivisions)
    base = np.array([[1 / 6, 1 / 6], [2 / 3, 1 / 6], [1 / 6, 2 / 3]])
    points = []
    for i in range(s):
        for j in range(s - i):
            points.append((base + [i, j]) / s)  # the upward sub-triangle
            if i + j < s - 1:  # the downward one, its corners (i+1, j), (i, j+1), (i+1, j+1)
                points.append(([i + 1, j + 1] - base) / s)
    points = np.vstack(points)
    return points, np.full(len(points), 0.5 / len(points))


def triangle_shape_functions(points: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Shape functions of the 3- or 6-node triangle and their derivatives at ``points``.

    Args:
        points: (P, 2) reference coordinates ``xi_1, xi_2``.
        count: 3 (linear) or 6 (quadratic: corners, then the mid-edge nodes of (0, 1),
            (1, 2), (2, 0)).

    Returns:
        ``(N, dN)``: (P, count) and (P, count, 2) (d/dxi_1, d/dxi_2).

    Notes:
        Barycentric ``L = (1 - xi_1 - xi_2, xi_1, xi_2)``; corners ``L_i (2 L_i - 1)``,
        mid-edge nodes ``4 L_i L_j`` (TET10 faces); linear: ``L_i``.
    """
    xi = np.asarray(points, dtype=np.float64)
    bary = np.column_stack([1.0 - xi[:, 0] - xi[:, 1], xi[:, 0], xi[:, 1]])
    d_bary = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])  # dL_i / dxi
    if count == 3:
        return bary, np.broadcast_to(d_bary, (len(xi), 3, 2)).copy()
    if count != 6:
        raise InputError("a triangle has 3 or 6 nodes", key="count", value=count)
    values = np.empty((len(xi), 6))
    grads = np.empty((len(xi), 6, 2))
    for i in range(3):
        values[:, i] = bary[:, i] * (2.0 * bary[:, i] - 1.0)
        grads[:, i] = (4.0 * bary[:, i] - 1.0)[:, None] * d_bary[i]
    for m, (i, j) in enumerate(((0, 1), (1, 2), (2, 0))):
        values[:, 3 + m] = 4.0 * bary[:, i] * bary[:, j]
        grads[:, 3 + m] = 4.0 * (bary[:, j, None] * d_bary[i] + bary[:, i, None] * d_bary[j])
    return values, grads


@dataclass(frozen=True)
class SurfaceQuadrature:
    """Quadrature points of a contact surface in the reference configuration.

    Attributes:
        faces: The triangles, (F, 3 or 6) node indices (:func:`surface_triangles`).
        point_face: The triangle of each point, (Q,).
        point_shape: The triangle's shape functions at each point, (Q, 3 or 6).
        point_area_m2: The reference area each point stands for, (Q,), m^2 (summing to the
            surface's area, curved faces included).
        subdivisions: ``s`` of :func:`triangle_rule`.
    """

    faces: np.ndarray
    point_face: np.ndarray
    point_shape: np.ndarray
    point_area_m2: np.ndarray
    subdivisions: int = SURFACE_SUBDIVISIONS

    def areas_m2(self, points_m: np.ndarray) -> np.ndarray:
        """The area each point stands for with the nodes at ``points_m`` (N, 3), m (the
        current configuration, for the contact area), (Q,), m^2."""
        return (
            type(self).for_faces(points_m, self.faces, subdivisions=self.subdivisions).point_area_m2
        )

    @classmethod
    def for_faces(
        cls, points_m: np.ndarray, faces: np.ndarray, *, subdivisions: int = SURFACE_SUBDIVISIONS
    ) -> SurfaceQuadrature:
        """The rule of :func:`triangle_rule` on every triangle of ``faces``.

        Args:
            points_m: Reference node coordinates, (N, 3), m.
            faces: (F, 3 or 6) node indices.
            subdivisions: ``s`` of :func:`triangle_rule`.

        Raises:
            InputError: No triangle.
        """
        faces = np.asarray(faces, dtype=np.int64)
        if len(faces) == 0:
            raise InputError("no boundary triangle lies on the contact's nodes", key="surface")
        xi, weights = triangle_rule(subdivisions)
        shape, grads = triangle_shape_functions(xi, faces.shape[1])
        x = np.asarray(points_m, dtype=np.float64)[faces]  # (F, n, 3)
        tangents = np.einsum("pad,fai->fpdi", grads, x)  # (F, P, 2, 3)
        jacobian = np.linalg.norm(np.cross(tangents[:, :, 0], tangents[:, :, 1]), axis=2)
        count = len(faces)
        return cls(
            faces=faces,
            point_face=np.repeat(np.arange(count), len(xi)),
            point_shape=np.tile(shape, (count, 1)),
            point_area_m2=(jacobian * weights).ravel(),
            subdivisions=int(subdivisions),
        )


def block_ids(
    pattern_offsets: np.ndarray, pattern_columns: np.ndarray, rows: np.ndarray, columns: np.ndarray
) -> np.ndarray:
    """The index of block (``rows[e]``, ``columns[e]``) in a row-major BSR pattern.

    Args:
        pattern_offsets: The pattern's row offsets, (N + 1,).
        pattern_columns: Its column of each block, ascending within a row.
        rows, columns: The wanted blocks' node indices, same shape.

    Returns:
        The block indices, int64, the shape of ``rows``.

    Raises:
        InputError: A wanted block is not in the pattern (two nodes that share no element).
    """
    n = len(pattern_offsets) - 1
    pattern_rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(pattern_offsets))
    keys = pattern_rows * n + pattern_columns  # ascending: the pattern is row-major
    wanted = np.asarray(rows, dtype=np.int64) * n + np.asarray(columns, dtype=np.int64)
    ids = np.minimum(np.searchsorted(keys, wanted), len(keys) - 1)
    if not np.all(keys[ids] == wanted):
        raise InputError("the blocks couple nodes that share no element", key="mesh")
    return ids


class SurfaceContactArrays:
    """The device arrays of ``rigid_surface_contact_kernel`` for K problems' quadratures.

    Args:
        quadratures: Each problem's quadrature or None, (K,), in the problem's own node
            numbering.
        node_offsets: First node of each problem in the assembler's numbering, (K + 1,).
        pattern_offsets, pattern_columns: The tangent's BSR pattern.
        device: The Warp device.
    """

    def __init__(
        self,
        quadratures: list[SurfaceQuadrature | None],
        *,
        node_offsets: np.ndarray,
        pattern_offsets: np.ndarray,
        pattern_columns: np.ndarray,
        device: Any,
    ) -> None:
        used = [k for k, each in enumerate(quadratures) if each is not None]
        widths = {quadratures[k].faces.shape[1] for k in used}
        if len(widths) != 1:
            raise InputError("surface contacts of one assembler need one kind of triangle")
        faces, problems, point_face, shapes, areas = [], [], [], [], []
        face_count = 0
        for k in used:
            own = quadratures[k]
            faces.append(own.faces + node_offsets[k])
            problems.append(np.full(len(own.faces), k, dtype=np.int32))
            point_face.append(own.point_face + face_count)
            shapes.append(own.point_shape)
            areas.append(own.point_area_m2)
            face_count += len(own.faces)
        faces = np.vstack(faces)
        width = faces.shape[1]
        rows = np.repeat(faces, width, axis=1)
        columns = np.tile(faces, (1, width))
        blocks = block_ids(pattern_offsets, pattern_columns, rows, columns)
        self.point_count = int(sum(len(a) for a in areas))
        self.point_areas_m2 = np.concatenate(areas)
        self.point_problem = np.concatenate(problems)[np.concatenate(point_face)]
        self.inputs = [
            wp.array(faces.astype(np.int32), dtype=wp.int32, device=device),
            wp.array(blocks.astype(np.int32), dtype=wp.int32, device=device),
            wp.array(np.concatenate(problems), dtype=wp.int32, device=device),
            wp.array(np.concatenate(point_face).astype(np.int32), dtype=wp.int32, device=device),
            wp.array(np.vstack(shapes), dtype=wp.float64, device=device),
            wp.array(self.point_areas_m2, dtype=wp.float64, device=device),
        ]
        self.gap = wp.zeros(self.point_count, dtype=wp.float64, device=device)

    @classmethod
    def for_problems(
        cls,
        quadratures: list[SurfaceQuadrature | None],
        used: list[int],
        *,
        node_offsets: np.ndarray,
        pattern: tuple[np.ndarray, np.ndarray],
        device: Any,
    ) -> SurfaceContactArrays | None:
        """The arrays of the problems ``used`` (those with a rigid contact), None where
        every one of them is nodal (``quadratures[k]`` None).

        Raises:
            InputError: Nodal and surface-integrated contacts mixed.
        """
        surface = [quadratures[k] is not None for k in used]
        if not any(surface):
            return None
        if not all(surface):
            raise InputError(
                "surface-integrated contacts of one assembler need every contact integrated so",
                key="integration",
            )
        return cls(
            quadratures,
            node_offsets=node_offsets,
            pattern_offsets=pattern[0],
            pattern_columns=pattern[1],
            device=device,
        )
