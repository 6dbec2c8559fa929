"""The tetrahedral mesh container."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from warptissue.errors import MeshError

__all__ = [
    "TET4_EDGES",
    "TET4_FACES",
    "TetMesh",
    "boundary_faces",
    "signed_volumes",
    "to_tet10",
    "unique_sorted_rows",
]

TET4_EDGES: np.ndarray = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]], dtype=np.int32)
"""Corner pairs of the six edges, in the order of TET10 mid-edge nodes 4..9 (VTK/meshio order)."""

TET4_FACES: np.ndarray = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int32)
"""Corner triples of the four faces (face i is opposite corner i), ordered so that the normal
points out of a positively oriented tet."""


@dataclass
class TetMesh:
    """A tetrahedral mesh in metres.

    Attributes:
        points: Node coordinates, shape (node_count, 3), float64, metres.
        tets: Connectivity, shape (tet_count, 4) for TET4 or (tet_count, 10) for TET10, int32.
            Corners 0-3 are positively oriented (positive signed volume); TET10 mid-edge
            nodes 4-9 sit on edges (0,1), (1,2), (0,2), (0,3), (1,3), (2,3).
        node_sets: Named node sets, name to node indices, shape (k,), int32.
        face_sets: Named boundary face sets, name to corner-node triangles, shape (k, 3), int32.
        tet_regions: Material region of each tet, shape (tet_count,), int32 (all 0 by default).
    """

    points: np.ndarray
    tets: np.ndarray
    node_sets: dict[str, np.ndarray] = field(default_factory=dict)
    face_sets: dict[str, np.ndarray] = field(default_factory=dict)
    tet_regions: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.points = np.ascontiguousarray(self.points, dtype=np.float64)
        self.tets = np.ascontiguousarray(self.tets, dtype=np.int32)
        if self.points.ndim != 2 or self.points.shape[1] != 3:
            raise MeshError(f"points must have shape (N, 3), got {self.points.shape}")
        if self.tets.ndim != 2 or self.tets.shape[1] not in (4, 10):
            raise MeshError(f"tets must have shape (M, 4) or (M, 10), got {self.tets.shape}")
        if not np.all(np.isfinite(self.points)):
            raise MeshError("points contain non-finite coordinates")
        if self.tets.size:
            low, high = int(self.tets.min()), int(self.tets.max())
            if low < 0 or high >= len(self.points):
                bad = int(
                    np.flatnonzero((self.tets < 0).any(1) | (self.tets >= len(self.points)).any(1))[
                        0
                    ]
                )
                raise MeshError(
                    f"node index out of range [0, {len(self.points)}): {self.tets[bad].tolist()}",
                    element=bad,
                )
        if self.tet_regions is None:
            self.tet_regions = np.zeros(len(self.tets), dtype=np.int32)
        self.tet_regions = np.ascontiguousarray(self.tet_regions, dtype=np.int32)
        if self.tet_regions.shape != (len(self.tets),):
            raise MeshError(
                f"tet_regions must have shape ({len(self.tets)},), got {self.tet_regions.shape}"
            )
        self.node_sets = {
            k: np.ascontiguousarray(v, dtype=np.int32) for k, v in self.node_sets.items()
        }
        self.face_sets = {
            k: np.ascontiguousarray(v, dtype=np.int32).reshape(-1, 3)
            for k, v in self.face_sets.items()
        }
        for name, nodes in self.node_sets.items():
            if nodes.size and (nodes.min() < 0 or nodes.max() >= len(self.points)):
                raise MeshError(f"node set {name!r} has indices outside [0, {len(self.points)})")

    @property
    def node_count(self) -> int:
        """Number of nodes."""
        return int(self.points.shape[0])

    @property
    def tet_count(self) -> int:
        """Number of tetrahedra."""
        return int(self.tets.shape[0])

    @property
    def nodes_per_tet(self) -> int:
        """4 for TET4, 10 for TET10."""
        return int(self.tets.shape[1])

    @property
    def element_type(self) -> str:
        """``"TET4"`` or ``"TET10"``."""
        return f"TET{self.nodes_per_tet}"

    @property
    def corner_tets(self) -> np.ndarray:
        """The corner connectivity, shape (tet_count, 4)."""
        return self.tets[:, :4]

    def volumes(self) -> np.ndarray:
        """Signed volumes of the straight-sided corner tetrahedra, shape (tet_count,), m^3."""
        return signed_volumes(self.points, self.corner_tets)

    def node_set(self, name: str) -> np.ndarray:
        """Return a named node set, with an error naming the sets that exist."""
        try:
            return self.node_sets[name]
        except KeyError:
            raise MeshError(
                f"no node set {name!r}; the mesh has {sorted(self.node_sets)}"
            ) from None


def signed_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes of tetrahedra from their four corners.

    Args:
        points: Node coordinates, shape (N, 3).
        tets: Corner connectivity, shape (M, 4) (extra columns are ignored).

    Returns:
        det[x1 - x0, x2 - x0, x3 - x0] / 6, shape (M,).
    """
    x = points[tets[:, :4]]
    edges = x[:, 1:] - x[:, :1]
    return np.einsum("ij,ij->i", edges[:, 0], np.cross(edges[:, 1], edges[:, 2])) / 6.0


def to_tet10(mesh: TetMesh) -> TetMesh:
    """Promote a TET4 mesh to straight-sided TET10 with mid-edge nodes.

    Node sets gain the mid-edge nodes of edges whose two corners are both in the set; face
    sets keep their corner triangles.

    Args:
        mesh: A TET4 mesh.

    Returns:
        A TET10 mesh that shares the corner nodes' indices with ``mesh``.
    """
    if mesh.nodes_per_tet == 10:
        return mesh
    corners = mesh.tets
    unique_edges, inverse = unique_sorted_rows(corners[:, TET4_EDGES].reshape(-1, 2))
    midpoints = 0.5 * (mesh.points[unique_edges[:, 0]] + mesh.points[unique_edges[:, 1]])
    mid_index = (mesh.node_count + inverse.reshape(-1, 6)).astype(np.int32)
    node_sets = {}
    for name, nodes in mesh.node_sets.items():
        member = np.zeros(mesh.node_count, dtype=bool)
        member[nodes] = True
        both = member[unique_edges[:, 0]] & member[unique_edges[:, 1]]
        node_sets[name] = np.concatenate([nodes, mesh.node_count + np.flatnonzero(both)])
    return TetMesh(
        points=np.vstack([mesh.points, midpoints]),
        tets=np.hstack([corners, mid_index]),
        node_sets=node_sets,
        face_sets=dict(mesh.face_sets),
        tet_regions=mesh.tet_regions.copy(),
    )


def boundary_faces(tets: np.ndarray) -> np.ndarray:
    """Corner triangles that belong to exactly one tet, oriented with outward normals.

    Args:
        tets: Positively oriented connectivity, shape (M, 4) or (M, 10) (corners are used).

    Returns:
        Boundary triangles, shape (k, 3), int32, in the order of the tets they come from.
    """
    faces = np.asarray(tets)[:, :4][:, TET4_FACES].reshape(-1, 3)
    _, inverse, counts = unique_sorted_rows(faces, return_counts=True)
    return faces[counts[inverse] == 1].astype(np.int32)


def unique_sorted_rows(rows: np.ndarray, *, return_counts: bool = False) -> tuple[np.ndarray, ...]:
    """Unique rows of small non-negative integers, ignoring the order within a row.

    Rows are sorted and packed into one int64 key when that cannot overflow, which is several
    times faster than ``np.unique(axis=0)`` for the millions of edges and faces of large meshes.

    Args:
        rows: Integer array, shape (k, w).
        return_counts: Also return how often each unique row occurs.

    Returns:
        ``(unique_rows (u, w), inverse (k,))`` and, when asked, ``counts (u,)``.
    """
    key_rows = np.sort(np.asarray(rows, dtype=np.int64), axis=1)
    width = key_rows.shape[1]
    base = int(key_rows.max()) + 1 if key_rows.size else 1
    if base**width < 2**62:
        key = np.zeros(len(key_rows), dtype=np.int64)
        for column in range(width):
            key = key * base + key_rows[:, column]
        _, first, inverse, counts = np.unique(
            key, return_index=True, return_inverse=True, return_counts=True
        )
        unique_rows = key_rows[first]
    else:
        unique_rows, inverse, counts = np.unique(
            key_rows, axis=0, return_inverse=True, return_counts=True
        )
    inverse = inverse.reshape(-1)
    if return_counts:
        return unique_rows, inverse, counts
    return unique_rows, inverse
