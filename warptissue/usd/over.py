"""A run layered over an organ's own USD asset (``warptissue export RUN --over ASSET``): the
asset is referenced, never copied or changed, and the run sits in an overlay and a results
layer over it. The building blocks (material and indenter prims, result attributes and their
time samples) are :mod:`warptissue.usd.writer`'s; the layout of a scene of its own is there.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pxr import Sdf, Usd, UsdGeom

from warptissue.errors import InputError
from warptissue.indenter import Indenter
from warptissue.io import atomic_path, software_versions
from warptissue.mesh import TetMesh
from warptissue.usd.writer import (
    INDENTER,
    MATERIAL,
    WORLD,
    UsdScenePaths,
    bind_materials,
    check_density,
    corner_mesh,
    declare_result_attributes,
    indenter_prims,
    result_arrays,
    result_summary,
    set_stage_metadata,
    vt_dictionary,
    write_results,
)

__all__ = ["write_results_over_asset"]


def _clear_transforms(stage: Any, root: str) -> None:
    """Empty the ``xformOpOrder`` of every Xformable under ``root`` in the edit target, so
    that prims redefined there add their own ops over an asset's."""
    top = stage.GetPrimAtPath(root)
    if top:
        for prim in list(Usd.PrimRange(top)):
            if prim.IsA(UsdGeom.Xformable):
                UsdGeom.Xformable(prim).ClearXformOpOrder()


def _block_leftovers(stage: Any, root: str, layer: Any, kept: tuple[str, ...]) -> None:
    """Hide what weaker layers hold under ``root`` and the edit target ``layer`` did not
    write: prims other than ``kept`` are deactivated and the attributes of ``kept`` prims
    without an opinion in ``layer`` blocked, so that a prim redefined over an asset (its
    indenter, its material) keeps none of the asset's values."""
    top = stage.GetPrimAtPath(root)
    if not top:
        return
    inactive, blocked = [], []
    prims = iter(Usd.PrimRange(top))
    for prim in prims:
        if str(prim.GetPath()) not in kept:
            inactive.append(prim)  # its descendants go with it
            prims.PruneChildren()
            continue
        blocked.extend(
            attribute
            for attribute in prim.GetAuthoredAttributes()
            if not layer.GetAttributeAtPath(attribute.GetPath())
        )
    for attribute in blocked:
        attribute.Block()
    for prim in inactive:
        prim.SetActive(False)


def _transfer_onto_asset(
    mesh: TetMesh,
    arrays: dict[str, np.ndarray],
    asset_points: np.ndarray,
    asset_tets: np.ndarray,
    *,
    extent: float,
    volume_path: str,
) -> tuple[dict[str, np.ndarray], dict[str, Any] | None]:
    """A run on a mesh refined from the asset's (its surface nodes among the run's nodes),
    its results on the asset's mesh: nodal fields interpolated with the run's shape
    functions at the asset's nodes (exact at the surface nodes, which the run shares), and
    each asset tet's stress the mean of the run's tets' at its four quadrature points.

    Returns:
        ``(arrays, how)``; ``(arrays, None)`` where the run's mesh is not refined from the
        asset's.
    """
    from scipy.spatial import cKDTree

    from warptissue.errors import MeshError
    from warptissue.fem.elements import interpolation_matrix, quadrature_rule
    from warptissue.mesh import boundary_faces, locate_points

    surface = np.unique(boundary_faces(asset_tets))
    distance, _ = cKDTree(mesh.points).query(asset_points[surface])
    if float(distance.max()) > 1e-6 * extent:
        return arrays, None
    try:
        nodal = interpolation_matrix(mesh, asset_points)
        reference, _ = quadrature_rule(10)
        lam = np.column_stack([1.0 - reference.sum(axis=1), reference])  # (4, 4)
        samples = np.einsum("qc,mcx->mqx", lam, asset_points[asset_tets]).reshape(-1, 3)
        holders = locate_points(mesh, samples)[0].reshape(len(asset_tets), -1)
    except MeshError as exc:
        raise InputError(
            f"the asset's mesh at {volume_path} does not lie in the run's: {exc}", key="--over"
        ) from None
    out = dict(arrays)
    u = arrays["displacement_m"]
    out["displacement_m"] = np.stack([nodal @ step for step in u]) if u.ndim == 3 else nodal @ u
    if "contact_pressure_Pa" in arrays:
        pressure = arrays["contact_pressure_Pa"]
        out["contact_pressure_Pa"] = (
            (nodal @ pressure.T).T if pressure.ndim == 2 else nodal @ pressure
        )
    for name in ("cauchy_stress_Pa", "von_mises_Pa"):
        if name in arrays:
            out[name] = arrays[name][holders].mean(axis=1)
    how = {
        "nodes": int(mesh.node_count),
        "tets": int(mesh.tet_count),
        "nodal_fields": "the run's shape functions at the asset's nodes",
        "tet_fields": "mean of the run's tets at each asset tet's four quadrature points",
    }
    return out, how


def write_results_over_asset(
    root_path: str | Path,
    asset_path: str | Path,
    mesh: TetMesh,
    *,
    result: Any,
    material: Any = None,
    provenance: Mapping[str, Any] | None = None,
    density_kg_per_m3: float | None = None,
    indenter: Indenter | None = None,
    indenter_axes: np.ndarray | None = None,
) -> UsdScenePaths:
    """Write a simulation result layered over an organ's own USD asset, which is referenced,
    not copied: the scene the asset pipeline already holds, with the run on top.

    Layout: ``NAME.usda`` (root: SI metadata and the time range) sublayers
    ``NAME.results.usdc`` (time samples only: the TetMesh's deformed ``points`` and
    ``tissue:displacement``, the stress primvars at the last step, the surface Mesh's points
    and contact pressure where the asset has the surface Mesh of
    :func:`write_simulation_usd`, the probe's curves and motion), over ``NAME.asset.usda`` (no
    time samples: the result attributes' declarations, the run's material bound to the
    TetMesh, the indenter at its site, provenance; what the asset held under
    ``/World/Indenter`` and ``/World/Materials/Tissue`` and the run does not is deactivated or
    blocked), over the organ's asset by its relative path.

    Args:
        root_path: The root layer, ``NAME.usda``.
        asset_path: The organ's USD asset (a TetMesh, metersPerUnit 1), the one the run's
            mesh was read from (``[specimen] mesh``).
        mesh: The run's mesh, metres: the asset's (its corner nodes and tets; TET10: the
            asset's TET4 promoted), or one refined from it around the sites (every surface
            node of the asset is a node of the run, as
            :func:`warptissue.mesh.refine_near_sites` keeps them): the run's fields are then
            transferred onto the asset's mesh (nodal fields by the run's shape functions at
            the asset's nodes, exact at its surface; each tet's stress the mean of the run's
            at its four quadrature points), and ``/World``'s customData says so
            (``transferred_from``).
        result: As :func:`write_simulation_usd`'s.
        density_kg_per_m3: Mass density for ``physics:density``; None keeps the asset's
            (``physics:density`` of its ``/World/Materials/Tissue``; 1000 without one).
        material, provenance, indenter, indenter_axes: As :func:`write_simulation_usd`'s.

    Returns:
        The paths written (``asset`` is the overlay ``NAME.asset.usda``).

    Raises:
        InputError: A root that is not ``.usda``, an asset not in metres, or a run's mesh
            that is neither the asset's nor refined from it: one line naming ``--over``.
    """
    root_path, asset_path = Path(root_path), Path(asset_path)
    if root_path.suffix != ".usda":
        raise InputError("the root layer must be a .usda file", path=root_path)
    organ = _OrganAsset.read(asset_path)
    if density_kg_per_m3 is None:
        density_kg_per_m3 = organ.density_kg_per_m3
    check_density(density_kg_per_m3)
    volume_path, surface_path = organ.volume_path, organ.surface_path
    arrays, transferred, kept, rest = organ.fields_of(mesh, result)
    stem = root_path.name[: -len(".usda")]
    paths = UsdScenePaths(
        root=root_path,
        asset=root_path.with_name(f"{stem}.asset.usda"),
        results=root_path.with_name(f"{stem}.results.usdc"),
    )
    overlay = Sdf.Layer.CreateAnonymous(".usda")
    results_layer = Sdf.Layer.CreateAnonymous(".usdc")
    root_layer = Sdf.Layer.CreateAnonymous(".usda")
    set_stage_metadata(root_layer)
    relative = Path(os.path.relpath(asset_path.resolve(), root_path.resolve().parent))
    for layer in (results_layer, overlay):
        root_layer.subLayerPaths.append(layer.identifier)
    root_layer.subLayerPaths.append(str(asset_path.resolve()))
    stage = Usd.Stage.Open(root_layer)
    stage.SetEditTarget(Usd.EditTarget(overlay))
    world = stage.GetPrimAtPath(WORLD)
    info: dict[str, Any] = {"software": software_versions(), "layered_over": relative.as_posix()}
    if transferred is not None:
        info["transferred_from"] = transferred
    if provenance:
        info.update(provenance)
    world.SetCustomDataByKey("warptissue", vt_dictionary(info))
    world.SetCustomDataByKey("warptissue:result", vt_dictionary(result_summary(arrays, result)))
    if material is not None:
        bind_materials(stage, stage.GetPrimAtPath(volume_path), material, density_kg_per_m3)
        _block_leftovers(stage, MATERIAL, overlay, (MATERIAL,))
    _clear_transforms(stage, INDENTER)
    if indenter is not None:
        indenter_prims(stage, indenter, rest, axes=indenter_axes)
    drawn = () if indenter is None else (INDENTER, f"{INDENTER}/Shape")
    _block_leftovers(stage, INDENTER, overlay, drawn)
    declare_result_attributes(stage, arrays, volume_path=volume_path, surface_path=surface_path)
    stage.SetEditTarget(Usd.EditTarget(results_layer))
    write_results(
        stage,
        arrays,
        kept=kept,
        surface_nodes=organ.surface_nodes,
        owners=organ.owners,
        rest=rest,
        volume_path=volume_path,
        surface_path=surface_path,
    )
    del stage
    _export_layers(paths, root_layer, results_layer, overlay, relative, len(arrays["depths_m"]))
    return paths


@dataclass(frozen=True)
class _OrganAsset:
    """What a run layered over an organ's asset needs of it: its TetMesh (path, points,
    tets), the surface Mesh of :func:`write_simulation_usd` where it has one (path, its
    volume nodes and their tets), and its density."""

    path: Path
    volume_path: str
    points: np.ndarray
    tets: np.ndarray
    surface_path: str | None
    surface_nodes: np.ndarray | None
    owners: np.ndarray | None
    density_kg_per_m3: float

    @classmethod
    def read(cls, asset_path: Path) -> _OrganAsset:
        """Read the asset (refused where it is not in metres)."""
        from warptissue._stage import open_stage
        from warptissue.mesh import tetmesh_prim

        organ = open_stage(asset_path)
        held = organ.GetPrimAtPath(MATERIAL)
        held = held.GetAttribute("physics:density").Get() if held else None
        units = UsdGeom.GetStageMetersPerUnit(organ)
        if units != 1.0:
            raise InputError(
                f"the asset is in metersPerUnit {units:g}: a result layered over it would be "
                "read in its units; layering needs an asset in metres",
                path=asset_path,
                key="--over",
            )
        volume_path = str(tetmesh_prim(organ, asset_path).GetPath())
        volume = UsdGeom.TetMesh(organ.GetPrimAtPath(volume_path))
        points = np.asarray(volume.GetPointsAttr().Get(), dtype=np.float64).reshape(-1, 3)
        tets = np.asarray(volume.GetTetVertexIndicesAttr().Get(), dtype=np.int64).reshape(-1, 4)
        surface_path = surface_nodes = owners = None
        for sibling in organ.GetPrimAtPath(volume_path).GetParent().GetChildren():
            indices = sibling.GetAttribute("tissue:volumePointIndices")
            if sibling.IsA(UsdGeom.Mesh) and indices:
                surface_path = str(sibling.GetPath())
                surface_nodes = np.asarray(indices.Get(), dtype=np.int64)
                owners = np.asarray(sibling.GetAttribute("tissue:volumeTetIndices").Get())
                break
        return cls(
            path=asset_path,
            volume_path=volume_path,
            points=points,
            tets=tets,
            surface_path=surface_path,
            surface_nodes=surface_nodes,
            owners=owners,
            density_kg_per_m3=1000.0 if held is None else float(held),
        )

    def fields_of(
        self, mesh: TetMesh, result: Any
    ) -> tuple[dict[str, Any], dict[str, Any] | None, np.ndarray, np.ndarray]:
        """The run's fields on the asset's mesh: as they are where the run's mesh is the
        asset's, else transferred onto it (refused where the run's mesh is not refined from
        the asset's).

        Returns:
            (the fields, how they were transferred (None: not), the run's nodes that are the
            asset's, in its order, and their rest positions (n, 3), m).
        """
        kept, tets, _ = corner_mesh(mesh)
        rest = mesh.points[kept]
        extent = float(np.ptp(self.points, axis=0).max())
        same = (
            rest.shape == self.points.shape
            and tets.shape == self.tets.shape
            and np.array_equal(np.sort(tets, axis=1), np.sort(self.tets, axis=1))
            and float(np.abs(rest - self.points).max()) <= 1e-6 * extent
        )
        arrays = result_arrays(result, node_count=mesh.node_count, tet_count=mesh.tet_count)
        if same:
            return arrays, None, kept, rest
        # A mesh refined around the sites: its fields onto the asset's mesh.
        arrays, transferred = _transfer_onto_asset(
            mesh, arrays, self.points, self.tets, extent=extent, volume_path=self.volume_path
        )
        if transferred is None:
            raise InputError(
                f"the run's mesh ({len(rest)} corner nodes, {len(tets)} tets) is not the "
                f"asset's ({len(self.points)} nodes, {len(self.tets)} tets at "
                f"{self.volume_path}), nor refined from it (the asset's surface nodes are not "
                "nodes of the run): export the run as its own scene (without --over)",
                path=self.path,
                key="--over",
            )
        return arrays, transferred, np.arange(len(self.points)), self.points


def _export_layers(
    paths: UsdScenePaths,
    root_layer: Sdf.Layer,
    results_layer: Sdf.Layer,
    overlay: Sdf.Layer,
    relative: Path,
    steps: int,
) -> None:
    """Write the three layers, the root's time range ``[0, steps]`` and its sublayers by
    their relative paths (results, overlay, the organ's asset), each file atomically."""
    root_layer.startTimeCode = 0.0
    root_layer.endTimeCode = float(steps)
    del root_layer.subLayerPaths[:]
    root_layer.subLayerPaths.append(f"./{paths.results.name}")
    root_layer.subLayerPaths.append(f"./{paths.asset.name}")
    root_layer.subLayerPaths.append(relative.as_posix())
    with atomic_path(paths.results) as temporary:
        results_layer.Export(str(temporary))
    with atomic_path(paths.asset) as temporary:
        overlay.Export(str(temporary))
    with atomic_path(paths.root) as temporary:
        root_layer.Export(str(temporary))
