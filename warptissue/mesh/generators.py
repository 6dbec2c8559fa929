"""Structured tetrahedral mesh generators."""

from __future__ import annotations

import numpy as np

from warptissue.errors import MeshError
from warptissue.mesh.core import TetMesh, signed_volumes

__all__ = ["HEX_TO_FIVE_TETS", "HEX_TO_SIX_TETS", "block_mesh", "graded_coordinates"]

# Hexahedron corners: 0 (0,0,0), 1 (1,0,0), 2 (1,1,0), 3 (0,1,0), 4 (0,0,1), 5 (1,0,1),
# 6 (1,1,1), 7 (0,1,1).
HEX_TO_SIX_TETS: np.ndarray = np.array(
    [[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]],
    dtype=np.int32,
)
"""Kuhn split along the 0-6 diagonal: conforming when every cell is split the same way."""

HEX_TO_FIVE_TETS: np.ndarray = np.array(
    [
        [[1, 3, 4, 6], [0, 1, 3, 4], [2, 3, 1, 6], [5, 4, 6, 1], [7, 6, 4, 3]],
        [[0, 2, 5, 7], [1, 0, 2, 5], [3, 2, 0, 7], [4, 5, 7, 0], [6, 7, 5, 2]],
    ],
    dtype=np.int32,
)
"""Five-tet splits (seed 002): a central tet and four corners. Cells alternate between the
two mirror splits by the parity of i + j + k, which makes neighbouring face diagonals match."""


def graded_coordinates(length_m: float, count: int, *, ratio: float = 1.0) -> np.ndarray:
    """Coordinates from 0 to ``length_m`` in ``count`` intervals, graded geometrically.

    Args:
        length_m: Total length, metres.
        count: Number of intervals (>= 1).
        ratio: Size of the last interval over the first. 1 is uniform; < 1 refines toward
            ``length_m``, > 1 toward 0.

    Returns:
        Increasing coordinates, shape (count + 1,), float64.
    """
    if count < 1:
        raise MeshError(f"need at least one interval, got count={count}")
    if not length_m > 0:
        raise MeshError(f"length must be positive, got {length_m} m")
    if not ratio > 0:
        raise MeshError(f"grading ratio must be positive, got {ratio}")
    if count == 1 or ratio == 1.0:
        sizes = np.ones(count)
    else:
        sizes = ratio ** (np.arange(count) / (count - 1))
    return np.concatenate([[0.0], np.cumsum(sizes) / sizes.sum() * length_m])


def block_mesh(
    x_m: np.ndarray,
    y_m: np.ndarray,
    z_m: np.ndarray,
    *,
    split: str = "six",
) -> TetMesh:
    """A box meshed with hexahedral cells split into tetrahedra.

    Node sets ``xmin``, ``xmax``, ``ymin``, ``ymax``, ``zmin``, ``zmax`` hold the nodes on each
    face of the box, and face sets of the same names hold the boundary triangles there.
    ``tet_regions`` holds the index of the hexahedral cell each tet came from
    (i + nx * (j + ny * k)), so that per-cell parameters (seed 002) can be grouped.

    Args:
        x_m: Increasing x coordinates of the grid planes, shape (nx + 1,), metres.
        y_m: Increasing y coordinates, shape (ny + 1,).
        z_m: Increasing z coordinates, shape (nz + 1,).
        split: ``"six"`` (Kuhn) or ``"five"`` (seed 002, alternating).

    Returns:
        A positively oriented TET4 mesh.
    """
    axes = [np.asarray(a, dtype=np.float64) for a in (x_m, y_m, z_m)]
    for name, a in zip("xyz", axes, strict=True):
        if a.ndim != 1 or len(a) < 2 or np.any(np.diff(a) <= 0):
            raise MeshError(
                f"{name}_m must be at least two strictly increasing coordinates, got {a}"
            )
    if split not in ("five", "six"):
        raise MeshError(f"split must be 'five' or 'six', got {split!r}")
    nx, ny, nz = (len(a) - 1 for a in axes)
    gx, gy, gz = np.meshgrid(*axes, indexing="ij")
    points = np.column_stack([gx.ravel(order="F"), gy.ravel(order="F"), gz.ravel(order="F")])

    def node(i: np.ndarray, j: np.ndarray, k: np.ndarray) -> np.ndarray:
        return i + (nx + 1) * (j + (ny + 1) * k)

    ci, cj, ck = (
        c.ravel(order="F")
        for c in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    )
    offsets = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    )
    hexes = np.stack([node(ci + o[0], cj + o[1], ck + o[2]) for o in offsets], axis=1)
    cell_index = np.arange(len(hexes), dtype=np.int32)
    if split == "six":
        tets = hexes[:, HEX_TO_SIX_TETS].reshape(-1, 4)
        regions = np.repeat(cell_index, 6)
    else:
        parity = (ci + cj + ck) % 2
        tets = np.take_along_axis(
            hexes[:, None, :], HEX_TO_FIVE_TETS[parity].reshape(len(hexes), 1, 20), axis=2
        )
        tets = tets.reshape(-1, 4)
        regions = np.repeat(cell_index, 5)
    tets = tets.astype(np.int32)
    negative = signed_volumes(points, tets) < 0
    tets[negative, 1], tets[negative, 2] = tets[negative, 2].copy(), tets[negative, 1].copy()

    node_sets, face_sets = {}, {}
    faces = _boundary_faces(tets)
    for axis, label in enumerate("xyz"):
        for side, value in (("min", axes[axis][0]), ("max", axes[axis][-1])):
            on_plane = np.isclose(
                points[:, axis], value, rtol=0.0, atol=1e-12 * max(1.0, abs(value))
            )
            node_sets[f"{label}{side}"] = np.flatnonzero(on_plane).astype(np.int32)
            face_sets[f"{label}{side}"] = faces[on_plane[faces].all(axis=1)]
    return TetMesh(
        points=points, tets=tets, node_sets=node_sets, face_sets=face_sets, tet_regions=regions
    )


def _boundary_faces(tets: np.ndarray) -> np.ndarray:
    """Triangles that belong to exactly one tet, oriented with outward normals."""
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    faces = tets[:, local].reshape(-1, 3)
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return faces[counts[inverse.ravel()] == 1].astype(np.int32)
