"""Tetrahedralization of closed triangle surfaces with TetGen (the ``tetgen`` package)."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import tetgen

from warptissue.errors import InputError, MeshError
from warptissue.mesh._usd import USD_SUFFIXES, read_usd_surface
from warptissue.mesh.core import TetMesh, boundary_faces
from warptissue.mesh.quality import fix_orientation

__all__ = [
    "SURFACE_SUFFIXES",
    "check_closed_surface",
    "fill_surface_file",
    "tetrahedralize_surface",
]

SURFACE_SUFFIXES: tuple[str, ...] = (".stl", ".obj", ".ply")
"""The closed triangle surface files :func:`fill_surface_file` reads."""


def check_closed_surface(vertices_m: np.ndarray, triangles: np.ndarray) -> None:
    """Check that triangles form a closed (watertight, manifold) surface.

    Every edge must be shared by exactly two triangles, and no triangle may be degenerate.

    Args:
        vertices_m: Surface vertices, shape (V, 3), metres.
        triangles: Vertex indices, shape (F, 3).

    Raises:
        InputError: Bad shapes or indices, a degenerate triangle, or an edge used by one
            triangle (a hole) or by more than two (non-manifold); the message names the edge
            or triangle.
    """
    vertices = np.asarray(vertices_m, dtype=np.float64)
    faces = np.asarray(triangles)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or not np.all(np.isfinite(vertices)):
        raise InputError(f"vertices must be finite, shape (V, 3); got shape {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) < 4:
        raise InputError(f"triangles must have shape (F >= 4, 3); got shape {faces.shape}")
    if not np.issubdtype(faces.dtype, np.integer):
        raise InputError(f"triangles must hold integer indices, got dtype {faces.dtype}")
    if faces.min() < 0 or faces.max() >= len(vertices):
        bad = int(np.flatnonzero((faces < 0).any(1) | (faces >= len(vertices)).any(1))[0])
        raise InputError(
            f"triangle {bad} indexes a vertex outside [0, {len(vertices)})",
            value=faces[bad].tolist(),
        )
    corners = vertices[faces]
    doubled_area = np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    scale = np.ptp(vertices, axis=0).max()
    flat = np.flatnonzero(doubled_area <= 1e-12 * scale**2)
    if flat.size:
        raise InputError(
            f"triangle {int(flat[0])} is degenerate (zero area)", value=faces[flat[0]].tolist()
        )
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique_edges, counts = np.unique(edges, axis=0, return_counts=True)
    bad = np.flatnonzero(counts != 2)
    if bad.size:
        edge, count = unique_edges[bad[0]], int(counts[bad[0]])
        kind = "an open boundary (hole)" if count == 1 else "non-manifold"
        raise InputError(
            f"surface is not closed: edge {edge.tolist()} belongs to {count} triangle(s), "
            f"{kind}; {bad.size} such edges in all",
            value=edge.tolist(),
        )


def tetrahedralize_surface(
    vertices_m: np.ndarray,
    triangles: np.ndarray,
    *,
    max_volume_m3: float | None = None,
    quality: float | None = 1.5,
    min_dihedral_deg: float = 10.0,
    surface_sets: Mapping[str, np.ndarray] | None = None,
) -> TetMesh:
    """Fill a closed triangle surface with tetrahedra (TetGen, constrained Delaunay).

    TetGen may split the input triangles (Steiner points on the surface), but it keeps every
    input vertex and, with ``surface_sets``, every edge between two named groups.

    Args:
        vertices_m: Surface vertices, shape (V, 3), metres.
        triangles: Vertex indices of the surface triangles, shape (F, 3), either orientation.
        max_volume_m3: Largest tet volume, m^3 (TetGen ``-a``); None leaves it unbounded.
        quality: Largest radius-edge ratio (TetGen ``-q``; > 1, smaller is better, about 1.1
            is the practical limit); None turns quality refinement off.
        min_dihedral_deg: Dihedral angle TetGen tries to keep every tet above, degrees (a
            target, not a guarantee: slivers can remain next to the input surface). Used
            only with ``quality``.
        surface_sets: Named, disjoint groups of input triangles (indices into
            ``triangles``). Each becomes a face set of the boundary faces that fill its
            triangles and a node set of their nodes (a boundary condition's target).

    Returns:
        A positively oriented TET4 mesh. Input vertices keep their indices (TetGen appends
        any Steiner points after them). Node set and face set ``"surface"`` hold the boundary,
        and each of ``surface_sets`` has its own.

    Raises:
        InputError: The surface is not closed or is malformed (:func:`check_closed_surface`),
            an option is out of range, or a surface set indexes a triangle that does not
            exist or that another set already holds (the message names both).
        MeshError: TetGen fails (for example on a self-intersecting surface).
    """

    check_closed_surface(vertices_m, triangles)
    set_names = list(surface_sets or {})
    markers = _surface_markers(len(triangles), surface_sets or {})
    options: dict[str, object] = {"quality": quality is not None}
    if quality is not None:
        if not quality > 1.0:
            raise InputError("quality (radius-edge ratio) must exceed 1", value=quality)
        options["minratio"] = float(quality)
        options["mindihedral"] = float(min_dihedral_deg)
    if max_volume_m3 is not None:
        if not max_volume_m3 > 0:
            raise InputError("max_volume_m3 must be positive", value=max_volume_m3)
        options["fixedvolume"] = True
        options["maxvolume"] = float(max_volume_m3)
    generator = tetgen.TetGen(
        np.ascontiguousarray(vertices_m, dtype=np.float64),
        np.ascontiguousarray(triangles, dtype=np.int32),
        markers,
    )
    # TetGen writes the faces it finds crossing each other to _skipped.face/.node in the
    # working folder: removed again where this call made them.
    leftovers = [Path(name) for name in ("_skipped.face", "_skipped.node")]
    before = {path: path.exists() for path in leftovers}
    try:
        nodes, tets, _, face_markers = generator.tetrahedralize(**options)
    except RuntimeError as exc:
        raise MeshError(f"TetGen failed: {exc}") from exc
    finally:
        for path, existed in before.items():
            if not existed:
                path.unlink(missing_ok=True)
    if len(tets) == 0:
        raise MeshError("TetGen produced no tetrahedra (is the surface self-intersecting?)")
    mesh = fix_orientation(TetMesh(points=nodes, tets=tets))
    faces = boundary_faces(mesh.tets)
    mesh.node_sets["surface"] = np.unique(faces).astype(np.int32)
    mesh.face_sets["surface"] = faces
    if set_names:
        # TetGen's boundary faces carry their input triangle's marker; match them to the
        # outward-oriented boundary faces by their sorted corners.
        marker_of = dict(
            zip(map(tuple, np.sort(generator.trifaces, axis=1)), face_markers, strict=True)
        )
        face_marker = np.array([marker_of[tuple(face)] for face in np.sort(faces, axis=1)])
        for marker, name in enumerate(set_names, start=1):
            named = faces[face_marker == marker]
            mesh.face_sets[name] = named
            mesh.node_sets[name] = np.unique(named).astype(np.int32)
    return mesh


def _surface_markers(triangle_count: int, surface_sets: Mapping[str, np.ndarray]) -> np.ndarray:
    """TetGen facet markers: 1, 2, ... for the named sets in order, 0 elsewhere."""
    markers = np.zeros(triangle_count, dtype=np.int32)
    owner: dict[int, str] = {}
    for marker, (name, indices) in enumerate(surface_sets.items(), start=1):
        indices = np.asarray(indices)
        if indices.size == 0:
            indices = indices.astype(np.int64)
        if not np.issubdtype(indices.dtype, np.integer) or indices.ndim != 1:
            raise InputError(
                f"surface set {name!r} must be a 1-D array of triangle indices",
                value=str(indices.dtype),
            )
        outside = indices[(indices < 0) | (indices >= triangle_count)]
        if outside.size:
            raise InputError(
                f"surface set {name!r} indexes triangle {int(outside[0])}, outside "
                f"[0, {triangle_count})",
                value=int(outside[0]),
            )
        taken = indices[markers[indices] != 0]
        if taken.size:
            triangle = int(taken[0])
            raise InputError(
                f"triangle {triangle} is in surface sets {owner[int(markers[triangle])]!r} and "
                f"{name!r}; the sets must be disjoint",
                value=triangle,
            )
        markers[indices] = marker
        owner[marker] = name
    return markers


def fill_surface_file(
    path: str | Path, *, unit_m: float = 1.0, max_volume_m3: float | None = None
) -> TetMesh:
    """Read a closed surface (STL, OBJ, PLY, or a USD stage's first ``UsdGeom.Mesh``) and
    fill it with TetGen's quality tets.

    Args:
        path: The surface file; its suffix is one of :data:`SURFACE_SUFFIXES` or
            ``USD_SUFFIXES`` (polygons split into triangles, the Mesh's transform applied).
        unit_m: Length of the file's coordinate unit in metres (1e-3 for a file in mm).
        max_volume_m3: Largest tet volume, m^3 (:func:`tetrahedralize_surface`); None leaves
            it unbounded.

    Returns:
        A TET4 mesh in metres.

    Raises:
        InputError: A missing or unreadable file, a file without triangles, or a surface
            that is not closed (:func:`check_closed_surface`); the message names the file.
    """
    import meshio  # measured: 0.3 s; only a surface file needs it

    file_path = Path(path)
    if file_path.suffix.lower() in USD_SUFFIXES:
        vertices, triangles = read_usd_surface(file_path)
        return _fill(vertices * unit_m, triangles, file_path, max_volume_m3)
    if file_path.suffix.lower() not in SURFACE_SUFFIXES:
        known = ", ".join((*SURFACE_SUFFIXES, *USD_SUFFIXES))
        raise InputError(f"a surface file is one of {known}", path=file_path)
    if not file_path.is_file():
        raise InputError("no such file", path=file_path)
    try:
        with warnings.catch_warnings():  # meshio's binary-STL size test overflows on ASCII
            warnings.simplefilter("ignore", RuntimeWarning)
            surface = meshio.read(file_path)
    except Exception as exc:  # meshio raises many kinds on a malformed file
        raise InputError(f"cannot read the surface: {exc}", path=file_path) from None
    blocks = [block.data for block in surface.cells if block.type == "triangle"]
    if not blocks:
        raise InputError("the file holds no triangles", path=file_path)
    triangles = np.vstack(blocks).astype(np.int64)
    vertices_m = np.asarray(surface.points, dtype=np.float64)[:, :3] * unit_m
    return _fill(vertices_m, triangles, file_path, max_volume_m3)


def _fill(
    vertices_m: np.ndarray, triangles: np.ndarray, path: Path, max_volume_m3: float | None
) -> TetMesh:
    try:
        check_closed_surface(vertices_m, triangles)
    except InputError as exc:
        message = f"not a closed surface TetGen can fill: {exc.message}"
        raise InputError(message, path=path) from None
    return tetrahedralize_surface(vertices_m, triangles, max_volume_m3=max_volume_m3)
