"""Local refinement of a specimen mesh around the sites a probe indents.

The boundary surface is refined around each site by longest-edge bisection (Rivara's
conforming bisection along the longest-edge propagation path, so no triangle is left with a
hanging node and the smallest angle stays bounded), to a size that grows with the distance
from the site; TetGen then fills the refined surface with quality tets, which grade the
interior from the small surface triangles. Node sets of the surface travel with it (a
midpoint belongs to a set where both ends of its edge do); node sets inside the body, and the
file's tets, do not: the mesh is made again.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from warptissue.errors import InputError
from warptissue.mesh.core import TetMesh, boundary_faces
from warptissue.mesh.surface import tetrahedralize_surface

GRADING = 0.3
"""How fast the target surface size grows away from a refined zone: by this many metres per
metre of distance beyond it (a size ratio of about 1.3 from one element to the next)."""


def refine_near_sites(
    mesh: TetMesh,
    *,
    sites_m: Sequence[Sequence[float]],
    zone_radii_m: Sequence[float],
    sizes_m: Sequence[float],
    grading: float = GRADING,
    quality: float = 1.5,
) -> TetMesh:
    """A TET4 mesh of the same body, refined around each site.

    Within ``zone_radii_m[k]`` of site k the surface triangles are bisected until their
    longest edge is at most ``sizes_m[k]``; beyond it the size allowed grows by ``grading``
    per metre of distance, up to the mesh's own. TetGen fills the refined surface
    (:func:`warptissue.mesh.tetrahedralize_surface`, radius-edge ratio ``quality``), which
    grades the tets inside from the surface's sizes.

    Args:
        mesh: A mesh of one closed body (TET4 or TET10: its corner nodes are used).
        sites_m: The sites on its surface, each (3,), m.
        zone_radii_m: Radius of the refined zone around each site, m.
        sizes_m: Largest surface edge within each zone, m.
        grading: Growth of the size allowed with the distance beyond a zone (m per m).
        quality: TetGen's largest radius-edge ratio.

    Returns:
        A positively oriented TET4 mesh with node set ``"surface"`` and every node set of
        ``mesh`` that lies on its surface (as node and face sets), its surface the same
        surface, subdivided.

    Raises:
        InputError: Sites, radii and sizes of different counts or not positive, or a mesh
            of several material regions (they would be lost).
    """
    sites = np.asarray(sites_m, dtype=np.float64).reshape(-1, 3)
    radii = np.asarray(zone_radii_m, dtype=np.float64).ravel()
    sizes = np.asarray(sizes_m, dtype=np.float64).ravel()
    if not (len(sites) == radii.size == sizes.size) or len(sites) == 0:
        raise InputError(
            f"one zone radius and one size per site: {len(sites)} sites, {radii.size} radii, "
            f"{sizes.size} sizes",
            key="sites_m",
        )
    if not (np.all(radii > 0) and np.all(sizes > 0) and grading > 0):
        raise InputError(
            "zone radii, sizes and the grading must be positive",
            key="sizes_m",
            value=[radii.tolist(), sizes.tolist(), grading],
        )
    if np.unique(mesh.tet_regions).size > 1:
        raise InputError(
            "a mesh of several material regions cannot be refined around a site (the "
            "regions would be lost): give the mesh refined",
            key="tet_regions",
            value=int(np.unique(mesh.tet_regions).size),
        )
    faces = boundary_faces(mesh.tets[:, :4])
    corners = np.unique(faces)
    renumber = np.full(mesh.node_count, -1, dtype=np.int64)
    renumber[corners] = np.arange(corners.size)
    points = mesh.points[corners]
    triangles = renumber[faces]
    member = {
        name: np.isin(corners, nodes)
        for name, nodes in mesh.node_sets.items()
        if name != "surface" and np.isin(corners, nodes).any()
    }
    points, triangles, member = _bisect_near(
        points, triangles, member, sites=sites, radii=radii, sizes=sizes, grading=grading
    )
    surface_sets = {}
    for name, inside in member.items():
        named = np.flatnonzero(inside[triangles].all(axis=1))
        if named.size:
            surface_sets[name] = named
    return tetrahedralize_surface(
        points, triangles, quality=quality, surface_sets=_disjoint(surface_sets)
    )


def _disjoint(sets: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """TetGen's face markers are one per triangle: a triangle in several sets stays in the
    first (the others keep their nodes through it only where they are disjoint)."""
    taken: set[int] = set()
    kept = {}
    for name, indices in sets.items():
        free = np.array([i for i in indices.tolist() if i not in taken], dtype=np.int64)
        taken.update(free.tolist())
        if free.size:
            kept[name] = free
    return kept


def _bisect_near(
    points: np.ndarray,
    triangles: np.ndarray,
    member: dict[str, np.ndarray],
    *,
    sites: np.ndarray,
    radii: np.ndarray,
    sizes: np.ndarray,
    grading: float,
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Rivara's longest-edge bisection of a closed triangle surface until every triangle is
    no longer than the size allowed where it lies."""
    vertices = [tuple(p) for p in points]
    sets = {name: list(inside) for name, inside in member.items()}
    tris: list[list[int] | None] = [list(map(int, t)) for t in triangles]
    edges: dict[tuple[int, int], set[int]] = {}
    for t, tri in enumerate(tris):
        for a, b in _edges(tri):
            edges.setdefault((min(a, b), max(a, b)), set()).add(t)

    def length(edge: tuple[int, int]) -> float:
        a, b = edge
        return float(np.linalg.norm(np.subtract(vertices[a], vertices[b])))

    def longest(t: int) -> tuple[int, int]:
        tri = tris[t]
        assert tri is not None
        return max(((min(a, b), max(a, b)) for a, b in _edges(tri)), key=lambda e: (length(e), e))

    def allowed(t: int) -> float:
        tri = tris[t]
        assert tri is not None
        corner = np.asarray([vertices[v] for v in tri])
        centre = corner.mean(axis=0)
        reach = float(np.max(np.linalg.norm(corner - centre, axis=1)))
        distance = np.maximum(np.linalg.norm(sites - centre, axis=1) - reach - radii, 0.0)
        return float(np.min(sizes + grading * distance))

    def bisect(edge: tuple[int, int]) -> None:
        a, b = edge
        middle = len(vertices)
        vertices.append(tuple((np.asarray(vertices[a]) + np.asarray(vertices[b])) / 2.0))
        for inside in sets.values():
            inside.append(bool(inside[a] and inside[b]))
        for t in list(edges.pop(edge)):
            tri = tris[t]
            assert tri is not None
            i = next(k for k in range(3) if {tri[k], tri[(k + 1) % 3]} == {a, b})
            first, second, apex = tri[i], tri[(i + 1) % 3], tri[(i + 2) % 3]
            for u, v in _edges(tri):
                key = (min(u, v), max(u, v))
                if key in edges:
                    edges[key].discard(t)
            tris[t] = None
            for child in ([first, middle, apex], [middle, second, apex]):
                tris.append(child)
                for u, v in _edges(child):
                    edges.setdefault((min(u, v), max(u, v)), set()).add(len(tris) - 1)

    queue = list(range(len(tris)))
    while queue:
        t = queue.pop()
        if tris[t] is None or length(longest(t)) <= allowed(t):
            continue
        # Follow the longest-edge propagation path to the pair sharing its longest edge.
        path = [t]
        while True:
            edge = longest(path[-1])
            other = next(s for s in edges[edge] if s != path[-1])
            if longest(other) == edge:
                break
            path.append(other)
        before = len(tris)
        bisect(edge)
        queue.extend(range(before, len(tris)))
        if tris[t] is not None:
            queue.append(t)
    kept = np.array([tri for tri in tris if tri is not None], dtype=np.int64)
    return (
        np.asarray(vertices, dtype=np.float64),
        kept,
        {name: np.asarray(inside, dtype=bool) for name, inside in sets.items()},
    )


def _edges(tri: Sequence[int]) -> tuple[tuple[int, int], ...]:
    return ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0]))
