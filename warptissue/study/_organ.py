"""A specimen given as a mesh file, indented at a site (issue 34): ``[specimen] mesh``,
``[indenter] site_m``/``direction`` and ``[boundary] support``.

The mesh is read once per file, unit and element (a small cache keyed by the file's
modification time), checked against its unit, and given the node sets the finite elements
need: ``"bottom"`` (the support) and ``"top"`` (the rest of the surface, which the probe may
touch).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import InputError, MeshError
from warptissue.fem.probe import footprint_normal, snap_to_surface
from warptissue.mesh import (
    SURFACE_SUFFIXES,
    USD_SUFFIXES,
    TetMesh,
    boundary_faces,
    fill_surface_file,
    read_mesh,
    refine_near_sites,
    to_tet10,
    usd_holds_tetmesh,
)

MESH_UNITS: dict[str, float] = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "um": 1e-6}
"""``[specimen] unit``: the mesh file's length unit, in metres."""
LARGEST_SPECIMEN_M = 2.0
"""A mesh larger than this in metres is taken for one in millimetres read as metres."""
SITE_TOLERANCE_SHARE = 0.01
"""How far ``site_m`` may lie from the surface, as a share of the mesh's largest extent."""
OPPOSITE = "opposite"
"""``[boundary] support``: the surface opposite the site (the far half along the probe)."""

_CACHE: dict[tuple[str, int, float, str, tuple], TetMesh] = {}


def specimen_mesh(
    path: Path, *, unit: str, element: str, zones: tuple[tuple[float, ...], ...] = ()
) -> TetMesh:
    """The specimen's mesh in metres, TET4 promoted to TET10 where ``element`` asks.

    Args:
        path: A volume mesh (.vtu, .msh, .inp, or a USD TetMesh asset), or a closed surface
            (.stl, .obj, .ply) that TetGen fills with quality tets
            (:func:`warptissue.mesh.fill_surface_file`).
        unit: The file's length unit, a key of :data:`MESH_UNITS`.
        element: ``"TET10"`` or ``"TET4"`` (a TET10 file is not demoted).
        zones: Refine around sites: ``(x, y, z, zone radius, size)`` each, m
            (:func:`warptissue.mesh.refine_near_sites`; :attr:`Specimen.refine_zones`).

    Returns:
        The mesh (shared: do not modify it), with node set ``"surface"``.

    Raises:
        InputError: A file that cannot be read, or a mesh whose extent says its unit is
            wrong (``key`` names ``specimen.unit``).
    """
    unit_m = MESH_UNITS[unit]
    stamp = path.stat().st_mtime_ns if path.is_file() else 0
    key = (str(path.resolve()), stamp, unit_m, element, tuple(zones))
    if key in _CACHE:
        return _CACHE[key]
    surface = path.suffix.lower() in SURFACE_SUFFIXES
    if path.suffix.lower() in USD_SUFFIXES and path.is_file():
        surface = not usd_holds_tetmesh(path)  # a USD Mesh alone: a surface to fill
    try:
        mesh = fill_surface_file(path, unit_m=unit_m) if surface else read_mesh(path, unit_m=unit_m)
    except MeshError as exc:  # e.g. TetGen: a surface that crosses itself
        raise InputError(str(exc), path=path, key="specimen.mesh", value=path.name) from None
    extent = float(np.max(np.ptp(mesh.points, axis=0)))
    if extent > LARGEST_SPECIMEN_M:
        raise InputError(
            f"the mesh is {extent:.4g} m across in unit {unit!r}: a specimen that large is "
            'probably in millimetres; give unit = "mm"',
            path=path,
            key="specimen.unit",
            value=unit,
        )
    if zones:
        table = np.asarray(zones, dtype=np.float64)
        mesh = refine_near_sites(
            mesh, sites_m=table[:, :3], zone_radii_m=table[:, 3], sizes_m=table[:, 4]
        )
    if element == "TET10" and mesh.nodes_per_tet == 4:
        mesh = to_tet10(mesh)
    faces = boundary_faces(mesh.tets[:, :4])
    surface = np.unique(faces)
    if mesh.nodes_per_tet == 10:
        member = np.zeros(mesh.node_count, dtype=bool)
        member[surface] = True
        corners = mesh.tets[:, [[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]]]
        both = member[corners].all(axis=2)
        surface = np.union1d(surface, mesh.tets[:, 4:][both])
    mesh.node_sets["surface"] = surface.astype(np.int32)
    if len(_CACHE) >= 4:  # an organ as read and refined; a batch of one organ's studies
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[key] = mesh
    return mesh


def probe_placement(
    mesh: TetMesh,
    site_m: tuple[float, ...],
    direction: tuple[float, ...] | None,
    *,
    radius_m: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The site snapped to the surface and the probe's direction (given, or the inward
    normal averaged over a footprint of ``radius_m``).

    Raises:
        InputError: The site lies farther than :data:`SITE_TOLERANCE_SHARE` of the mesh from
            its surface (``key`` ``indenter.site_m``, the distance in the message).
    """
    tolerance = SITE_TOLERANCE_SHARE * float(np.max(np.ptp(mesh.points, axis=0)))
    try:
        site = snap_to_surface(mesh, site_m, tolerance_m=tolerance, surface="surface")
    except InputError as exc:
        raise InputError(exc.message, key="indenter.site_m", value=exc.value) from None
    if direction is None:
        along = footprint_normal(mesh, site, radius_m=radius_m, surface="surface")
    else:
        along = np.asarray(direction, dtype=np.float64)
        along = along / np.linalg.norm(along)
    return site, along


def extent_along(mesh: TetMesh, site_m: np.ndarray, direction: np.ndarray) -> float:
    """How deep the body reaches below the site along the direction, m."""
    return float(np.max((mesh.points - site_m) @ direction))


def support_nodes(
    mesh: TetMesh,
    support: str | Mapping[str, Any],
    *,
    site_m: np.ndarray,
    direction: np.ndarray,
) -> np.ndarray:
    """The nodes a ``[boundary] support`` holds: a node set of the file, :data:`OPPOSITE`
    (the surface nodes farther than half the body's depth below the site),
    ``{"box": [[xmin, ymin, zmin], [xmax, ymax, zmax]]}`` (every node inside the box, m), or
    ``{"half_space": [point, normal]}`` (every node on the side of the plane through
    ``point`` (m) that ``normal`` points to, the plane included to 1e-9 of the mesh's size).

    Raises:
        InputError: A node set the file does not have, or a support that holds no node
            (``key`` ``boundary.support``).
    """
    if isinstance(support, Mapping) and "half_space" in support:
        point, normal = (np.asarray(v, dtype=np.float64) for v in support["half_space"])
        side = (mesh.points - point) @ (normal / np.linalg.norm(normal))
        size = float(np.max(np.ptp(mesh.points, axis=0)))
        nodes = np.flatnonzero(side >= -1e-9 * size)
    elif isinstance(support, Mapping):
        low, high = (np.asarray(corner, dtype=np.float64) for corner in support["box"])
        nodes = np.flatnonzero(np.all((mesh.points >= low) & (mesh.points <= high), axis=1))
    elif support == OPPOSITE:
        surface = mesh.node_sets["surface"]
        depth = (mesh.points[surface] - site_m) @ direction
        nodes = surface[depth > 0.5 * extent_along(mesh, site_m, direction)]
    elif support in mesh.node_sets and support != "surface":
        nodes = np.asarray(mesh.node_sets[support])
    else:
        known = sorted(name for name in mesh.node_sets if name != "surface")
        raise InputError(
            f"the mesh has no node set {support!r} (it has {known}; or give {OPPOSITE!r})",
            key="boundary.support",
            value=support,
        )
    if nodes.size == 0:
        raise InputError(
            "holds no node: the body would be left free to move (rigid-body modes)",
            key="boundary.support",
            value=support,
        )
    held = mesh.points[nodes] - mesh.points[nodes].mean(axis=0)
    spread = np.linalg.svd(held, compute_uv=False) if nodes.size > 1 else np.zeros(3)
    if nodes.size < 3 or spread[1] <= 1e-9 * max(float(spread[0]), 1e-300):
        raise InputError(
            f"holds {nodes.size} node(s) on one line: the body could still turn about it "
            "(rigid-body modes); hold a patch of its surface",
            key="boundary.support",
            value=support,
        )
    return nodes.astype(np.int32)


def organ_mesh(mesh: TetMesh, support: np.ndarray) -> TetMesh:
    """A copy of ``mesh`` with node sets ``"bottom"`` (the support) and ``"top"`` (the rest of
    the surface), the sets :class:`warptissue.fem.IndentationProblem` reads."""
    sets: dict[str, Any] = dict(mesh.node_sets)
    sets["bottom"] = support
    sets["top"] = np.setdiff1d(mesh.node_sets["surface"], support).astype(np.int32)
    return TetMesh(
        points=mesh.points,
        tets=mesh.tets,
        node_sets=sets,
        face_sets=dict(mesh.face_sets),
        tet_regions=mesh.tet_regions,
    )
