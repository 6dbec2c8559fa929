"""Validate USD scenes: the UsdValidation framework plus warptissue's own rules.

usd-core 26.8 removed ``UsdUtils.ComplianceChecker``; its checks live on as validators in the
``UsdValidation`` registry, which :func:`validate_stage` runs in full. On top of them it checks
what those validators do not: inverted tetrahedra (``UsdGeom.TetMesh.FindInvertedElements``) in
the rest shape and at every time sample, the surface faces against
``UsdGeom.TetMesh.ComputeSurfaceFaces``, SI stage units, the layering rules (no time samples in
an asset layer, only time samples in a results layer), physically valid deformable
material values, and the per-tet material field primvars where a TetMesh or Mesh has them
(uniform, one value per tet or face, finite, E > 0, -1 < nu < 0.5).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pxr import Sdf, Usd, UsdGeom, UsdValidation

from warptissue.usd.reader import open_stage
from warptissue.usd.schema import (
    TISSUE_MATERIAL_API,
    VOLUME_DEFORMABLE_MATERIAL_API,
    applied_schema_names,
)
from warptissue.usd.writer import MATERIAL_FIELD_PRIMVARS, material_field_problems

__all__ = ["validate_stage"]


def _framework_findings(stage: object) -> list[str]:
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    return [
        error.GetErrorAsString()
        for error in context.Validate(stage)
        if error.GetType() != UsdValidation.ValidationErrorType.None_
    ]


def _tetmesh_findings(stage: object) -> list[str]:
    findings = []
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.TetMesh):
            continue
        tetmesh = UsdGeom.TetMesh(prim)
        times = [Usd.TimeCode.Default()] + [
            Usd.TimeCode(t) for t in tetmesh.GetPointsAttr().GetTimeSamples()
        ]
        for time in times:
            inverted = list(UsdGeom.TetMesh.FindInvertedElements(tetmesh, time))
            if inverted:
                when = "rest shape" if time.IsDefault() else f"time {time.GetValue():g}"
                findings.append(
                    f"Error: (warptissue:InvertedElements) TetMesh {prim.GetPath()} has "
                    f"{len(inverted)} inverted tetrahedra at {when}, first {inverted[:5]}"
                )
        authored = tetmesh.GetSurfaceFaceVertexIndicesAttr().Get()
        if authored is not None:
            expected = np.sort(
                np.asarray(UsdGeom.TetMesh.ComputeSurfaceFaces(tetmesh)).reshape(-1, 3), axis=0
            )
            if not np.array_equal(np.sort(np.asarray(authored).reshape(-1, 3), axis=0), expected):
                findings.append(
                    f"Error: (warptissue:SurfaceFaces) TetMesh {prim.GetPath()}: "
                    "surfaceFaceVertexIndices differ from ComputeSurfaceFaces"
                )
    return findings


def _layer_findings(stage: object) -> list[str]:
    findings = []
    if UsdGeom.GetStageMetersPerUnit(stage) != 1.0:
        findings.append(
            f"Error: (warptissue:Units) metersPerUnit is {UsdGeom.GetStageMetersPerUnit(stage)}, "
            "not 1 (SI)"
        )
    kilograms = stage.GetRootLayer().pseudoRoot.GetInfo("kilogramsPerUnit")
    if kilograms != 1.0:
        findings.append(f"Error: (warptissue:Units) kilogramsPerUnit is {kilograms}, not 1 (SI)")
    for layer in stage.GetLayerStack(includeSessionLayers=False):
        name = Path(layer.identifier).name
        is_asset, is_results = name.endswith(".asset.usda"), name.endswith(".results.usdc")
        if not (is_asset or is_results):
            continue

        attribute_paths: list[Sdf.Path] = []
        layer.Traverse(
            Sdf.Path.absoluteRootPath,
            lambda path, found=attribute_paths: (
                found.append(path) if path.IsPropertyPath() else None
            ),
        )
        for path in attribute_paths:
            spec = layer.GetAttributeAtPath(path)
            if spec is None:
                continue
            if is_asset and layer.GetNumTimeSamplesForPath(path):
                findings.append(
                    f"Error: (warptissue:LayerRules) asset layer {name} holds time samples "
                    f"for {path}"
                )
            if is_results and spec.HasDefaultValue():
                findings.append(
                    f"Error: (warptissue:LayerRules) results layer {name} holds a default value "
                    f"for {path}"
                )
    return findings


def _material_findings(stage: object) -> list[str]:
    findings = []
    limits = {
        "physics:density": lambda v: v > 0,
        "physics:youngsModulus": lambda v: v > 0,
        "physics:poissonsRatio": lambda v: -1.0 < v <= 0.5,
    }
    for prim in stage.Traverse():
        applied = applied_schema_names(prim)
        if TISSUE_MATERIAL_API in applied and not prim.HasAPI(TISSUE_MATERIAL_API):
            findings.append(
                f"Error: (warptissue:Schema) {prim.GetPath()} applies {TISSUE_MATERIAL_API} but "
                "the schema is not registered (import warptissue.usd before opening stages)"
            )
        if VOLUME_DEFORMABLE_MATERIAL_API not in applied:
            continue
        for name, valid in limits.items():
            attr = prim.GetAttribute(name)
            value = attr.Get() if attr else None
            if value is None or not np.isfinite(value) or not valid(value):
                findings.append(
                    f"Error: (warptissue:Material) {prim.GetPath()}.{name} is missing or out of "
                    f"range: {value}"
                )
    return findings


def _material_field_findings(stage: object) -> list[str]:
    findings = []
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.TetMesh):
            counts = UsdGeom.TetMesh(prim).GetTetVertexIndicesAttr().Get()
        elif prim.IsA(UsdGeom.Mesh):
            counts = UsdGeom.Mesh(prim).GetFaceVertexCountsAttr().Get()
        else:
            continue
        count = len(counts or [])
        primvars = UsdGeom.PrimvarsAPI(prim)
        for key, (name, _) in MATERIAL_FIELD_PRIMVARS.items():
            primvar = primvars.GetPrimvar(name)
            if not (primvar and primvar.HasAuthoredValue()):
                continue
            where = f"{prim.GetPath()}.primvars:{name}"
            problems = []
            if primvar.GetInterpolation() != UsdGeom.Tokens.uniform:
                problems.append(f"interpolation is {primvar.GetInterpolation()}, not uniform")
            value = primvar.ComputeFlattened()
            if value is None:
                problems.append("no default value")
            else:
                problems += material_field_problems(key, np.asarray(value), count=count)
            findings += [f"Error: (warptissue:MaterialField) {where}: {p}" for p in problems]
    return findings


def validate_stage(path: str | Path) -> list[str]:
    """Validate a USD scene and return its findings (an empty list means valid).

    Args:
        path: The scene's root layer (or any USD file).

    Returns:
        One line per finding, ``"Error: (validator.ErrorName) message"`` (warnings start with
        ``Warning:``).
    """
    stage = open_stage(path)
    return (
        _framework_findings(stage)
        + _tetmesh_findings(stage)
        + _layer_findings(stage)
        + _material_findings(stage)
        + _material_field_findings(stage)
    )
