"""The physics material of a scene: the proposal's small-strain attributes, the ``tissue:``
schema, the per-region bindings and the per-tet material field primvars."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from pxr import Sdf, Tf, UsdGeom, UsdShade, Vt

from warptissue.errors import InputError
from warptissue.materials import material_from_dict
from warptissue.mesh import REGION_FAMILY
from warptissue.usd._layout import (
    MATERIAL,
    SURFACE,
    VOLUME,
    vt_dictionary,
)
from warptissue.usd.schema import (
    TISSUE_MATERIAL_API,
    VOLUME_DEFORMABLE_MATERIAL_API,
    material_record,
)

MATERIAL_FIELD_PRIMVARS = {
    "youngs_modulus_Pa": ("tissue:youngsModulus", "Pa"),
    "poissons_ratio": ("tissue:poissonsRatio", "1"),
}
"""Per-tet material field: ``material_field`` key -> (uniform primvar name, unit customData)."""


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


def material_field_arrays(material_field: Mapping[str, Any], *, tet_count: int) -> dict:
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


def material_field_primvars(
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
