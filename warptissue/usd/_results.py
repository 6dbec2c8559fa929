"""A result's arrays and their time samples: the deformed points, the displacement, stress
and contact primvars, the probe's curves."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from pxr import Gf, Sdf, UsdGeom, Vt

from warptissue.errors import InputError
from warptissue.usd._layout import (
    INDENTER,
    SURFACE,
    VOLUME,
)

CONTACT_RESULTS = ("contact_area_m2", "contact_pressure_Pa")
"""Optional results of a rigid indenter in contact: the contact area per step (S,), m^2,
written as ``tissue:probe:contactArea`` on ``/World/Indenter``, and the nodal contact
pressure (S, N) (or (N,): the last step), Pa, written as the vertex primvar
``primvars:tissue:contactPressure`` of the surface Mesh."""


def result_field(result: Any, name: str) -> Any:
    """A result's field ``name``: a mapping's key or an object's attribute (None without)."""
    if isinstance(result, Mapping):
        return result.get(name)
    return getattr(result, name, None)


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
