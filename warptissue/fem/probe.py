"""Where and at what angle a probe meets a specimen: the site on the surface, the inward
normal under the probe and the probe's frame.

A probe acts at a point of the specimen's boundary (the *site*) along a unit *direction*
(into the body). :func:`snap_to_surface` moves a given point to the nearest point of the
boundary triangles, :func:`footprint_normal` averages the inward normal over the triangles
under the probe, and :func:`probe_frame` builds the orthonormal frame the rigid-contact
kernel works in (``kernels/contact.py``: every rigid body is described along the local z
axis, ``e3 = -direction``, a wedge's edge along ``e2``).

Example:
    >>> import numpy as np
    >>> from warptissue.fem.probe import probe_frame
    >>> frame = probe_frame(origin_m=[0.0, 0.0, 0.01], direction=[0.0, 0.0, -1.0])
    >>> frame.axes.tolist()
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from warptissue.errors import InputError
from warptissue.mesh import TetMesh, boundary_faces

__all__ = [
    "DOWN",
    "ProbeFrame",
    "closest_surface_points",
    "footprint_normal",
    "probe_frame",
    "snap_to_surface",
    "surface_triangles",
]

DOWN = (0.0, 0.0, -1.0)
"""The default probe direction: along -z, into a specimen whose indented face is on top."""


@dataclass(frozen=True)
class ProbeFrame:
    """An orthonormal, right-handed frame at the probe's contact point.

    Attributes:
        origin_m: The contact point at depth 0 (the site), (3,), m.
        axes: The frame's unit axes as rows ``e1, e2, e3`` in world coordinates, (3, 3):
            ``e3 = -direction`` (the probe's "up"), ``e2`` a wedge's edge, ``e1 = e2 x e3``.
    """

    origin_m: np.ndarray
    axes: np.ndarray

    @property
    def direction(self) -> np.ndarray:
        """The unit direction the probe moves in (into the body), (3,)."""
        return -self.axes[2] + 0.0

    @property
    def is_default(self) -> bool:
        """Whether the frame is the world's (the probe along -z)."""
        return bool(np.array_equal(self.axes, np.eye(3)))

    def to_local(self, points_m: np.ndarray) -> np.ndarray:
        """Coordinates of ``points_m`` (n, 3) in the frame (relative to ``origin_m``), m."""
        return (np.asarray(points_m, dtype=np.float64) - self.origin_m) @ self.axes.T

    def point_at_depth(self, depth_m: float) -> np.ndarray:
        """The contact point after the probe has moved ``depth_m`` along its direction, m."""
        return self.origin_m + depth_m * self.direction


def _unit(vector: Sequence[float], key: str) -> np.ndarray:
    value = np.asarray(vector, dtype=np.float64)
    if value.shape != (3,) or not np.all(np.isfinite(value)):
        raise InputError("must be three finite numbers", key=key, value=list(np.ravel(value)))
    norm = float(np.linalg.norm(value))
    if norm == 0.0:
        raise InputError("must not be the zero vector", key=key, value=value.tolist())
    return value / norm


def probe_frame(
    *,
    origin_m: Sequence[float],
    direction: Sequence[float] = DOWN,
    edge: Sequence[float] | None = None,
) -> ProbeFrame:
    """The probe's frame at ``origin_m`` moving along ``direction``.

    Args:
        origin_m: The contact point at depth 0, (3,), m.
        direction: The probe's direction of motion (into the body), (3,); normalised.
        edge: A wedge's edge direction, (3,): its part perpendicular to ``direction`` is
            ``e2``. None: y, or x where ``direction`` is within 1e-6 of the y axis.

    Returns:
        The frame (``direction = (0, 0, -1)`` and the default edge give the identity axes).

    Raises:
        InputError: A direction or edge that is not three finite numbers, the zero vector,
            or an edge along the direction (``key`` names it).
    """
    origin = np.asarray(origin_m, dtype=np.float64)
    if origin.shape != (3,) or not np.all(np.isfinite(origin)):
        raise InputError("must be three finite numbers in metres", key="site_m", value=origin_m)
    up = -_unit(direction, "direction") + 0.0
    if edge is None:
        along = np.array([0.0, 1.0, 0.0]) if abs(up[1]) < 1.0 - 1e-6 else np.array([1.0, 0, 0])
    else:
        along = _unit(edge, "edge")
    e2 = along - np.dot(along, up) * up
    norm = float(np.linalg.norm(e2))
    if norm < 1e-6:
        raise InputError("the edge must not be along the direction", key="edge", value=edge)
    e2 = e2 / norm
    e1 = np.cross(e2, up)
    axes = np.vstack([e1, e2, up]) + 0.0  # + 0.0: no negative zeros
    return ProbeFrame(origin_m=origin.copy(), axes=axes)


def surface_triangles(mesh: TetMesh, *, surface: str | None = None) -> np.ndarray:
    """The boundary triangles (corners, outward oriented) of ``mesh``, (F, 3) int; those
    whose corners all lie in node set ``surface`` when it is given.

    Raises:
        InputError: No boundary triangle lies on ``surface``.
    """
    faces = boundary_faces(mesh.tets).astype(np.int64)
    if surface is None:
        return faces
    member = np.zeros(mesh.node_count, dtype=bool)
    member[np.asarray(mesh.node_set(surface), dtype=np.int64)] = True
    faces = faces[member[faces].all(axis=1)]
    if len(faces) == 0:
        raise InputError(f"no boundary triangle lies on node set {surface!r}", key="surface")
    return faces


def _closest_on_segments(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
    return a + np.clip(t, 0.0, 1.0)[:, None] * ab


def closest_surface_points(
    points: np.ndarray, triangles: np.ndarray, point_m: Sequence[float]
) -> tuple[np.ndarray, np.ndarray]:
    """The closest point of each triangle to ``point_m`` and its distance.

    Args:
        points: Node coordinates, (N, 3), m.
        triangles: Corner triangles, (F, 3).
        point_m: The query point, (3,), m.

    Returns:
        The closest points (F, 3), m, and their distances (F,), m: the projection onto the
        triangle's plane where it falls inside, else the nearest point of its three edges.
    """
    p = np.asarray(point_m, dtype=np.float64)
    a, b, c = (points[triangles[:, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    area2 = np.einsum("ij,ij->i", normal, normal)
    unit = normal / np.sqrt(np.maximum(area2, 1e-300))[:, None]
    projected = p - np.einsum("ij,ij->i", p - a, unit)[:, None] * unit
    # Barycentric coordinates of the projection (signed sub-areas over the area).
    inside = np.ones(len(triangles), dtype=bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(v - u, projected - u), normal) >= 0.0
    rep = np.broadcast_to(p, a.shape)
    candidates = [_closest_on_segments(rep, u, v) for u, v in ((a, b), (b, c), (c, a))]
    best = candidates[0]
    for other in candidates[1:]:
        nearer = np.linalg.norm(other - p, axis=1) < np.linalg.norm(best - p, axis=1)
        best = np.where(nearer[:, None], other, best)
    best = np.where(inside[:, None], projected, best)
    return best, np.linalg.norm(best - p, axis=1)


def snap_to_surface(
    mesh: TetMesh,
    site_m: Sequence[float],
    *,
    tolerance_m: float,
    surface: str | None = None,
) -> np.ndarray:
    """The point of the boundary (of node set ``surface``'s triangles) nearest ``site_m``.

    Args:
        mesh: The specimen, m.
        site_m: The requested site, (3,), m.
        tolerance_m: The largest distance the site may be moved, m.
        surface: Node set whose boundary triangles may hold the site; None: all of them.

    Returns:
        The snapped site, (3,), m.

    Raises:
        InputError: ``site_m`` is not three finite numbers, or lies farther than
            ``tolerance_m`` from the surface (the message names the distance).
    """
    site = np.asarray(site_m, dtype=np.float64)
    if site.shape != (3,) or not np.all(np.isfinite(site)):
        raise InputError("must be three finite numbers in metres", key="site_m", value=site_m)
    triangles = surface_triangles(mesh, surface=surface)
    closest, distance = closest_surface_points(mesh.points, triangles, site)
    nearest = int(np.argmin(distance))
    if distance[nearest] > tolerance_m:
        where = "the surface" if surface is None else f"node set {surface!r}"
        raise InputError(
            f"the site is {distance[nearest]:.3g} m from {where} (tolerance {tolerance_m:.3g} "
            "m): is the mesh's unit right?",
            key="site_m",
            value=site.tolist(),
        )
    return closest[nearest]


def footprint_normal(
    mesh: TetMesh, site_m: Sequence[float], *, radius_m: float, surface: str | None = None
) -> np.ndarray:
    """The inward unit normal of the boundary averaged over the probe's footprint.

    The area-weighted mean of the inward normals of the boundary triangles that come within
    ``radius_m`` of ``site_m`` (the nearest triangle where none does, or ``radius_m`` is 0).

    Args:
        mesh: The specimen, m.
        site_m: A point on the surface, (3,), m.
        radius_m: The footprint's radius, m (>= 0).
        surface: Node set whose boundary triangles count; None: all of them.

    Returns:
        The inward unit normal, (3,).

    Raises:
        InputError: The footprint's normals cancel (the site on an edge of a thin sheet).
    """
    triangles = surface_triangles(mesh, surface=surface)
    _, distance = closest_surface_points(mesh.points, triangles, site_m)
    near = distance <= radius_m
    if not near.any():
        near = distance == distance.min()
    a, b, c = (mesh.points[triangles[near, i]] for i in range(3))
    area_normal = 0.5 * np.cross(b - a, c - a).sum(axis=0)  # outward, area weighted
    norm = float(np.linalg.norm(area_normal))
    if not (math.isfinite(norm) and norm > 0.0):
        raise InputError(
            "the surface normals under the probe cancel: give the direction", key="direction"
        )
    return -area_normal / norm
