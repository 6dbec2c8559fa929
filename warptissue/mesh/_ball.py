"""An elastic ball meshed finer around one pole: the organ-shaped specimen of the Hertz
ball-on-ball check (issue 34) and a closed curved body for probes at any site.

The surface is rings of points at polar angles graded from ``pole_size_m`` at the top pole
(+z) to ``far_size_m``, triangulated as their convex hull (every point of a sphere is a
vertex of the hull); TetGen fills it with quality tetrahedra, whose size follows the
surface's. TET10 mid-edge nodes on the boundary are moved onto the sphere, so that the
quadratic faces follow its curvature, each only as far as the elements' Jacobians stay
positive (a flat tet against the surface would otherwise invert), so that the mesh passes
:func:`warptissue.mesh.check_mesh` for every size it accepts.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from warptissue.errors import InputError
from warptissue.mesh.core import TET4_EDGES, TetMesh, boundary_faces, to_tet10
from warptissue.mesh.quality import move_midnodes_keeping_jacobian
from warptissue.mesh.surface import tetrahedralize_surface


def ball_mesh(
    radius_m: float,
    *,
    pole_size_m: float,
    far_size_m: float,
    growth: float = 0.25,
    element: str = "TET10",
) -> TetMesh:
    """A ball of radius ``radius_m`` centred at the origin, meshed finer around (0, 0, R).

    Args:
        radius_m: The ball's radius R, m.
        pole_size_m: Element edge length at the top pole, m.
        far_size_m: Largest element edge length, m.
        growth: How fast the surface's element size grows with the arc length s from the
            pole: h(s) = min(far, pole + growth s) (0.25: a quarter of a metre per metre).
        element: ``"TET10"`` (boundary mid-edge nodes on the sphere, or as near it as the
            element's Jacobian allows) or ``"TET4"``.

    Returns:
        The mesh, with node sets ``"surface"``, ``"top"`` (the surface with z >= 0, the
        indented half) and ``"bottom"`` (the surface with z < 0, the half a support holds).

    Raises:
        InputError: A size that is not positive, a pole size above the far size, a growth
            that is not positive, or an unknown element.
    """
    if not (radius_m > 0 and pole_size_m > 0 and far_size_m >= pole_size_m and growth > 0):
        raise InputError(
            "need radius_m > 0, 0 < pole_size_m <= far_size_m and growth > 0",
            value=(radius_m, pole_size_m, far_size_m, growth),
        )
    if element not in ("TET4", "TET10"):
        raise InputError("element must be 'TET4' or 'TET10'", key="element", value=element)
    points = _graded_sphere_points(radius_m, pole_size_m, far_size_m, growth)
    triangles = ConvexHull(points).simplices
    mesh = tetrahedralize_surface(points, triangles, quality=1.4)
    faces = boundary_faces(mesh.tets)
    if element == "TET10":
        mesh = to_tet10(mesh)
        _midnodes_onto_sphere(mesh, faces, radius_m)
    surface = _face_nodes(mesh, faces)
    z = mesh.points[surface, 2]
    mesh.node_sets["surface"] = surface.astype(np.int32)
    mesh.node_sets["top"] = surface[z >= 0.0].astype(np.int32)
    mesh.node_sets["bottom"] = surface[z < 0.0].astype(np.int32)
    return mesh


def _graded_sphere_points(
    radius_m: float, pole_size_m: float, far_size_m: float, growth: float
) -> np.ndarray:
    """Rings of points at arc lengths s from the top pole, spaced by h(s), each ring holding
    about 2 pi rho / h(s) points (rho its radius), alternate rings turned half a step."""

    def size_at(arc: float) -> float:
        return min(far_size_m, pole_size_m + growth * arc)

    half_circle = np.pi * radius_m
    arcs = [0.0]
    while arcs[-1] + 1.5 * size_at(arcs[-1]) < half_circle:
        arcs.append(arcs[-1] + size_at(arcs[-1]))
    # Stretch the rings evenly so that the bottom pole is one step past the last one.
    arcs = np.asarray(arcs) * half_circle / (arcs[-1] + size_at(arcs[-1]))
    rings = [np.array([[0.0, 0.0, radius_m]])]
    for k, arc in enumerate(arcs[1:], start=1):
        theta = arc / radius_m
        rho = radius_m * np.sin(theta)
        size = size_at(arc)
        count = max(3, int(round(2.0 * np.pi * rho / size)))
        phi = 2.0 * np.pi * (np.arange(count) + 0.5 * (k % 2)) / count
        rings.append(
            np.column_stack(
                [rho * np.cos(phi), rho * np.sin(phi), np.full(count, radius_m * np.cos(theta))]
            )
        )
    rings.append(np.array([[0.0, 0.0, -radius_m]]))
    return np.vstack(rings)


def _face_nodes(mesh: TetMesh, faces: np.ndarray) -> np.ndarray:
    """The corner and (TET10) mid-edge nodes of the boundary triangles ``faces``."""
    nodes = [np.unique(faces)]
    if mesh.nodes_per_tet == 10:
        nodes.append(_boundary_midnodes(mesh, faces))
    return np.unique(np.concatenate(nodes))


def _boundary_midnodes(mesh: TetMesh, faces: np.ndarray) -> np.ndarray:
    """The mid-edge nodes of the boundary triangles' edges (not of interior chords between
    two boundary corners, which a node set's rule in :func:`to_tet10` would include)."""
    edges = np.sort(faces[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    on_boundary = {tuple(edge) for edge in edges.tolist()}
    tet_edges = np.sort(mesh.tets[:, TET4_EDGES], axis=2).reshape(-1, 2)
    midnodes = mesh.tets[:, 4:10].reshape(-1)
    keep = np.fromiter((tuple(edge) in on_boundary for edge in tet_edges.tolist()), bool)
    return np.unique(midnodes[keep])


def _midnodes_onto_sphere(mesh: TetMesh, faces: np.ndarray, radius_m: float) -> None:
    """Move the boundary mid-edge nodes radially onto the sphere (the corners are on it), each
    only as far as its elements' Jacobians stay positive."""
    nodes = _boundary_midnodes(mesh, faces)
    points = mesh.points[nodes]
    targets = radius_m * points / np.linalg.norm(points, axis=1, keepdims=True)
    move_midnodes_keeping_jacobian(mesh, nodes, targets)
