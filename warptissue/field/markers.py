"""Surface markers: reading them, a hexahedral mesh from their grid, and interpolation.

Marker file (CSV, header row, SI units), one row per marker and load set::

    load_set,marker,x0_m,y0_m,z0_m,x1_m,y1_m,z1_m

``x0_m, y0_m, z0_m`` is the marker before loading and ``x1_m, y1_m, z1_m`` after it; the
displacement is their difference. ``load_set`` (any label, for example ``A``) is optional;
without it the file holds one load set named ``A``. Every load set must list the same markers.

Force file (CSV)::

    load_set,marker,fx_N,fy_N,fz_N

The force applied at a marker (which must sit on a mesh node) for a load set. ``load_set`` is
optional as above.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from warptissue.errors import InputError, MeshError
from warptissue.io import csv_number, read_csv_rows
from warptissue.mesh import TetMesh, block_mesh

__all__ = [
    "MarkerData",
    "MarkerGrid",
    "grid_from_markers",
    "read_forces_csv",
    "read_markers_csv",
    "surface_interpolation",
]

MARKER_COLUMNS: tuple[str, ...] = ("marker", "x0_m", "y0_m", "z0_m", "x1_m", "y1_m", "z1_m")
FORCE_COLUMNS: tuple[str, ...] = ("marker", "fx_N", "fy_N", "fz_N")


@dataclass(frozen=True)
class MarkerData:
    """Marker positions for one or more load sets.

    Attributes:
        load_sets: Load-set labels, in file order, shape (S,).
        markers: Marker labels, shape (k,).
        reference_m: Positions before loading, shape (k, 3), metres.
        displacement_m: Displacements per load set, shape (S, k, 3), metres.
    """

    load_sets: tuple[str, ...]
    markers: tuple[str, ...]
    reference_m: np.ndarray
    displacement_m: np.ndarray


def _read_rows(path: str | Path, required: tuple[str, ...]) -> list[tuple[int, dict[str, str]]]:
    rows = read_csv_rows(path, required=required)
    if not rows:
        raise InputError("no data rows", path=Path(path), line=2)
    return rows


def read_markers_csv(path: str | Path) -> MarkerData:
    """Read a marker file (format in the module docstring).

    Raises:
        InputError: Missing columns, a non-numeric value (with file, line and column), a
            duplicated marker, or load sets that list different markers.
    """
    rows = _read_rows(path, MARKER_COLUMNS)
    sets: dict[str, dict[str, tuple[int, np.ndarray]]] = {}
    for line, row in rows:
        label = (row.get("load_set") or "A").strip() or "A"
        marker = (row.get("marker") or "").strip()
        if not marker:
            raise InputError("empty marker label", path=path, line=line, column="marker")
        values = np.array([csv_number(path, line, row, c) for c in MARKER_COLUMNS[1:]])
        entries = sets.setdefault(label, {})
        if marker in entries:
            raise InputError(
                f"marker {marker!r} appears twice in load set {label!r}",
                path=path,
                line=line,
                column="marker",
                value=marker,
            )
        entries[marker] = (line, values)
    labels = tuple(sets)
    markers = tuple(sets[labels[0]])
    for label in labels[1:]:
        if set(sets[label]) != set(markers):
            extra = sorted(set(sets[label]) ^ set(markers))[:5]
            raise InputError(
                f"load set {label!r} lists different markers than {labels[0]!r} ({extra} ...)",
                path=path,
            )
    reference = np.array([sets[labels[0]][m][1][:3] for m in markers])
    for label in labels[1:]:
        for marker in markers:
            line, values = sets[label][marker]
            if not np.allclose(values[:3], reference[markers.index(marker)], atol=1e-9):
                raise InputError(
                    f"marker {marker!r} has a different reference position than in load set "
                    f"{labels[0]!r}",
                    path=path,
                    line=line,
                    column="x0_m",
                )
    displacement = np.array(
        [[sets[label][m][1][3:] - sets[label][m][1][:3] for m in markers] for label in labels]
    )
    return MarkerData(labels, markers, reference, displacement)


def read_forces_csv(path: str | Path) -> dict[str, dict[str, np.ndarray]]:
    """Read a force file: ``{load_set: {marker: force (3,) in N}}``.

    Raises:
        InputError: Missing columns, non-numeric values, an empty marker label, or a marker
            listed twice in one load set, with file, line and column.
    """
    forces: dict[str, dict[str, np.ndarray]] = {}
    for line, row in _read_rows(path, FORCE_COLUMNS):
        label = (row.get("load_set") or "A").strip() or "A"
        marker = (row.get("marker") or "").strip()
        if not marker:
            raise InputError("empty marker label", path=path, line=line, column="marker")
        vector = np.array([csv_number(path, line, row, c) for c in FORCE_COLUMNS[1:]])
        entries = forces.setdefault(label, {})
        if marker in entries:
            raise InputError(
                f"marker {marker!r} has two forces in load set {label!r}; give one row per "
                "marker (the sum of its forces)",
                path=path,
                line=line,
                column="marker",
            )
        entries[marker] = vector
    return forces


@dataclass(frozen=True)
class MarkerGrid:
    """A block mesh built on the grid lines of surface markers.

    Attributes:
        mesh: TET4 mesh, hexahedra split into 5 tets; ``tet_regions`` = hexahedron index.
        x_m, y_m, z_m: Grid-plane coordinates, shapes (nx + 1,), (ny + 1,), (nz + 1,).
        top_nodes: Nodes of the top face in (i, j) order, shape (ny + 1, nx + 1).
    """

    mesh: TetMesh
    x_m: np.ndarray
    y_m: np.ndarray
    z_m: np.ndarray
    top_nodes: np.ndarray

    @property
    def hex_shape(self) -> tuple[int, int, int]:
        """Number of hexahedra along x, y and z."""
        return len(self.x_m) - 1, len(self.y_m) - 1, len(self.z_m) - 1

    def node_index(self, i: np.ndarray, j: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Node index of grid point (i, j, k), as numbered by ``block_mesh``."""
        nx, ny, _ = self.hex_shape
        return i + (nx + 1) * (j + (ny + 1) * k)


MAX_CELL_ASPECT = 50.0
"""Largest ratio of a cell's marker spacing to its layer thickness (or the inverse) accepted
by :func:`grid_from_markers`; flatter cells come from a wrong unit or thickness."""


def _length(value_m: float) -> str:
    """A length for messages, in metres with 3 significant digits."""
    return f"{value_m:.3g} m"


def _cluster(values: np.ndarray, tolerance: float) -> np.ndarray:
    ordered = np.sort(values)
    breaks = np.flatnonzero(np.diff(ordered) > tolerance) + 1
    return np.array([group.mean() for group in np.split(ordered, breaks)])


def grid_from_markers(
    reference_m: np.ndarray,
    *,
    thickness_m: float,
    layers: int = 1,
    tolerance_m: float | None = None,
) -> MarkerGrid:
    """Build the hexahedral (5-tet) mesh of Tong et al. from the markers' grid.

    The markers lie on the top face z = mean(z0) of a block whose base (z = top -
    thickness_m) is fixed. Marker x and y coordinates are clustered into grid lines
    (coordinates closer than ``tolerance_m`` belong to one line).

    Args:
        reference_m: Marker positions before loading, shape (k, 3), metres.
        thickness_m: Block thickness, metres.
        layers: Hexahedra through the thickness.
        tolerance_m: Clustering tolerance; default a quarter of the smallest marker spacing.

    Returns:
        The grid and its mesh.

    Raises:
        InputError: Fewer than 2 grid lines along x or y, bad thickness or layers, or cells
            flatter (or taller) than an aspect ratio of :data:`MAX_CELL_ASPECT`.
    """
    reference_m = np.asarray(reference_m, dtype=np.float64)
    if not thickness_m > 0 or layers < 1:
        raise InputError(f"need thickness_m > 0 and layers >= 1, got {thickness_m}, {layers}")
    if tolerance_m is None:
        spans = [np.diff(np.unique(np.round(reference_m[:, a], 9))) for a in (0, 1)]
        spacing = min(float(s[s > 0].max(initial=0.0)) for s in spans)
        tolerance_m = 0.25 * spacing if spacing > 0 else 1e-6
    x_m = _cluster(reference_m[:, 0], tolerance_m)
    y_m = _cluster(reference_m[:, 1], tolerance_m)
    if len(x_m) < 2 or len(y_m) < 2:
        raise InputError(
            f"the markers lie on {len(x_m)} x {len(y_m)} grid lines (x by y); a block needs "
            "at least 2 x 2"
        )
    spacing = min(float(np.diff(x_m).min()), float(np.diff(y_m).min()))
    span = max(float(np.ptp(x_m)), float(np.ptp(y_m)))
    layer = thickness_m / layers
    aspect = max(spacing / layer, layer / spacing)
    if aspect > MAX_CELL_ASPECT:
        raise InputError(
            f"the cells would be {_length(spacing)} across and {_length(layer)} thick "
            f"(aspect ratio {aspect:.0f}, at most {MAX_CELL_ASPECT:.0f}) for markers spanning "
            f"{_length(span)}: check --thickness-m and --layers, and that the marker "
            "coordinates are in metres"
        )
    top = float(reference_m[:, 2].mean())
    z_m = np.linspace(top - thickness_m, top, layers + 1)
    try:
        mesh = block_mesh(x_m, y_m, z_m, split="five")
    except MeshError as exc:
        raise InputError(f"cannot build the marker grid mesh: {exc}") from exc
    nx, ny = len(x_m) - 1, len(y_m) - 1
    j, i = np.meshgrid(np.arange(ny + 1), np.arange(nx + 1), indexing="ij")
    top_nodes = i + (nx + 1) * (j + (ny + 1) * layers)
    return MarkerGrid(mesh, x_m, y_m, z_m, top_nodes)


def surface_interpolation(
    mesh: TetMesh, positions_m: np.ndarray, *, face_set: str = "zmax"
) -> sp.csr_matrix:
    """Barycentric interpolation from mesh nodes to points on a planar face set.

    Each point is projected along z onto the face set's plane and located in a triangle;
    its row holds the triangle's three barycentric weights.

    Args:
        mesh: The mesh.
        positions_m: Points, shape (k, 3), metres (only x and y are used).
        face_set: Name of a planar face set normal to z.

    Returns:
        Interpolation matrix, shape (k, node_count): values_at_points = P @ nodal_values.

    Raises:
        InputError: A point lies outside the face set.
    """
    triangles = mesh.face_sets.get(face_set)
    if triangles is None or len(triangles) == 0:
        raise InputError(f"mesh has no face set {face_set!r}")
    xy = mesh.points[:, :2]
    a, b, c = xy[triangles[:, 0]], xy[triangles[:, 1]], xy[triangles[:, 2]]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    points = np.asarray(positions_m, dtype=np.float64)[:, :2]
    rows, cols, weights = [], [], []
    for index, p in enumerate(points):
        w1 = ((p[0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (p[1] - a[:, 1])) / det
        w2 = ((b[:, 0] - a[:, 0]) * (p[1] - a[:, 1]) - (p[0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
        w0 = 1.0 - w1 - w2
        margin = np.minimum(np.minimum(w0, w1), w2)
        best = int(np.argmax(margin))
        if margin[best] < -1e-9:
            raise InputError(
                f"point {index} at ({p[0]:.6g}, {p[1]:.6g}) m lies outside face set {face_set!r}",
                value=p.tolist(),
            )
        rows += [index] * 3
        cols += triangles[best].tolist()
        weights += [w0[best], w1[best], w2[best]]
    return sp.csr_matrix((weights, (rows, cols)), shape=(len(points), mesh.node_count))
