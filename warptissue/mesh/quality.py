"""Orientation and shape-quality checks of tetrahedral meshes."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from warptissue.errors import MeshError
from warptissue.mesh.core import (
    TET4_EDGES,
    TET4_FACES,
    TetMesh,
    signed_volumes,
    unique_sorted_rows,
)

__all__ = [
    "TET10_SWAP_1_2",
    "MeshQuality",
    "check_mesh",
    "dihedral_angles",
    "edge_lengths",
    "fix_orientation",
    "move_midnodes_keeping_jacobian",
    "radius_ratios",
    "tet10_jacobian_determinants",
]

CURVED_MIN_SCALED_JACOBIAN = 0.1
"""Smallest scaled Jacobian (det J over 6 V, 1 straight-sided) that
:func:`move_midnodes_keeping_jacobian` leaves in an element it curves."""

TET10_SWAP_1_2: np.ndarray = np.array([0, 2, 1, 3, 6, 5, 4, 7, 9, 8], dtype=np.int32)
"""Node permutation that swaps corners 1 and 2 of a TET10 and its mid-edge nodes with them:
edges (0,1) <-> (0,2) and (1,3) <-> (2,3); (1,2) and (0,3) stay. Its first four entries are the
TET4 permutation."""

_DEGENERATE_TOLERANCE = 1e-8
"""Default bound on |volume| / (longest edge)^3 below which a tet counts as degenerate (a
regular tet has 1 / (6 sqrt 2) = 0.118)."""

_BATCH = 32768
"""Tets per batch in the TET10 Jacobians, which bounds temporary memory on large meshes."""

# Barycentric sample points for TET10 Jacobians: the 4 corners, 6 edge midpoints, centroid.
_TET10_SAMPLES = np.vstack(
    [np.eye(4), 0.5 * (np.eye(4)[TET4_EDGES[:, 0]] + np.eye(4)[TET4_EDGES[:, 1]]), [[0.25] * 4]]
)


@dataclass(frozen=True)
class MeshQuality:
    """Summary of a mesh's size and element shapes.

    Attributes:
        element_type: ``"TET4"`` or ``"TET10"``.
        node_count: Number of nodes.
        tet_count: Number of tets.
        total_volume_m3: Sum of the corner tets' volumes, m^3.
        min_volume_m3: Smallest corner-tet volume, m^3.
        max_volume_m3: Largest corner-tet volume, m^3.
        min_edge_m: Shortest corner edge, m.
        max_edge_m: Longest corner edge, m.
        min_radius_ratio: Smallest normalized radius ratio 3 r_in / r_circ (1 for a regular
            tet, 0 for a flat one).
        mean_radius_ratio: Mean normalized radius ratio.
        min_dihedral_deg: Smallest dihedral angle, degrees (70.53 for a regular tet).
        max_dihedral_deg: Largest dihedral angle, degrees.
        min_scaled_jacobian: TET10: smallest det J at the nodes and centroid over 6 times the
            corner tet's volume (1 for straight-sided elements). TET4: 1.
        worst_element: Index of the tet with the smallest radius ratio.
        boundary_face_count: Corner triangles that belong to one tet only.
        unused_node_count: Nodes that no tet uses (they make a stiffness matrix singular).
    """

    element_type: str
    node_count: int
    tet_count: int
    total_volume_m3: float
    min_volume_m3: float
    max_volume_m3: float
    min_edge_m: float
    max_edge_m: float
    min_radius_ratio: float
    mean_radius_ratio: float
    min_dihedral_deg: float
    max_dihedral_deg: float
    min_scaled_jacobian: float
    worst_element: int
    boundary_face_count: int
    unused_node_count: int

    def to_dict(self) -> dict[str, Any]:
        """The fields as a JSON-ready mapping."""
        return asdict(self)


def check_mesh(
    mesh: TetMesh, *, degenerate_tolerance: float = _DEGENERATE_TOLERANCE
) -> MeshQuality:
    """Check that every tet is positively oriented and not degenerate, and measure quality.

    Args:
        mesh: The mesh to check (TET4 or TET10).
        degenerate_tolerance: A tet with |volume| <= tolerance * (longest edge)^3 is degenerate.

    Returns:
        The quality summary.

    Raises:
        MeshError: The mesh has no tets, or a tet is inverted
            (negative volume), degenerate (near-zero volume for its size) or, for TET10,
            curved so much that its Jacobian determinant is not positive somewhere, or a face
            is shared by more than two tets. The error
            names the first offending element and carries its index in ``.element``.
    """
    if mesh.tet_count == 0:
        raise MeshError("the mesh has no tetrahedra")
    volumes = mesh.volumes()
    lengths = edge_lengths(mesh.points, mesh.corner_tets)
    longest = lengths.max(axis=1)
    degenerate = np.abs(volumes) <= degenerate_tolerance * longest**3
    inverted = (volumes < 0) & ~degenerate
    bad = np.flatnonzero(degenerate | inverted)
    if bad.size:
        first = int(bad[0])
        kind = "inverted (negative volume" if inverted[first] else "degenerate (near-zero volume"
        raise MeshError(
            f"{kind} {volumes[first]:.3e} m^3 for longest edge {longest[first]:.3e} m; "
            f"{bad.size} bad tets in all), nodes {mesh.tets[first, :4].tolist()}",
            element=first,
        )
    scaled_jacobian = np.ones(mesh.tet_count)
    if mesh.nodes_per_tet == 10:
        # Straight-sided elements (mid nodes at edge midpoints) have det J = 6 V everywhere;
        # evaluate the Jacobian only where a mid node is off its edge's midpoint.
        corners = mesh.points[mesh.tets[:, :4]]
        midpoints = 0.5 * (corners[:, TET4_EDGES[:, 0]] + corners[:, TET4_EDGES[:, 1]])
        offset = np.linalg.norm(mesh.points[mesh.tets[:, 4:]] - midpoints, axis=2)
        curved = np.flatnonzero((offset > 1e-12 * lengths).any(axis=1))
        determinants = tet10_jacobian_determinants(mesh.points, mesh.tets[curved])
        scaled_jacobian[curved] = determinants.min(axis=1) / (6.0 * volumes[curved])
        bad_jacobian = np.flatnonzero(scaled_jacobian <= 0)
        if bad_jacobian.size:
            first = int(bad_jacobian[0])
            raise MeshError(
                "TET10 Jacobian determinant is not positive inside the element (mid-edge node "
                f"too far from its edge; {bad_jacobian.size} such tets), nodes "
                f"{mesh.tets[first].tolist()}",
                element=first,
            )
    faces = np.sort(mesh.corner_tets[:, TET4_FACES].reshape(-1, 3), axis=1)
    _, face_inverse, face_counts = unique_sorted_rows(faces, return_counts=True)
    crowded = np.flatnonzero(face_counts[face_inverse] > 2)
    if crowded.size:
        first = int(crowded[0] // 4)
        raise MeshError(
            f"face {faces[crowded[0]].tolist()} is shared by "
            f"{int(face_counts[face_inverse[crowded[0]]])} tets (overlapping or non-manifold "
            "elements)",
            element=first,
        )
    ratios = _radius_ratios(mesh.points, mesh.corner_tets, lengths)
    dihedral = dihedral_angles(mesh.points, mesh.corner_tets)
    return MeshQuality(
        element_type=mesh.element_type,
        node_count=mesh.node_count,
        tet_count=mesh.tet_count,
        total_volume_m3=float(volumes.sum()),
        min_volume_m3=float(volumes.min()),
        max_volume_m3=float(volumes.max()),
        min_edge_m=float(lengths.min()),
        max_edge_m=float(lengths.max()),
        min_radius_ratio=float(ratios.min()),
        mean_radius_ratio=float(ratios.mean()),
        min_dihedral_deg=float(np.degrees(dihedral.min())),
        max_dihedral_deg=float(np.degrees(dihedral.max())),
        min_scaled_jacobian=float(scaled_jacobian.min()),
        worst_element=int(np.argmin(ratios)),
        boundary_face_count=int((face_counts == 1).sum()),
        unused_node_count=int(
            np.count_nonzero(np.bincount(mesh.tets.ravel(), minlength=mesh.node_count) == 0)
        ),
    )


def fix_orientation(mesh: TetMesh) -> TetMesh:
    """Return a copy with every negatively oriented tet turned positive.

    Corners 1 and 2 of each negative tet swap, and for TET10 the mid-edge nodes move with
    them (:data:`TET10_SWAP_1_2`), so every mid-edge node stays on its edge. Degenerate tets
    are left as they are (:func:`check_mesh` reports them). Node sets, face sets and regions
    are kept.

    Args:
        mesh: A TET4 or TET10 mesh.

    Returns:
        The reoriented mesh (a new object; ``mesh`` is not modified).
    """
    tets = mesh.tets.copy()
    negative = mesh.volumes() < 0
    permutation = TET10_SWAP_1_2[: mesh.nodes_per_tet]
    tets[negative] = tets[negative][:, permutation]
    return TetMesh(
        points=mesh.points.copy(),
        tets=tets,
        node_sets={k: v.copy() for k, v in mesh.node_sets.items()},
        face_sets={k: v.copy() for k, v in mesh.face_sets.items()},
        tet_regions=mesh.tet_regions.copy(),
    )


def move_midnodes_keeping_jacobian(
    mesh: TetMesh,
    nodes: np.ndarray,
    targets_m: np.ndarray,
    *,
    min_scaled_jacobian: float = CURVED_MIN_SCALED_JACOBIAN,
) -> np.ndarray:
    """Move TET10 mid-edge nodes toward targets (a curved boundary), each only as far as the
    elements around it keep a positive Jacobian, in place.

    Args:
        mesh: A TET10 mesh whose elements are valid as they are (straight-sided, say).
            Modified in place.
        nodes: Mid-edge node indices, shape (n,).
        targets_m: Where each node should go, shape (n, 3), m.
        min_scaled_jacobian: An element that the move would leave with det J / (6 V) below
            this, at any of the samples of :func:`tet10_jacobian_determinants`, has its moved
            nodes' moves halved, up to 10 times, then undone (the straight position, det J =
            6 V, is valid).

    Returns:
        The fraction of its move each node made, shape (n,): 1 where it reached its target.

    Notes:
        Projecting a boundary edge's mid node onto a curved surface bends the element; a flat
        element against the surface (a sliver with four corners on it) inverts when its mid
        node moves farther than about its height. Such a node stops part of the way, so the
        face follows the surface a little less there and the element stays valid (the
        :func:`check_mesh` test).
    """
    nodes = np.asarray(nodes, dtype=np.int64)
    start = mesh.points[nodes].copy()
    move = np.asarray(targets_m, dtype=float) - start
    fraction = np.ones(len(nodes))
    position = np.full(mesh.node_count, -1, dtype=np.int64)
    position[nodes] = np.arange(len(nodes))
    touched = np.flatnonzero((position[mesh.tets[:, 4:]] >= 0).any(axis=1))
    tets = mesh.tets[touched]
    volumes = signed_volumes(mesh.points, tets[:, :4])
    for attempt in range(11):
        mesh.points[nodes] = start + fraction[:, None] * move
        scaled = tet10_jacobian_determinants(mesh.points, tets).min(axis=1) / (6.0 * volumes)
        bad = scaled < min_scaled_jacobian
        if not bad.any():
            break
        held = position[tets[bad, 4:]]
        held = np.unique(held[held >= 0])
        fraction[held] = 0.0 if attempt == 9 else 0.5 * fraction[held]
    return fraction


def radius_ratios(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Normalized radius ratio 3 r_in / r_circ of each tet (1 regular, 0 flat).

    Args:
        points: Node coordinates, shape (N, 3), metres.
        tets: Corner connectivity, shape (M, 4) (extra columns are ignored).

    Returns:
        Ratios in [0, 1], shape (M,).

    Notes:
        r_in = 3 |V| / (sum of face areas). The circumradius follows from the products of
        opposite edge lengths p = a a', q = b b', r = c c':
        r_circ = sqrt((p + q + r)(p + q - r)(p - q + r)(-p + q + r)) / (24 |V|).
    """
    return _radius_ratios(points, tets, edge_lengths(points, tets))


def _radius_ratios(points: np.ndarray, tets: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """:func:`radius_ratios` with the edge lengths (M, 6) already computed."""
    corners = tets[:, :4]
    volume = np.abs(signed_volumes(points, corners))
    x = points[corners[:, TET4_FACES]]  # (M, 4, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(x[:, :, 1] - x[:, :, 0], x[:, :, 2] - x[:, :, 0]), axis=2)
    # Opposite edge pairs in TET4_EDGES order: (0,1)-(2,3), (1,2)-(0,3), (0,2)-(1,3).
    p, q, r = (
        lengths[:, 0] * lengths[:, 5],
        lengths[:, 1] * lengths[:, 3],
        lengths[:, 2] * lengths[:, 4],
    )
    product = np.clip((p + q + r) * (p + q - r) * (p - q + r) * (-p + q + r), 0.0, None)
    with np.errstate(divide="ignore", invalid="ignore"):
        inradius = 3.0 * volume / area.sum(axis=1)
        circumradius = np.sqrt(product) / (24.0 * volume)
        ratio = 3.0 * inradius / circumradius
    return np.nan_to_num(ratio, nan=0.0, posinf=0.0)


def dihedral_angles(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """The six dihedral angles of each tet, at edges in :data:`TET4_EDGES` order, radians.

    Args:
        points: Node coordinates, shape (N, 3).
        tets: Corner connectivity, shape (M, 4) (extra columns are ignored).

    Returns:
        Angles in [0, pi], shape (M, 6).
    """
    x = points[tets[:, :4][:, TET4_FACES]]
    normals = np.cross(x[:, :, 1] - x[:, :, 0], x[:, :, 2] - x[:, :, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        normals /= np.linalg.norm(normals, axis=2, keepdims=True)
    # The edge (i, j) is shared by the faces opposite the two other corners.
    others = np.array([[k for k in range(4) if k not in edge] for edge in TET4_EDGES])
    cosine = np.einsum("mej,mej->me", normals[:, others[:, 0]], normals[:, others[:, 1]])
    return np.pi - np.arccos(np.clip(np.nan_to_num(cosine), -1.0, 1.0))


def tet10_jacobian_determinants(
    points: np.ndarray, tets: np.ndarray, *, barycentric: np.ndarray | None = None
) -> np.ndarray:
    """det(dx/dxi) of isoparametric TET10s at points given in barycentric coordinates.

    Args:
        points: Node coordinates, shape (N, 3).
        tets: TET10 connectivity (VTK mid-edge order), shape (M, 10).
        barycentric: Sample points (L_0, L_1, L_2, L_3), shape (S, 4). Default: the 4
            corners, the 6 edge midpoints (in :data:`TET4_EDGES` order) and the centroid.

    Returns:
        Determinants, shape (M, S): equal to 6 times the volume everywhere for a
        straight-sided element.

    Notes:
        Shape functions in barycentric coordinates L: corners L_i (2 L_i - 1), mid-edge nodes
        4 L_i L_j; xi = (L_1, L_2, L_3) and L_0 = 1 - L_1 - L_2 - L_3.
    """
    samples = _TET10_SAMPLES if barycentric is None else np.asarray(barycentric, float)
    # dN_a / dL_k at each sample: (S, 10, 4).
    d_dl = np.zeros((len(samples), 10, 4))
    for corner in range(4):
        d_dl[:, corner, corner] = 4.0 * samples[:, corner] - 1.0
    for edge, (i, j) in enumerate(TET4_EDGES):
        d_dl[:, 4 + edge, i] = 4.0 * samples[:, j]
        d_dl[:, 4 + edge, j] = 4.0 * samples[:, i]
    dl_dxi = np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    d_dxi = d_dl @ dl_dxi  # (S, 10, 3)
    # Per batch, one BLAS product for all tets and samples: (3 m, 10) @ (10, 3 S) -> J[m, c, s, d].
    shape_gradients = d_dxi.transpose(1, 0, 2).reshape(10, -1)
    determinants = np.empty((len(tets), len(samples)))
    for start in range(0, len(tets), _BATCH):
        batch = tets[start : start + _BATCH]
        coordinates = points[batch].transpose(0, 2, 1).reshape(-1, 10)
        jacobians = (coordinates @ shape_gradients).reshape(len(batch), 3, len(samples), 3)
        # Columns d first, rows c second, contiguous: (3, 3, m, S).
        columns = np.ascontiguousarray(jacobians.transpose(3, 1, 0, 2))
        determinants[start : start + len(batch)] = _det3(columns[0], columns[1], columns[2])
    return determinants


def _det3(u: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Determinants of 3x3 matrices given by columns u, v, w, each shaped (3, ...) with the
    row index first: det = u . (v x w)."""
    return (
        u[0] * (v[1] * w[2] - v[2] * w[1])
        + u[1] * (v[2] * w[0] - v[0] * w[2])
        + u[2] * (v[0] * w[1] - v[1] * w[0])
    )


def edge_lengths(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Lengths of each tet's six corner edges.

    Args:
        points: Node coordinates, shape (N, 3), metres.
        tets: Corner connectivity, shape (M, 4) (extra columns are ignored).

    Returns:
        Edge lengths in :data:`TET4_EDGES` order, shape (M, 6), metres.
    """
    x = points[tets[:, :4]]
    return np.linalg.norm(x[:, TET4_EDGES[:, 1]] - x[:, TET4_EDGES[:, 0]], axis=2)
