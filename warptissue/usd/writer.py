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
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdPhysics, UsdShade, Vt

from warptissue.errors import InputError, MeshError
from warptissue.indenter import Indenter
from warptissue.io import atomic_path, software_versions, to_jsonable
from warptissue.materials import material_from_dict
from warptissue.mesh import FACE_SET_FAMILY, NODE_SET_FAMILY, REGION_FAMILY, TetMesh
from warptissue.usd.schema import (
    DEFORMABLE_BODY_API,
    TISSUE_MATERIAL_API,
    VOLUME_DEFORMABLE_MATERIAL_API,
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

MATERIAL_FIELD_PRIMVARS = {
    "youngs_modulus_Pa": ("tissue:youngsModulus", "Pa"),
    "poissons_ratio": ("tissue:poissonsRatio", "1"),
}
"""Per-tet material field: ``material_field`` key -> (uniform primvar name, unit customData)."""

CONTACT_RESULTS = ("contact_area_m2", "contact_pressure_Pa")
"""Optional results of a rigid indenter in contact: the contact area per step (S,), m^2,
written as ``tissue:probe:contactArea`` on ``/World/Indenter``, and the nodal contact
pressure (S, N) (or (N,): the last step), Pa, written as the vertex primvar
``primvars:tissue:contactPressure`` of the surface Mesh."""

WORLD = "/World"
SPECIMEN = "/World/Specimen"
VOLUME = "/World/Specimen/Volume"
SURFACE = "/World/Specimen/Surface"
MATERIAL = "/World/Materials/Tissue"
INDENTER = "/World/Indenter"


@dataclass(frozen=True)
class UsdScenePaths:
    """The files of a written scene.

    Attributes:
        root: The root layer (open this one).
        asset: The asset layer.
        results: The results layer, or None when no result was written.
    """

    root: Path
    asset: Path
    results: Path | None


def result_field(result: Any, name: str) -> Any:
    """A result's field ``name``: a mapping's key or an object's attribute (None without)."""
    if isinstance(result, Mapping):
        return result.get(name)
    return getattr(result, name, None)


def corner_mesh(mesh: TetMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Corner nodes of a TET4/TET10 mesh: (kept node ids (n,), renumbered tets (M,4), map)."""
    corners = mesh.tets[:, :4]
    kept = np.unique(corners)
    new_index = np.full(mesh.node_count, -1, dtype=np.int64)
    new_index[kept] = np.arange(kept.size)
    return kept, new_index[corners].astype(np.int32), new_index


def vt_dictionary(data: Mapping[str, Any]) -> dict[str, Any]:
    """JSON-like data as values USD customData accepts (nested dicts, str, float, int, bool)."""

    converted: dict[str, Any] = {}
    for key, value in to_jsonable(data).items():
        if isinstance(value, Mapping):
            converted[key] = vt_dictionary(value)
        elif isinstance(value, (str, bool, int, float)):
            converted[key] = value
        elif isinstance(value, list) and value and all(isinstance(v, str) for v in value):
            converted[key] = Vt.StringArray(value)
        elif (
            isinstance(value, list)
            and value
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
        ):
            converted[key] = Vt.DoubleArray([float(v) for v in value])
        elif value is not None:
            converted[key] = json.dumps(value)
    return converted


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


def check_density(density_kg_per_m3: float) -> None:
    """Refuse a mass density that is not a positive number (kg/m^3)."""
    if not (np.isfinite(density_kg_per_m3) and density_kg_per_m3 > 0):
        raise InputError("density must be positive", value=density_kg_per_m3)


def material_field_problems(key: str, values: Any, *, count: int) -> list[str]:
    """What is wrong with one array of a per-tet material field (empty when it is valid).

    Args:
        key: ``"youngs_modulus_Pa"`` (must be > 0) or ``"poissons_ratio"`` (must lie in the
            open interval (-1, 0.5): a linear elastic solid is stable there, and nu = 0.5
            makes the bulk modulus infinite).
        values: The array, one value per element.
        count: The expected number of values (tets, or faces of the surface Mesh).

    Returns:
        One sentence per problem: shape, non-finite values, values out of range (the first
        offending index and value named).
    """
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        return [f"{key} is not an array of numbers"]
    if array.shape != (count,):
        return [f"{key} has shape {array.shape}, expected ({count},)"]
    problems = []
    finite = np.isfinite(array)
    if not finite.all():
        bad = int(np.flatnonzero(~finite)[0])
        problems.append(f"{key} holds non-finite values (first at index {bad}: {array[bad]})")
    if key == "youngs_modulus_Pa":
        invalid = finite & ~(array > 0.0)
        allowed = "> 0"
    else:
        invalid = finite & ~((array > -1.0) & (array < 0.5))
        allowed = "in (-1, 0.5)"
    if invalid.any():
        bad = int(np.flatnonzero(invalid)[0])
        problems.append(
            f"{key} must be {allowed}: {int(invalid.sum())} values are not "
            f"(first at index {bad}: {float(array[bad])!r})"
        )
    return problems


def _material_field_arrays(material_field: Mapping[str, Any], *, tet_count: int) -> dict:
    """Validated per-tet arrays of ``material_field`` (see :func:`write_simulation_usd`)."""
    if not isinstance(material_field, Mapping) or set(material_field) != set(
        MATERIAL_FIELD_PRIMVARS
    ):
        keys = sorted(material_field) if isinstance(material_field, Mapping) else None
        raise InputError(
            f"material_field must map exactly {sorted(MATERIAL_FIELD_PRIMVARS)} to per-tet arrays",
            value=keys,
        )
    arrays = {}
    for key in MATERIAL_FIELD_PRIMVARS:
        problems = material_field_problems(key, material_field[key], count=tet_count)
        if problems:
            raise InputError(f"material_field: {problems[0]}")
        arrays[key] = np.asarray(material_field[key], dtype=np.float64)
    return arrays


def _material_field_primvars(
    stage: Any, arrays: Mapping[str, np.ndarray], *, owners: np.ndarray
) -> None:
    """Per-tet values on the TetMesh and per-face values (of the owning tet) on the surface."""

    volume = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath(VOLUME))
    surface = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath(SURFACE))
    for key, (name, unit) in MATERIAL_FIELD_PRIMVARS.items():
        for api, values in ((volume, arrays[key]), (surface, arrays[key][owners])):
            primvar = api.CreatePrimvar(
                name, Sdf.ValueTypeNames.DoubleArray, UsdGeom.Tokens.uniform
            )
            primvar.Set(Vt.DoubleArray.FromNumpy(np.ascontiguousarray(values)))
            primvar.GetAttr().SetCustomDataByKey("unit", unit)


def set_stage_metadata(layer: Any) -> None:
    """SI units and z up: the project's coordinates (indentation along -z) need no rotation."""
    layer.defaultPrim = "World"
    metadata = {"metersPerUnit": 1.0, "kilogramsPerUnit": 1.0, "upAxis": "Z"}
    pseudo = layer.pseudoRoot
    for key, value in metadata.items():
        pseudo.SetInfo(key, value)


def material_prims(
    stage: Any, record: Any, density_kg_per_m3: float, *, path: str = MATERIAL
) -> Any:
    """The physics material: proposal small-strain attributes plus the ``tissue:`` schema.

    Returns:
        The ``UsdShade.Material`` at ``path`` (``/World/Materials/Tissue``).
    """

    UsdGeom.Scope.Define(stage, path.rsplit("/", 1)[0])
    material = UsdShade.Material.Define(stage, path)
    prim = material.GetPrim()
    prim.AddAppliedSchema(VOLUME_DEFORMABLE_MATERIAL_API)
    prim.AddAppliedSchema(TISSUE_MATERIAL_API)
    for name, value in (
        ("density", density_kg_per_m3),
        ("youngsModulus", record.youngs_modulus_Pa),
        ("poissonsRatio", record.poissons_ratio),
    ):
        prim.CreateAttribute(f"physics:{name}", Sdf.ValueTypeNames.Float, custom=False).Set(
            float(value)
        )
    # Declared types and variability match generatedSchema.usda, so the values are written
    # the same whether or not the schema registry saw the plugin.
    tissue_values: list[tuple[str, Any]] = [
        ("tissue:convention", "abaqus"),
        ("tissue:hyperelastic:model", record.model),
    ]
    tissue_values += [(f"tissue:hyperelastic:{k}", v) for k, v in record.hyperelastic.items()]
    if record.prony_g.size:
        tissue_values += [
            ("tissue:viscoelastic:pronyG", record.prony_g),
            ("tissue:viscoelastic:pronyTau", record.prony_tau_s),
        ]
    for attr_name, value in tissue_values:
        if isinstance(value, str):
            type_name, usd_value = Sdf.ValueTypeNames.Token, value
        elif isinstance(value, np.ndarray):
            type_name, usd_value = Sdf.ValueTypeNames.DoubleArray, Vt.DoubleArray.FromNumpy(value)
        else:
            type_name, usd_value = Sdf.ValueTypeNames.Double, float(value)
        prim.CreateAttribute(
            attr_name, type_name, custom=False, variability=Sdf.VariabilityUniform
        ).Set(usd_value)
    prim.SetCustomDataByKey("warptissue:material", vt_dictionary(record.source))
    return material


def bind_materials(stage: Any, volume_prim: Any, material: Any, density_kg_per_m3: float) -> Any:
    """The run's materials, bound with purpose ``physics``: the material (a body of several
    regions: its default) at ``/World/Materials/Tissue`` to the TetMesh, and each named region's
    (:class:`warptissue.materials.MaterialRegions`) at ``/World/Materials/<name>`` to the
    TetMesh's ``materialRegion`` subsets of its tet regions.

    Returns:
        The ``UsdShade.Material`` bound to the TetMesh.

    Raises:
        InputError: The TetMesh has no ``materialRegion`` subset of a region's tet region.
    """
    if isinstance(material, Mapping) and "regions" in material:  # result.json's table
        material = material_from_dict(material)
    parts = material.parts if hasattr(material, "parts") else (("", material),)
    tissue = material_prims(stage, material_record(material), density_kg_per_m3)
    UsdShade.MaterialBindingAPI.Apply(volume_prim).Bind(
        tissue, UsdShade.Tokens.fallbackStrength, "physics"
    )
    for prefix, part in parts[1:]:
        name = prefix[:-1]
        region = material_prims(
            stage,
            material_record(part),
            density_kg_per_m3,
            path=f"{MATERIAL.rsplit('/', 1)[0]}/{Tf.MakeValidIdentifier(name)}",
        )
        for each in material.tet_regions[name]:
            subset = volume_prim.GetChild(Tf.MakeValidIdentifier(f"{REGION_FAMILY}_{each}"))
            if not subset.IsValid():
                raise InputError(
                    f"the TetMesh has no {REGION_FAMILY} subset of tet region {each} to bind "
                    f"region {name!r}'s material to",
                    key=f"material.regions.{name}.tet_regions",
                )
            UsdShade.MaterialBindingAPI.Apply(subset).Bind(
                region, UsdShade.Tokens.fallbackStrength, "physics"
            )
    return tissue


def result_arrays(result: Any, *, node_count: int, tet_count: int) -> dict[str, np.ndarray]:
    """Validated result arrays (see :func:`write_simulation_usd`)."""
    arrays: dict[str, np.ndarray] = {}
    for name in ("depths_m", "reaction_force_N", "displacement_m"):
        value = result_field(result, name)
        if value is None:
            raise InputError(f"the result has no {name!r}", value=type(result).__name__)
        arrays[name] = np.asarray(value, dtype=np.float64)
    for name in ("cauchy_stress_Pa", "von_mises_Pa", "time_s", *CONTACT_RESULTS):
        value = result_field(result, name)
        if value is not None:
            arrays[name] = np.asarray(value, dtype=np.float64)
    for name in CONTACT_RESULTS:  # a sharp flat punch's result holds them empty
        if name in arrays and arrays[name].size == 0:
            del arrays[name]
    step_count = arrays["depths_m"].shape[0] if arrays["depths_m"].ndim == 1 else -1
    expected = {
        "depths_m": (step_count,),
        "reaction_force_N": (step_count,),
        "time_s": (step_count,),
        "displacement_m": (step_count, node_count, 3),
        "cauchy_stress_Pa": (tet_count, 6),
        "von_mises_Pa": (tet_count,),
        "contact_area_m2": (step_count,),
        "contact_pressure_Pa": (step_count, node_count),
    }
    if arrays["displacement_m"].ndim == 2:
        expected["displacement_m"] = (node_count, 3)
    if "contact_pressure_Pa" in arrays and arrays["contact_pressure_Pa"].ndim == 1:
        expected["contact_pressure_Pa"] = (node_count,)
    for name, array in arrays.items():
        if array.shape != expected[name]:
            raise InputError(
                f"result {name!r} has shape {array.shape}, expected {expected[name]}",
                value=array.shape,
            )
        if not np.all(np.isfinite(array)):
            raise InputError(f"result {name!r} holds non-finite values")
    if step_count < 1:
        raise InputError("the result has no load steps", value=step_count)
    return arrays


def result_summary(arrays: Mapping[str, np.ndarray], result: Any) -> dict[str, Any]:
    """The result's ``customData`` on ``/World``: its step count, the time-code rule, and
    ``completed`` and ``message`` where the result has them."""
    summary: dict[str, Any] = {
        "step_count": len(arrays["depths_m"]),
        "time_code_of_step_k": "k (time code 0 is the rest state)",
    }
    for name in ("completed", "message"):
        if result_field(result, name) is not None:
            summary[name] = result_field(result, name)
    return summary


def declare_result_attributes(
    stage: Any,
    arrays: Mapping[str, np.ndarray],
    *,
    volume_path: str = VOLUME,
    surface_path: str | None = SURFACE,
) -> None:
    """Declare (type, interpolation, unit; no values) the attributes the results layer samples
    (on the surface Mesh only where ``surface_path`` is given)."""

    volume = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath(volume_path))
    surface = (
        None if surface_path is None else UsdGeom.PrimvarsAPI(stage.GetPrimAtPath(surface_path))
    )
    declared = [
        (
            volume.CreatePrimvar(
                "tissue:displacement", Sdf.ValueTypeNames.Vector3fArray, UsdGeom.Tokens.vertex
            ),
            "m",
        ),
    ]
    if "cauchy_stress_Pa" in arrays:
        stress = volume.CreatePrimvar(
            "tissue:cauchyStress", Sdf.ValueTypeNames.DoubleArray, UsdGeom.Tokens.uniform, 6
        )
        stress.GetAttr().SetCustomDataByKey("components", "xx, yy, zz, yz, xz, xy")
        declared.append((stress, "Pa"))
    if "von_mises_Pa" in arrays:
        for api in (volume, surface) if surface is not None else (volume,):
            declared.append(
                (
                    api.CreatePrimvar(
                        "tissue:vonMises", Sdf.ValueTypeNames.DoubleArray, UsdGeom.Tokens.uniform
                    ),
                    "Pa",
                )
            )
    if "contact_pressure_Pa" in arrays and surface is not None:
        declared.append(
            (
                surface.CreatePrimvar(
                    "tissue:contactPressure", Sdf.ValueTypeNames.DoubleArray, UsdGeom.Tokens.vertex
                ),
                "Pa",
            )
        )
    for primvar, unit in declared:
        primvar.GetAttr().SetCustomDataByKey("unit", unit)
    indenter = stage.GetPrimAtPath(INDENTER)
    if not indenter:
        UsdGeom.Xform.Define(stage, INDENTER).AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 0.0))
        indenter = stage.GetPrimAtPath(INDENTER)
    curves = [("depth", "m"), ("reactionForce", "N")] + (
        [("time", "s")] if "time_s" in arrays else []
    )
    if "contact_area_m2" in arrays:
        curves.append(("contactArea", "m2"))
    for name, unit in curves:
        attr = indenter.CreateAttribute(
            f"tissue:probe:{name}", Sdf.ValueTypeNames.Double, custom=True
        )
        attr.SetCustomDataByKey("unit", unit)


def write_results(
    stage: Any,
    arrays: Mapping[str, np.ndarray],
    *,
    kept: np.ndarray,
    surface_nodes: np.ndarray | None,
    owners: np.ndarray | None,
    rest: np.ndarray,
    volume_path: str = VOLUME,
    surface_path: str | None = SURFACE,
) -> None:
    """Author the time samples (stage's edit target: the results layer); ``surface_path``
    None: no surface Mesh to sample."""

    volume = UsdGeom.TetMesh(stage.GetPrimAtPath(volume_path))
    surface = None if surface_path is None else UsdGeom.Mesh(stage.GetPrimAtPath(surface_path))
    volume_api = UsdGeom.PrimvarsAPI(volume)
    indenter = stage.GetPrimAtPath(INDENTER)
    operations = UsdGeom.Xformable(indenter).GetOrderedXformOps()
    translate = operations[0]
    contact = translate.Get()
    along = Gf.Vec3d(0.0, 0.0, -1.0)  # the probe's direction: -z, or the frame's -e3
    if len(operations) > 1 and operations[1].GetOpType() == UsdGeom.XformOp.TypeOrient:
        turn = Gf.Matrix4d().SetRotate(operations[1].Get())
        along = -Gf.Vec3d(turn.GetRow3(2))
    points_attr, displacement_attr = (
        volume.GetPointsAttr(),
        volume_api.GetPrimvar("tissue:displacement").GetAttr(),
    )
    step_count = len(arrays["depths_m"])
    displacement = arrays["displacement_m"]
    if displacement.ndim == 2:
        shapes = {0: np.zeros_like(rest), step_count: displacement[kept]}
    else:
        shapes = {0: np.zeros_like(rest)}
        shapes.update({k + 1: displacement[k, kept] for k in range(step_count)})
    for time_code, nodal in shapes.items():
        deformed = (rest + nodal).astype(np.float32)
        points_attr.Set(Vt.Vec3fArray.FromNumpy(deformed), time_code)
        if surface is not None:
            surface.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(deformed[surface_nodes]), time_code)
        displacement_attr.Set(Vt.Vec3fArray.FromNumpy(nodal.astype(np.float32)), time_code)
    depths = np.concatenate([[0.0], arrays["depths_m"]])
    forces = np.concatenate([[0.0], arrays["reaction_force_N"]])
    for time_code, (depth, force) in enumerate(zip(depths, forces, strict=True)):
        translate.Set(Gf.Vec3d(contact) + float(depth) * along, time_code)
        indenter.GetAttribute("tissue:probe:depth").Set(float(depth), time_code)
        indenter.GetAttribute("tissue:probe:reactionForce").Set(float(force), time_code)
    if "time_s" in arrays:
        for k, time in enumerate(arrays["time_s"]):
            indenter.GetAttribute("tissue:probe:time").Set(float(time), k + 1)
    if "contact_area_m2" in arrays:
        area_attr = indenter.GetAttribute("tissue:probe:contactArea")
        for time_code, area in enumerate(np.concatenate([[0.0], arrays["contact_area_m2"]])):
            area_attr.Set(float(area), time_code)
    if "contact_pressure_Pa" in arrays and surface is not None:
        pressure = arrays["contact_pressure_Pa"]
        pressure_attr = UsdGeom.PrimvarsAPI(surface).GetPrimvar("tissue:contactPressure")
        rest_pressure = np.zeros(len(surface_nodes))
        if pressure.ndim == 1:
            samples = {0: rest_pressure, step_count: pressure[kept][surface_nodes]}
        else:
            samples = {0: rest_pressure}
            samples.update({k + 1: pressure[k, kept][surface_nodes] for k in range(step_count)})
        for time_code, values in samples.items():
            pressure_attr.Set(Vt.DoubleArray.FromNumpy(np.ascontiguousarray(values)), time_code)
    last = step_count
    if "cauchy_stress_Pa" in arrays:
        volume_api.GetPrimvar("tissue:cauchyStress").Set(
            Vt.DoubleArray.FromNumpy(arrays["cauchy_stress_Pa"].ravel()), last
        )
    if "von_mises_Pa" in arrays:
        von_mises = arrays["von_mises_Pa"]
        volume_api.GetPrimvar("tissue:vonMises").Set(Vt.DoubleArray.FromNumpy(von_mises), last)
        if surface is not None:
            UsdGeom.PrimvarsAPI(surface).GetPrimvar("tissue:vonMises").Set(
                Vt.DoubleArray.FromNumpy(von_mises[owners]), last
            )


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
    if root_path.suffix != ".usda":
        raise InputError("the root layer must be a .usda file", path=root_path)
    check_density(density_kg_per_m3)
    if mesh.tet_count == 0:
        raise MeshError("cannot export a mesh without tetrahedra")
    field_arrays = (
        None
        if material_field is None
        else _material_field_arrays(material_field, tet_count=mesh.tet_count)
    )
    volumes = mesh.volumes()
    if np.any(volumes <= 0):
        bad = int(np.flatnonzero(volumes <= 0)[0])
        raise MeshError(
            f"tetrahedron {bad} is inverted or degenerate (volume {volumes[bad]:.3e} m^3)",
            element=bad,
        )

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
        _material_field_primvars(stage, field_arrays, owners=owners)

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
