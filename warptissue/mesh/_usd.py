"""USD TetMesh assets as meshes: :func:`warptissue.mesh.read_mesh` of a ``.usd``, ``.usda``,
``.usdc`` or ``.usdz`` file, and so :func:`warptissue.usd.read_tetmesh_usd`. It sits on the
mesh floor so that a study's ``[specimen] mesh`` can name an organ's USD asset.

The GeomSubset families are the ones :func:`warptissue.usd.write_simulation_usd` writes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from warptissue._stage import open_stage
from warptissue.errors import InputError, MeshError
from warptissue.mesh.core import TetMesh

NODE_SET_FAMILY = "nodeSet"
"""GeomSubset family of the TetMesh's boundary node sets (elementType point)."""
REGION_FAMILY = "materialRegion"
"""GeomSubset family of the TetMesh's material regions (elementType tetrahedron, partition)."""
FACE_SET_FAMILY = "faceSet"
"""GeomSubset family of the surface Mesh's boundary face sets (elementType face)."""
USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")
"""The suffixes :func:`warptissue.mesh.read_mesh` reads as USD stages."""


def tetmesh_prim(stage: Any, path: Path, prim_path: str | None = None) -> Any:
    """The stage's ``UsdGeom.TetMesh`` prim at ``prim_path``, or its first one (``path``,
    the stage's file, names it in the error)."""
    from pxr import UsdGeom

    if prim_path is not None:
        prim = stage.GetPrimAtPath(prim_path)
        if not prim or not prim.IsA(UsdGeom.TetMesh):
            raise InputError(f"no TetMesh prim at {prim_path}", path=path)
        return prim
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.TetMesh):
            return prim
    raise InputError("the stage holds no UsdGeom.TetMesh", path=path)


def _subset_name(subset: Any) -> str:
    name = subset.GetPrim().GetCustomDataByKey("warptissue:name")
    return str(name) if name is not None else subset.GetPrim().GetName()


def read_usd(path: str | Path, *, prim_path: str | None = None) -> TetMesh:
    """Read a tetrahedral mesh (rest shape) from a USD file.

    Args:
        path: A warptissue scene (root or asset layer) or any stage with a ``UsdGeom.TetMesh``.
        prim_path: The TetMesh prim; None takes the first TetMesh in traversal order.

    Returns:
        A TET4 mesh: points (the ``points`` default value, i.e. the rest shape; float32 in
        USD), connectivity (left-handed meshes are reordered to positive orientation), node
        sets from ``nodeSet`` point subsets, material regions from ``materialRegion``
        tetrahedron subsets, and face sets from the ``faceSet`` subsets of the sibling surface
        Mesh written by :func:`warptissue.usd.write_simulation_usd`.
    """

    from pxr import Usd, UsdGeom

    path = Path(path)
    stage = open_stage(path)
    prim = tetmesh_prim(stage, path, prim_path)
    tetmesh = UsdGeom.TetMesh(prim)
    points = tetmesh.GetPointsAttr().Get(Usd.TimeCode.Default())
    tets = tetmesh.GetTetVertexIndicesAttr().Get()
    if points is None or tets is None:
        raise InputError(f"TetMesh {prim.GetPath()} lacks points or tetVertexIndices", path=path)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tets = np.asarray(tets, dtype=np.int32).reshape(-1, 4).copy()
    if tetmesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
        tets[:, [1, 2]] = tets[:, [2, 1]]
    node_sets = {
        _subset_name(subset): np.asarray(subset.GetIndicesAttr().Get(), dtype=np.int32)
        for subset in UsdGeom.Subset.GetGeomSubsets(tetmesh, UsdGeom.Tokens.point, NODE_SET_FAMILY)
    }
    tet_regions = np.zeros(len(tets), dtype=np.int32)
    for subset in UsdGeom.Subset.GetGeomSubsets(tetmesh, UsdGeom.Tokens.tetrahedron, REGION_FAMILY):
        name = _subset_name(subset)
        try:
            region = int(name)
        except ValueError:
            raise MeshError(f"material region subset {name!r} is not an integer id") from None
        tet_regions[np.asarray(subset.GetIndicesAttr().Get(), dtype=np.int64)] = region
    face_sets = {}
    for sibling in prim.GetParent().GetChildren():
        volume_points = sibling.GetAttribute("tissue:volumePointIndices")
        if not (sibling.IsA(UsdGeom.Mesh) and volume_points):
            continue
        mesh = UsdGeom.Mesh(sibling)
        triangles = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int32).reshape(-1, 3)
        triangles = np.asarray(volume_points.Get(), dtype=np.int32)[triangles]
        for subset in UsdGeom.Subset.GetGeomSubsets(mesh, UsdGeom.Tokens.face, FACE_SET_FAMILY):
            face_sets[_subset_name(subset)] = triangles[
                np.asarray(subset.GetIndicesAttr().Get(), dtype=np.int64)
            ]
    return TetMesh(
        points=points,
        tets=tets,
        node_sets=node_sets,
        face_sets=face_sets,
        tet_regions=tet_regions,
    )


def usd_holds_tetmesh(path: str | Path) -> bool:
    """Whether a USD stage holds a ``UsdGeom.TetMesh`` (else a study fills its surface)."""
    from pxr import UsdGeom

    stage = open_stage(path)
    return any(prim.IsA(UsdGeom.TetMesh) for prim in stage.Traverse())


def read_usd_surface(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The first ``UsdGeom.Mesh`` of a USD stage as a triangle surface.

    Polygons are split into fans of triangles; the points are taken at the default time and
    carried through the prim's local-to-world transform (an asset scaled or placed by its
    Xforms is read where it stands).

    Returns:
        ``(vertices, triangles)``: shape (V, 3) in the stage's units, and (F, 3) indices.

    Raises:
        InputError: No Mesh in the stage, or one without points or faces (naming the file).
    """
    from pxr import Usd, UsdGeom

    path = Path(path)
    stage = open_stage(path)
    prim = next((p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)), None)
    if prim is None:
        raise InputError("the stage holds no UsdGeom.Mesh (nor a TetMesh)", path=path)
    mesh = UsdGeom.Mesh(prim)
    points = mesh.GetPointsAttr().Get(Usd.TimeCode.Default())
    counts = mesh.GetFaceVertexCountsAttr().Get()
    indices = mesh.GetFaceVertexIndicesAttr().Get()
    if not points or not counts or indices is None:
        raise InputError(f"Mesh {prim.GetPath()} lacks points or faces", path=path)
    world = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default()))
    local = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    vertices = local @ world[:3, :3] + world[3, :3]  # USD's row vectors
    flat = np.asarray(indices, dtype=np.int64)
    triangles = []
    start = 0
    for count in counts:
        face = flat[start : start + count]
        triangles += [(face[0], face[k], face[k + 1]) for k in range(1, count - 1)]
        start += count
    return vertices, np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
