"""Mesh files through meshio: VTK XML (.vtu), Gmsh (.msh, v2 and v4) and Abaqus (.inp).

Node order of quadratic tets: warptissue and meshio use the VTK order of mid-edge nodes,
(0,1), (1,2), (0,2), (0,3), (1,3), (2,3), which is also Abaqus C3D10's. Gmsh's 10-node tet
swaps the last two, (2,3) before (1,3); meshio's Gmsh reader and writer permute it. The tests
check this by mid-edge node positions in hand-written files.
"""

from __future__ import annotations

import contextlib
import io
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import InputError, MeshError
from warptissue.io import atomic_path
from warptissue.mesh._usd import USD_SUFFIXES, read_usd
from warptissue.mesh.core import TetMesh, boundary_faces
from warptissue.mesh.quality import fix_orientation

__all__ = ["NODE_SET_PREFIX", "TET_REGION_KEY", "read_mesh", "write_mesh"]

NODE_SET_PREFIX = "node_set:"
"""Point-data arrays named ``node_set:<name>`` (0/1 per node) carry node sets in VTU/MSH."""

TET_REGION_KEY = "tet_region"
"""Cell-data array that carries ``TetMesh.tet_regions`` in VTU/MSH files."""

_READ_FORMATS = {".vtu": "vtu", ".msh": "gmsh", ".inp": "abaqus"}
_WRITE_FORMATS = {".vtu": "vtu", ".msh": "gmsh"}
_TET_TYPES = {"tetra": 4, "tetra10": 10}
_GMSH_COMPONENTS = (1, 3, 9)


def read_mesh(
    path: str | Path,
    *,
    unit_m: float = 1.0,
    reorient: bool = True,
    prim_path: str | None = None,
) -> TetMesh:
    """Read a tetrahedral mesh from a VTU, Gmsh MSH (v2 or v4), Abaqus INP or USD file.

    A USD stage (.usd, .usda, .usdc, .usdz) gives its ``UsdGeom.TetMesh``: the rest shape,
    node sets from ``nodeSet`` point subsets, regions from ``materialRegion`` subsets, face
    sets from the sibling surface's ``faceSet`` subsets (as
    :func:`warptissue.usd.write_simulation_usd` writes them).

    Only tets are kept (``tetra`` or ``tetra10``; a file may not mix them); nodes no tet uses
    are dropped and the rest renumbered in file order. Node sets come from, in this order:
    Abaqus ``*NSET``; Abaqus ``*ELSET`` and named Gmsh physical groups (the nodes of their cells,
    of any cell type, so a physical surface becomes the node set of its triangles); and the
    ``node_set:<name>`` point-data masks that :func:`write_mesh` writes. Face sets are the
    boundary triangles whose corners all lie in a node set of the same name. Regions come from
    a ``tet_region`` cell array, else from Gmsh physical tags of the tets, else are 0.

    Args:
        path: The file; its suffix (.vtu, .msh, .inp, .usd, .usda, .usdc, .usdz) picks the
            format.
        unit_m: Length of the file's coordinate unit in metres (1e-3 for a file in mm).
        reorient: Turn negatively oriented tets positive (:func:`fix_orientation`); some
            tools write tets in the opposite orientation.
        prim_path: A USD file's TetMesh prim; None takes the first TetMesh in traversal
            order.

    Returns:
        The mesh, in metres.

    Raises:
        InputError: The file is missing, has an unknown suffix, cannot be parsed, has no
            tetrahedra, or mixes linear and quadratic tets. The message names the file.
    """
    import meshio

    file_path = Path(path)
    if not (np.isfinite(unit_m) and unit_m > 0):
        raise InputError("unit_m must be a positive length in metres", value=unit_m)
    if file_path.suffix.lower() in USD_SUFFIXES:
        mesh = read_usd(file_path, prim_path=prim_path)
        if unit_m != 1.0:
            mesh = TetMesh(
                points=mesh.points * unit_m,
                tets=mesh.tets,
                node_sets=mesh.node_sets,
                face_sets=mesh.face_sets,
                tet_regions=mesh.tet_regions,
            )
        return fix_orientation(mesh) if reorient else mesh
    if prim_path is not None:
        raise InputError("prim_path is for a USD file", path=file_path, value=prim_path)
    file_format = _READ_FORMATS.get(file_path.suffix.lower())
    if file_format is None:
        known = sorted([*_READ_FORMATS, *USD_SUFFIXES])
        raise InputError(
            f"unknown mesh format {file_path.suffix!r}; expected one of {known}",
            path=file_path,
        )
    if not file_path.is_file():
        raise InputError("mesh file not found", path=file_path)
    messages = io.StringIO()
    try:
        with contextlib.redirect_stdout(messages), contextlib.redirect_stderr(messages):
            data = meshio.read(file_path, file_format=file_format)
    except (Exception, SystemExit) as exc:  # meshio raises many kinds, and exits on ReadError
        printed = " ".join(messages.getvalue().split())
        detail = printed if isinstance(exc, SystemExit) else f"{exc} {printed}".strip()
        raise InputError(f"cannot read {file_format} mesh: {detail}", path=file_path) from exc

    tet_blocks = [i for i, block in enumerate(data.cells) if block.type in _TET_TYPES]
    if not tet_blocks:
        found = sorted({block.type for block in data.cells}) or ["none"]
        raise InputError(
            f"the mesh has no tetrahedra (cell types found: {', '.join(found)})", path=file_path
        )
    kinds = {data.cells[i].type for i in tet_blocks}
    if len(kinds) > 1:
        raise InputError("the mesh mixes linear and quadratic tetrahedra", path=file_path)
    points = np.asarray(data.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise InputError(f"points have shape {points.shape}, expected (N, 3)", path=file_path)
    if points.shape[1] == 2:
        raise InputError("the mesh is two-dimensional", path=file_path)
    tets = np.vstack([np.asarray(data.cells[i].data, dtype=np.int64) for i in tet_blocks])
    regions = _read_regions(data, tet_blocks)

    node_sets = _read_node_sets(data)
    used = np.unique(tets)
    renumber = np.full(len(points), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    node_sets = {
        name: renumber[nodes][renumber[nodes] >= 0].astype(np.int32)
        for name, nodes in node_sets.items()
    }
    try:
        mesh = TetMesh(
            points=points[used] * unit_m,
            tets=renumber[tets],
            node_sets=node_sets,
            tet_regions=regions,
        )
    except MeshError as exc:
        raise InputError(str(exc), path=file_path) from exc
    if reorient:
        mesh = fix_orientation(mesh)
    _add_face_sets(mesh)
    return mesh


def _read_node_sets(data: Any) -> dict[str, np.ndarray]:
    """The node sets of a meshio mesh, in the file's numbering, in :func:`read_mesh`'s
    order: Abaqus ``*NSET``; Abaqus ``*ELSET`` and named Gmsh physical groups (the nodes of
    their cells); the ``node_set:<name>`` point-data masks."""
    node_sets: dict[str, np.ndarray] = {
        name: np.asarray(nodes, dtype=np.int64) for name, nodes in data.point_sets.items()
    }
    for name, per_block in data.cell_sets.items():
        if name.startswith("gmsh:"):
            continue
        members = [
            np.asarray(data.cells[b].data)[np.asarray(cells, dtype=np.int64)].ravel()
            for b, cells in enumerate(per_block)
            if cells is not None and len(cells)
        ]
        if members:
            node_sets.setdefault(name, np.unique(np.concatenate(members)))
    node_sets.update(_gmsh_physical_node_sets(data))
    for key, values in data.point_data.items():
        if key.startswith(NODE_SET_PREFIX):
            node_sets[key[len(NODE_SET_PREFIX) :]] = np.flatnonzero(np.asarray(values) != 0)
    return node_sets


def _add_face_sets(mesh: TetMesh) -> None:
    """Give ``mesh`` a face set per node set: the boundary triangles whose corners all lie
    in it."""
    faces = boundary_faces(mesh.tets)
    member = np.zeros(mesh.node_count, dtype=bool)
    for name, nodes in mesh.node_sets.items():
        member[:] = False
        member[nodes] = True
        on_set = faces[member[faces].all(axis=1)]
        if len(on_set):
            mesh.face_sets[name] = on_set


def write_mesh(
    path: str | Path,
    mesh: TetMesh,
    *,
    point_data: Mapping[str, np.ndarray] | None = None,
    cell_data: Mapping[str, np.ndarray] | None = None,
    binary: bool = True,
) -> Path:
    """Write a mesh and fields to VTU (ParaView) or Gmsh MSH 4.1, atomically.

    Node sets travel as ``node_set:<name>`` 0/1 point-data arrays and regions as the
    ``tet_region`` cell array, so :func:`read_mesh` restores them (face sets are rebuilt from
    the node sets). Gmsh allows 1, 3 or 9 components per field: an array of another width
    (a Voigt stress, shape (M, 6)) is written as scalar fields ``name[0]``, ``name[1]``, ...

    Args:
        path: Output file, ``.vtu`` or ``.msh``.
        mesh: The mesh.
        point_data: Nodal fields, name to shape (node_count,) or (node_count, k).
        cell_data: Per-tet fields, name to shape (tet_count,) or (tet_count, k).
        binary: Binary (compressed for VTU) rather than ASCII output.

    Returns:
        The path written.

    Raises:
        InputError: Unknown suffix, or a field whose length does not match the mesh (the
            message names the field).
    """
    import meshio

    file_path = Path(path)
    file_format = _WRITE_FORMATS.get(file_path.suffix.lower())
    if file_format is None:
        raise InputError(
            f"cannot write mesh format {file_path.suffix!r}; use one of {sorted(_WRITE_FORMATS)}",
            path=file_path,
        )
    nodal = _validated_fields(point_data, mesh.node_count, "point_data", file_path)
    per_tet = _validated_fields(cell_data, mesh.tet_count, "cell_data", file_path)
    for name, nodes in mesh.node_sets.items():
        mask = np.zeros(mesh.node_count, dtype=np.int32)
        mask[nodes] = 1
        nodal[NODE_SET_PREFIX + name] = mask
    per_tet[TET_REGION_KEY] = mesh.tet_regions.astype(np.int32)
    if file_format == "gmsh":
        nodal = _split_for_gmsh(nodal)
        per_tet = _split_for_gmsh(per_tet)
        tag = (mesh.tet_regions + 1).astype(np.int32)
        per_tet["gmsh:physical"] = tag
        per_tet["gmsh:geometrical"] = tag
    cell_type = "tetra" if mesh.nodes_per_tet == 4 else "tetra10"
    output = meshio.Mesh(
        mesh.points,
        [(cell_type, mesh.tets)],
        point_data=nodal,
        cell_data={name: [values] for name, values in per_tet.items()},
    )
    with atomic_path(file_path) as temporary:
        options = {"binary": binary}
        if file_format == "vtu":
            options["compression"] = "zlib" if binary else None
        meshio.write(temporary, output, file_format=file_format, **options)
    return file_path


def _gmsh_physical_node_sets(data) -> dict[str, np.ndarray]:
    """Nodes of the cells of each named Gmsh physical group (any dimension)."""
    tags = data.cell_data.get("gmsh:physical")
    if tags is None:
        return {}
    node_sets = {}
    for name, (tag, dimension) in data.field_data.items():
        members = [
            np.asarray(block.data)[np.asarray(block_tags) == tag].ravel()
            for block, block_tags in zip(data.cells, tags, strict=True)
            if block.dim == dimension
        ]
        members = [m for m in members if m.size]
        if members:
            node_sets[name] = np.unique(np.concatenate(members))
    return node_sets


def _read_regions(data, tet_blocks: list[int]) -> np.ndarray | None:
    """Per-tet regions from a ``tet_region`` array or Gmsh physical tags, else None."""
    for key, offset in ((TET_REGION_KEY, 0), ("gmsh:physical", -1)):
        if key in data.cell_data:
            values = np.concatenate([np.asarray(data.cell_data[key][i]) for i in tet_blocks])
            return (values.reshape(len(values), -1)[:, 0] + offset).astype(np.int32)
    return None


def _validated_fields(
    fields: Mapping[str, np.ndarray] | None, count: int, kind: str, path: Path
) -> dict[str, np.ndarray]:
    """Fields as arrays with ``count`` rows, or an InputError naming the bad one."""
    result = {}
    for name, values in (fields or {}).items():
        array = np.asarray(values)
        if array.ndim not in (1, 2) or array.shape[0] != count:
            raise InputError(
                f"{kind} field {name!r} has shape {array.shape}; expected ({count},) or "
                f"({count}, k)",
                path=path,
            )
        result[name] = array
    return result


def _split_for_gmsh(fields: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Split fields whose component count Gmsh does not allow into scalar fields."""
    result = {}
    for name, values in fields.items():
        width = 1 if values.ndim == 1 else values.shape[1]
        if width in _GMSH_COMPONENTS:
            result[name] = values
        else:
            result.update({f"{name}[{i}]": values[:, i] for i in range(width)})
    return result
