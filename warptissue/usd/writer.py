"""Write a specimen, its material and simulated results as a layered USD scene.

Layout (see the README's "USD export"):

- ``NAME.usda``: the root layer. Stage metadata only (``metersPerUnit = 1``,
  ``kilogramsPerUnit = 1``, ``upAxis``, ``defaultPrim``, the time range); it sublayers the
  results layer over the asset layer.
- ``NAME.asset.usda``: geometry, subsets, the material and the indenter. No time samples.
- ``NAME.results.usdc``: time samples only (deformed points, primvars, probe curves). Written
  only when a result is given.

Prims: ``/World`` (provenance in customData), ``/World/Specimen`` (deformable body),
``/World/Specimen/Volume`` (``UsdGeom.TetMesh``), ``/World/Specimen/Surface`` (triangle
``UsdGeom.Mesh`` for renderers), ``/World/Materials/Tissue`` (physics material),
``/World/Indenter``. A heterogeneous material field (per-tet Young's modulus and Poisson's
ratio, :data:`MATERIAL_FIELD_PRIMVARS`) is written as uniform primvars of the TetMesh and of
the surface Mesh (each face takes the value of the tet it bounds), in the asset layer.
Under a rigid indenter in contact the results layer also samples the contact pressure on the
surface Mesh and the contact area on the indenter (:data:`CONTACT_RESULTS`).

This module puts the layers together; the pieces live beside it and are re-exported here:
``_layout`` (prim paths, the written paths, customData values, stage metadata),
``_material`` (the physics material, its bindings and the material field) and ``_results``
(a result's arrays and time samples).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdPhysics, Vt

from warptissue._deprecated import moved_names
from warptissue.errors import InputError, MeshError
from warptissue.indenter import Indenter
from warptissue.io import atomic_path, software_versions
from warptissue.mesh import FACE_SET_FAMILY, NODE_SET_FAMILY, REGION_FAMILY, TetMesh
from warptissue.usd._layout import (  # noqa: F401 (the scene's paths, re-exported)
    INDENTER,
    MATERIAL,
    SPECIMEN,
    SURFACE,
    VOLUME,
    WORLD,
    UsdScenePaths,
    check_density,
    corner_mesh,
    set_stage_metadata,
    vt_dictionary,
)
from warptissue.usd._material import (  # noqa: F401 (re-exported)
    MATERIAL_FIELD_PRIMVARS,
    bind_materials,
    material_field_arrays,
    material_field_primvars,
    material_field_problems,
    material_prims,
)
from warptissue.usd._results import (  # noqa: F401 (re-exported)
    CONTACT_RESULTS,
    declare_result_attributes,
    result_arrays,
    result_field,
    result_summary,
    write_results,
)
from warptissue.usd.schema import (
    DEFORMABLE_BODY_API,
    VOLUME_DEFORMABLE_SIM_API,
    material_record,
)
from warptissue.usd.trainer import author_contact_sizes, author_trainer_material

__all__ = [
    "CONTACT_RESULTS",
    "MATERIAL_FIELD_PRIMVARS",
    "UsdScenePaths",
    "material_field_problems",
    "write_material_usd",
    "write_simulation_usd",
]


def _surface_owners(tets: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Index of the tet that owns each boundary triangle, shape (F,)."""
    local = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])
    tet_faces = np.sort(tets[:, local].reshape(-1, 3), axis=1)
    owner_of_face = np.repeat(np.arange(len(tets)), 4)
    keys = np.sort(faces, axis=1)
    order = np.lexsort(tet_faces.T[::-1])
    sorted_faces = tet_faces[order]
    # Row-wise search with a structured view: lexicographic order of int triples.
    view_dtype = np.dtype([("a", np.int64), ("b", np.int64), ("c", np.int64)])
    haystack = np.ascontiguousarray(sorted_faces, dtype=np.int64).view(view_dtype).ravel()
    needles = np.ascontiguousarray(keys, dtype=np.int64).view(view_dtype).ravel()
    position = np.searchsorted(haystack, needles)
    if np.any(position >= haystack.size) or np.any(
        haystack[np.minimum(position, haystack.size - 1)] != needles
    ):
        raise MeshError("a surface triangle does not belong to any tetrahedron")
    return owner_of_face[order[position]]


def _define_subsets(
    geom: Any,
    family: str,
    element_type: str,
    family_type: str,
    sets: Mapping[str, np.ndarray],
) -> None:
    """One GeomSubset per named set; the set's own name goes to customData ``warptissue:name``.

    Authors the subset prims as Sdf specs in one change block: defining them one by one
    through the Usd API recomposes the stage per subset, which is slow for meshes with
    thousands of regions.
    """

    if not sets:
        return
    layer = geom.GetPrim().GetStage().GetEditTarget().GetLayer()
    parent = geom.GetPath()
    used: set[str] = set()
    with Sdf.ChangeBlock():
        for name, indices in sets.items():
            # Distinct set names can share a valid identifier ("a-b", "a_b"): number repeats.
            identifier = base = Tf.MakeValidIdentifier(f"{family}_{name}")
            while identifier in used:
                identifier = f"{base}_{len(used)}"
            used.add(identifier)
            spec = Sdf.CreatePrimInLayer(layer, parent.AppendChild(identifier))
            spec.specifier = Sdf.SpecifierDef
            spec.typeName = "GeomSubset"
            spec.customData = {"warptissue": {"name": str(name)}}
            for attr_name, type_name, value in (
                ("elementType", Sdf.ValueTypeNames.Token, element_type),
                ("familyName", Sdf.ValueTypeNames.Token, family),
            ):
                Sdf.AttributeSpec(
                    spec, attr_name, type_name, Sdf.VariabilityUniform
                ).default = value
            Sdf.AttributeSpec(
                spec, "indices", Sdf.ValueTypeNames.IntArray
            ).default = Vt.IntArray.FromNumpy(np.asarray(indices, dtype=np.int32))
    UsdGeom.Subset.SetFamilyType(geom, family, family_type)


def indenter_prims(
    stage: Any, indenter: Indenter, rest_m: np.ndarray, *, axes: np.ndarray | None = None
) -> None:
    """The indenter's Xform at its contact point and its shape (``/World/Indenter/Shape``).

    ``rest_m`` are the specimen's rest points (n, 3), m: the contact point is on their top
    (largest z) unless the indenter has its own ``z_m``. A ``"plate"`` (a rigid plane in the
    FE) and a ``"platen"`` of ``length_m`` 0 are drawn as a thin box over their footprint
    (their x-y extent: a quarter model's quarter), a twentieth of its larger side thick,
    resting on the top; a platen with ``length_m`` > 0 is a square of that side
    centred on the probe. ``axes`` (the probe's frame at a site, rows ``e1, e2, e3`` with
    ``e3 = -direction``; :class:`warptissue.fem.probe.ProbeFrame`) turns the Xform by an
    orient op after its translate: the shape's z is the frame's e3, a wedge's edge (y) e2.
    """

    rest_m = np.asarray(rest_m, dtype=np.float64)
    top_z_m = float(rest_m[:, 2].max())
    contact_z = top_z_m if indenter.z_m is None else indenter.z_m
    xform = UsdGeom.Xform.Define(stage, INDENTER)
    xform.AddTranslateOp().Set(Gf.Vec3d(indenter.x_m, indenter.y_m, contact_z))
    if axes is not None:  # USD's row vectors: the rows are the local axes' images
        rotation = Gf.Matrix3d(*np.asarray(axes, dtype=np.float64).ravel().tolist())
        xform.AddOrientOp(UsdGeom.XformOp.PrecisionDouble).Set(
            Gf.Matrix4d().SetRotate(rotation).ExtractRotationQuat()
        )
    prim = xform.GetPrim()
    prim.CreateAttribute("tissue:indenter:kind", Sdf.ValueTypeNames.Token, custom=True).Set(
        indenter.kind
    )
    if indenter.kind == "flat_punch":
        height = 4.0 * indenter.radius_m
        shape = UsdGeom.Cylinder.Define(stage, f"{INDENTER}/Shape")
        shape.CreateAxisAttr(UsdGeom.Tokens.z)
        shape.CreateRadiusAttr(indenter.radius_m)
        shape.CreateHeightAttr(height)
        shape.CreateExtentAttr(
            [
                (-indenter.radius_m, -indenter.radius_m, -height / 2),
                (indenter.radius_m, indenter.radius_m, height / 2),
            ]
        )
        shape.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, height / 2))
    elif indenter.kind == "sphere":
        radius = indenter.radius_m
        shape = UsdGeom.Sphere.Define(stage, f"{INDENTER}/Shape")
        shape.CreateRadiusAttr(radius)
        shape.CreateExtentAttr([(-radius, -radius, -radius), (radius, radius, radius)])
        shape.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, radius))
    elif indenter.kind == "wedge":
        _wedge_mesh(stage, indenter)
    else:
        if indenter.length_m > 0:
            sides = (indenter.length_m, indenter.length_m)
            centre = (0.0, 0.0)
        else:
            low, high = rest_m[:, :2].min(axis=0), rest_m[:, :2].max(axis=0)
            sides = (float(high[0] - low[0]), float(high[1] - low[1]))
            centre = (
                float(0.5 * (low[0] + high[0]) - indenter.x_m),
                float(0.5 * (low[1] + high[1]) - indenter.y_m),
            )
        thickness = 0.05 * max(sides)
        shape = UsdGeom.Cube.Define(stage, f"{INDENTER}/Shape")
        shape.CreateSizeAttr(1.0)
        shape.CreateExtentAttr([(-0.5, -0.5, -0.5), (0.5, 0.5, 0.5)])
        shape.AddTranslateOp().Set(Gf.Vec3d(centre[0], centre[1], thickness / 2))
        shape.AddScaleOp().Set(Gf.Vec3f(sides[0], sides[1], thickness))
    for name, value, unit in (
        ("radius", indenter.radius_m, "m"),
        ("length", indenter.length_m, "m"),
        ("edgeRadius", indenter.edge_radius_m, "m"),
        ("angle", indenter.angle_deg, "deg"),
    ):
        if value > 0:
            attr = prim.CreateAttribute(
                f"tissue:indenter:{name}", Sdf.ValueTypeNames.Double, custom=True
            )
            attr.Set(float(value))
            attr.SetCustomDataByKey("unit", unit)


def _wedge_mesh(stage: Any, indenter: Indenter) -> None:
    """A wedge along y (opening ``angle_deg``, tip radius ``radius_m``, its lowest line at the
    origin) drawn as an extruded profile: the tip arc and two flanks up to a height of a few
    tip radii; ``length_m`` along y (0: ten tip radii)."""

    radius = indenter.radius_m
    half = math.radians(0.5 * indenter.angle_deg)
    length = indenter.length_m or 10.0 * radius
    height = max(10.0 * radius, 1e-3)
    # The tip arc from the left flank's tangent point to the right one's, then the flanks.
    arc = np.linspace(-(0.5 * math.pi - half), 0.5 * math.pi - half, 17)
    profile = [(radius * math.sin(a), radius * (1.0 - math.cos(a))) for a in arc]
    x_top = profile[-1][0] + (height - profile[-1][1]) * math.tan(half)
    profile = [(-x_top, height), *profile, (x_top, height)]
    count = len(profile)
    points = [(x, y, z) for y in (-length / 2, length / 2) for x, z in profile]
    faces, counts = [], []
    for i in range(count):  # the sides, the top closing the loop
        j = (i + 1) % count
        faces += [i, j, count + j, count + i]
        counts.append(4)
    faces += list(range(count - 1, -1, -1)) + list(range(count, 2 * count))
    counts += [count, count]
    shape = UsdGeom.Mesh.Define(stage, f"{INDENTER}/Shape")
    shape.CreatePointsAttr(points)
    shape.CreateFaceVertexCountsAttr(counts)
    shape.CreateFaceVertexIndicesAttr(faces)
    xs = [p[0] for p in points]
    shape.CreateExtentAttr([(min(xs), -length / 2, 0.0), (max(xs), length / 2, height)])


def _volume_prim(
    stage: Any, mesh: TetMesh, *, tets: np.ndarray, rest: np.ndarray, new_index: np.ndarray
) -> tuple[Any, np.ndarray]:
    """The TetMesh with its node-set and region subsets; returns (prim, surface faces (F, 3))."""

    volume = UsdGeom.TetMesh.Define(stage, VOLUME)
    volume_prim = volume.GetPrim()
    volume_prim.AddAppliedSchema(VOLUME_DEFORMABLE_SIM_API)
    UsdPhysics.CollisionAPI.Apply(volume_prim)
    volume.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(rest.astype(np.float32)))
    volume.CreateTetVertexIndicesAttr(Vt.Vec4iArray.FromNumpy(tets))
    volume.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    faces = np.array(UsdGeom.TetMesh.ComputeSurfaceFaces(volume), dtype=np.int32).reshape(-1, 3)
    volume.CreateSurfaceFaceVertexIndicesAttr(Vt.Vec3iArray.FromNumpy(faces))
    volume.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*rest.min(0)), Gf.Vec3f(*rest.max(0))]))
    node_sets = {}
    for name, nodes in mesh.node_sets.items():
        corner_nodes = new_index[nodes]
        node_sets[name] = np.sort(corner_nodes[corner_nodes >= 0])
    _define_subsets(
        volume, NODE_SET_FAMILY, UsdGeom.Tokens.point, UsdGeom.Tokens.unrestricted, node_sets
    )
    regions = {
        str(region): np.flatnonzero(mesh.tet_regions == region)
        for region in np.unique(mesh.tet_regions)
    }
    _define_subsets(
        volume, REGION_FAMILY, UsdGeom.Tokens.tetrahedron, UsdGeom.Tokens.partition, regions
    )
    return volume_prim, faces


def _surface_prim(
    stage: Any,
    mesh: TetMesh,
    *,
    tets: np.ndarray,
    rest: np.ndarray,
    faces: np.ndarray,
    new_index: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The render Mesh of the boundary with face-set subsets.

    Returns:
        The TetMesh points on the surface (n,) and the tet owning each face (F,).
    """

    surface_nodes, surface_local = np.unique(faces, return_inverse=True)
    surface_triangles = surface_local.reshape(-1, 3).astype(np.int32)
    owners = _surface_owners(tets, faces)
    surface = UsdGeom.Mesh.Define(stage, SURFACE)
    surface.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(rest[surface_nodes].astype(np.float32)))
    surface.CreateFaceVertexCountsAttr(
        Vt.IntArray.FromNumpy(np.full(len(faces), 3, dtype=np.int32))
    )
    surface.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(surface_triangles.ravel()))
    surface.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    surface.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    surface.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*rest.min(0)), Gf.Vec3f(*rest.max(0))]))
    surface.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set([Gf.Vec3f(0.78, 0.36, 0.32)])
    surface_prim = surface.GetPrim()
    index_attr = surface_prim.CreateAttribute(
        "tissue:volumePointIndices", Sdf.ValueTypeNames.IntArray, custom=True
    )
    index_attr.Set(Vt.IntArray.FromNumpy(surface_nodes.astype(np.int32)))
    owner_attr = surface_prim.CreateAttribute(
        "tissue:volumeTetIndices", Sdf.ValueTypeNames.IntArray, custom=True
    )
    owner_attr.Set(Vt.IntArray.FromNumpy(owners.astype(np.int32)))
    face_key = {tuple(sorted(f)): i for i, f in enumerate(faces.tolist())}
    face_sets = {}
    for name, triangles in mesh.face_sets.items():
        renumbered = new_index[triangles]
        missing = [t for t in renumbered.tolist() if tuple(sorted(t)) not in face_key]
        if missing:
            raise MeshError(
                f"face set {name!r} holds a triangle that is not on the boundary: {missing[0]}"
            )
        face_sets[name] = np.array(
            [face_key[tuple(sorted(t))] for t in renumbered.tolist()], dtype=np.int32
        )
    _define_subsets(
        surface, FACE_SET_FAMILY, UsdGeom.Tokens.face, UsdGeom.Tokens.unrestricted, face_sets
    )
    return surface_nodes, owners


def write_simulation_usd(
    root_path: str | Path,
    mesh: TetMesh,
    *,
    material: Any = None,
    result: Any = None,
    provenance: Mapping[str, Any] | None = None,
    density_kg_per_m3: float = 1000.0,
    indenter: Indenter | None = None,
    material_field: Mapping[str, Any] | None = None,
    indenter_axes: np.ndarray | None = None,
    trainer: Mapping[str, Any] | None = None,
) -> UsdScenePaths:
    """Write a specimen mesh, its material and a simulation result as a layered USD scene.

    Args:
        root_path: The root layer, ``NAME.usda``. ``NAME.asset.usda`` and (with a result)
            ``NAME.results.usdc`` are written beside it. All writes are atomic.
        mesh: The specimen, TET4 or TET10, metres. USD's TetMesh is linear, so a TET10 mesh is
            written as its corner tetrahedra: mid-edge nodes are dropped and nodal results
            are kept at the corner nodes (node sets are restricted to corner nodes).
        material: A ``warptissue.materials`` object (``to_dict()``,
            ``small_strain_equivalent()``) or a dictionary in ``to_dict()`` form; optional keys
            ``prony_g`` and ``prony_tau_s`` add a Prony series.
        result: An ``IndentationResult`` or a mapping with ``depths_m`` (S,),
            ``reaction_force_N`` (S,), ``displacement_m`` (S, N, 3) (or (N, 3): the last
            step only, sampled at time code S) and optionally
            ``cauchy_stress_Pa`` (M, 6) and ``von_mises_Pa`` (M,) at the last step,
            ``time_s`` (S,), and under a rigid indenter in contact ``contact_area_m2`` (S,)
            and ``contact_pressure_Pa`` (S, N) (or (N,): the last step only)
            (:data:`CONTACT_RESULTS`; empty arrays are skipped). Step k is written at time
            code k; time code 0 is the rest state.
        provenance: JSON-like metadata (data file, fit quality, ...) stored in ``/World``'s
            customData under ``warptissue``, with software versions added.
        density_kg_per_m3: Mass density written as ``physics:density``.
        indenter: The indenter to draw; None draws none.
        indenter_axes: The probe's frame at a site, (3, 3), rows ``e1, e2, e3`` with
            ``e3 = -direction`` (``IndentationProblem.frame.axes``): the indenter is turned
            to it and its time samples move along the direction; None: along -z.
        material_field: A heterogeneous linear elastic field, ``{"youngs_modulus_Pa": (M,),
            "poissons_ratio": (M,)}`` with E > 0 Pa and -1 < nu < 0.5, one value per tet of
            ``mesh`` (TET10: per corner tet, one to one). Written to the asset layer as the
            uniform primvars ``primvars:tissue:youngsModulus`` (customData unit ``Pa``) and
            ``primvars:tissue:poissonsRatio`` (unit ``1``) of the TetMesh, and per face
            (the value of the tet each face bounds) of the surface Mesh. ``material`` stays
            the one homogeneous material bound for simulators that read a single one.
        trainer: A trainer calibration (:meth:`warptissue.fit.trainer.TrainerCalibration.
            to_dict`, with ``youngs_modulus_Pa`` and ``poissons_ratio``): the physics
            material's E and nu become the calibrated ones, the tissue's move to
            ``tissue:smallStrain:*``, the calibration goes to the material's customData, and
            the TetMesh gets its particle sizes (:mod:`warptissue.usd.trainer`).

    Returns:
        The paths written.
    """

    root_path = Path(root_path)
    if trainer is not None and material is None:
        raise InputError("a trainer calibration needs the material", key="trainer")
    field_arrays = _checked_scene_inputs(root_path, mesh, density_kg_per_m3, material_field)
    stem = root_path.name[: -len(".usda")]
    asset_name = f"{stem}.asset.usda"
    results_name = f"{stem}.results.usdc"
    kept, tets, new_index = corner_mesh(mesh)
    rest = mesh.points[kept]

    asset_layer = Sdf.Layer.CreateAnonymous(".usda")
    set_stage_metadata(asset_layer)
    stage = Usd.Stage.Open(asset_layer)
    world = UsdGeom.Xform.Define(stage, WORLD)
    info = {"software": software_versions(), "element_type_source": mesh.element_type}
    if provenance:
        info.update(provenance)
    world.GetPrim().SetCustomDataByKey("warptissue", vt_dictionary(info))

    specimen = UsdGeom.Xform.Define(stage, SPECIMEN)
    specimen.GetPrim().AddAppliedSchema(DEFORMABLE_BODY_API)

    volume_prim, faces = _volume_prim(stage, mesh, tets=tets, rest=rest, new_index=new_index)
    surface_nodes, owners = _surface_prim(
        stage, mesh, tets=tets, rest=rest, faces=faces, new_index=new_index
    )
    if field_arrays is not None:
        material_field_primvars(stage, field_arrays, owners=owners)

    if material is not None:
        tissue = bind_materials(stage, volume_prim, material, density_kg_per_m3)
        if trainer is not None:
            author_trainer_material(tissue.GetPrim(), trainer, vt_dictionary(trainer))
            author_contact_sizes(volume_prim, rest, tets)
    if indenter is not None:
        indenter_prims(stage, indenter, rest, axes=indenter_axes)
    arrays = None
    if result is not None:
        arrays = result_arrays(result, node_count=mesh.node_count, tet_count=mesh.tet_count)
        declare_result_attributes(stage, arrays)
        world.GetPrim().SetCustomDataByKey(
            "warptissue:result", vt_dictionary(result_summary(arrays, result))
        )

    root_layer = Sdf.Layer.CreateAnonymous(".usda")
    set_stage_metadata(root_layer)
    results_layer = None
    if arrays is not None:
        results_layer = Sdf.Layer.CreateAnonymous(".usdc")
        root_layer.subLayerPaths.append(results_layer.identifier)
        root_layer.subLayerPaths.append(asset_layer.identifier)
        composed = Usd.Stage.Open(root_layer)
        composed.SetEditTarget(Usd.EditTarget(results_layer))
        write_results(
            composed,
            arrays,
            kept=kept,
            surface_nodes=surface_nodes,
            owners=owners,
            rest=rest,
        )
        del composed
        root_layer.startTimeCode = 0.0
        root_layer.endTimeCode = float(len(arrays["depths_m"]))

    paths = UsdScenePaths(
        root=root_path,
        asset=root_path.with_name(asset_name),
        results=root_path.with_name(results_name) if results_layer is not None else None,
    )
    del root_layer.subLayerPaths[:]
    if results_layer is not None:
        root_layer.subLayerPaths.append(f"./{results_name}")
        with atomic_path(paths.results) as temporary:
            results_layer.Export(str(temporary))
    root_layer.subLayerPaths.append(f"./{asset_name}")
    with atomic_path(paths.asset) as temporary:
        asset_layer.Export(str(temporary))
    with atomic_path(paths.root) as temporary:
        root_layer.Export(str(temporary))
    return paths


def _checked_scene_inputs(
    root_path: Path, mesh: TetMesh, density_kg_per_m3: float, material_field: Any
) -> Any:
    """Refuse a root that is not ``.usda``, a bad density, and a mesh without tets or with an
    inverted or degenerate one; the material field's arrays (None without one)."""
    if root_path.suffix != ".usda":
        raise InputError("the root layer must be a .usda file", path=root_path)
    check_density(density_kg_per_m3)
    if mesh.tet_count == 0:
        raise MeshError("cannot export a mesh without tetrahedra")
    field_arrays = (
        None
        if material_field is None
        else material_field_arrays(material_field, tet_count=mesh.tet_count)
    )
    volumes = mesh.volumes()
    if np.any(volumes <= 0):
        bad = int(np.flatnonzero(volumes <= 0)[0])
        raise MeshError(
            f"tetrahedron {bad} is inverted or degenerate (volume {volumes[bad]:.3e} m^3)",
            element=bad,
        )
    return field_arrays


def write_material_usd(
    path: str | Path,
    material: Any,
    *,
    provenance: Mapping[str, Any] | None = None,
    density_kg_per_m3: float = 1000.0,
) -> Path:
    """Write one fitted material as a material-library asset layer.

    The layer holds ``/World`` (provenance in customData under ``warptissue``, with software
    versions added) and the physics material ``/World/Materials/Tissue``, authored by the same
    code as the scene writer's material: ``physics:density``, ``physics:youngsModulus`` and
    ``physics:poissonsRatio`` (small-strain equivalent) plus the ``tissue:*`` attributes of
    ``TissueMaterialAPI``. Stage metadata: ``metersPerUnit = 1``, ``kilogramsPerUnit = 1``,
    ``upAxis = "Z"``. Reference it from a scene and bind it with purpose ``physics``.

    Args:
        path: The layer, a ``.usda`` file; written atomically.
        material: A ``warptissue.materials`` object or a dictionary in ``to_dict()`` form
            (see :func:`write_simulation_usd`).
        provenance: JSON-like metadata (fit quality, data file, ...).
        density_kg_per_m3: Mass density written as ``physics:density``.

    Returns:
        The path written.
    """

    path = Path(path)
    if path.suffix != ".usda":
        raise InputError("the material layer must be a .usda file", path=path)
    check_density(density_kg_per_m3)
    record = material_record(material)
    layer = Sdf.Layer.CreateAnonymous(".usda")
    set_stage_metadata(layer)
    stage = Usd.Stage.Open(layer)
    world = UsdGeom.Xform.Define(stage, WORLD)
    info = {"software": software_versions()}
    if provenance:
        info.update(provenance)
    world.GetPrim().SetCustomDataByKey("warptissue", vt_dictionary(info))
    material_prims(stage, record, density_kg_per_m3)
    with atomic_path(path) as temporary:
        layer.Export(str(temporary))
    return path


# The old paths of names that moved, with a DeprecationWarning naming the new one
# (warptissue._deprecated.MOVED).
__getattr__ = moved_names(__name__)
