"""Points located in a tet mesh: :func:`locate_points` (the interpolation of nodal values to
them is :func:`warptissue.fem.elements.interpolation_matrix`)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from warptissue.errors import MeshError
from warptissue.mesh.core import TetMesh

LOCATE_TOLERANCE = 1e-9
"""How far outside its tet (in barycentric coordinates) a point may lie and still be inside:
points on a face or a node of the mesh's boundary."""
_CANDIDATES = (8, 64, 512)


def locate_points(mesh: TetMesh, points_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The tet of ``mesh`` holding each point, and the point's barycentric coordinates in it.

    A point is tried in the tets whose centroids are nearest (8, then 64, then 512 of them)
    and kept in the one where its smallest barycentric coordinate is largest; it is inside
    where that coordinate is at least ``-LOCATE_TOLERANCE`` (on a face or a node counts).

    Args:
        mesh: TET4 or TET10 mesh, metres (located by its straight corner tets).
        points_m: Points, (n, 3), m.

    Returns:
        ``(tets, barycentric)``: the tet of each point, (n,) int64, and its coordinates with
        respect to the tet's corners 0..3, (n, 4) (summing to 1).

    Raises:
        MeshError: A point outside the mesh (the first such point and how far outside).
    """
    points = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    corners = mesh.points[mesh.tets[:, :4]]
    origin = corners[:, 0]
    edges = np.stack([corners[:, i] - origin for i in (1, 2, 3)], axis=2)  # columns
    inverse = np.linalg.inv(edges)
    tree = cKDTree(corners.mean(axis=1))
    best_tet = np.full(len(points), -1, dtype=np.int64)
    best = np.full((len(points), 4), np.nan)
    best_margin = np.full(len(points), -np.inf)
    todo = np.arange(len(points))
    for count in _CANDIDATES:
        if todo.size == 0:
            break
        count = min(count, mesh.tet_count)
        _, candidates = tree.query(points[todo], k=count)
        candidates = np.asarray(candidates).reshape(len(todo), count)
        offset = points[todo][:, None, :] - origin[candidates]
        tail = np.einsum("nkij,nkj->nki", inverse[candidates], offset)
        coordinates = np.concatenate([1.0 - tail.sum(axis=2, keepdims=True), tail], axis=2)
        margin = coordinates.min(axis=2)
        pick = margin.argmax(axis=1)
        rows = np.arange(len(todo))
        better = margin[rows, pick] > best_margin[todo]
        chosen = todo[better]
        best_tet[chosen] = candidates[rows, pick][better]
        best[chosen] = coordinates[rows, pick][better]
        best_margin[chosen] = margin[rows, pick][better]
        todo = todo[best_margin[todo] < -LOCATE_TOLERANCE]
        if count == mesh.tet_count:
            break
    if todo.size:
        first = int(todo[0])
        raise MeshError(
            f"{todo.size} point(s) lie outside the mesh, the first {points[first].tolist()} m "
            f"(barycentric coordinate {best_margin[first]:.3g} in its nearest tet)"
        )
    return best_tet, best
