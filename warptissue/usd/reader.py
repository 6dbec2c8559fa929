"""Read warptissue scenes (and plain UsdGeom.TetMesh assets) back from USD."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from pxr import Usd, UsdGeom, UsdShade

from warptissue._stage import open_stage
from warptissue.errors import InputError
from warptissue.mesh import TetMesh, read_mesh, tetmesh_prim
from warptissue.usd.schema import record_from_attributes
from warptissue.usd.trainer import SMALL_STRAIN, TRAINER_KEY
from warptissue.usd.writer import (
    INDENTER,
    MATERIAL,
    MATERIAL_FIELD_PRIMVARS,
)

__all__ = [
    "open_stage",
    "read_material_field_usd",
    "read_material_usd",
    "read_particle_radii_usd",
    "read_probe_curve_usd",
    "read_tetmesh_usd",
]


def read_tetmesh_usd(path: str | Path, *, prim_path: str | None = None) -> TetMesh:
    """Read a tetrahedral mesh (rest shape) from a USD file.

    Args:
        path: A warptissue scene (root or asset layer) or any stage with a ``UsdGeom.TetMesh``.
        prim_path: The TetMesh prim; None takes the first TetMesh in traversal order.

    Returns:
        A TET4 mesh: points (the ``points`` default value, i.e. the rest shape; float32 in
        USD), connectivity (left-handed meshes are reordered to positive orientation), node
        sets from ``nodeSet`` point subsets, material regions from ``materialRegion``
        tetrahedron subsets, and face sets from the ``faceSet`` subsets of the sibling surface
        Mesh written by :func:`warptissue.usd.write_simulation_usd`. The reading is
        :func:`warptissue.mesh.read_mesh`'s for a USD file (a study's ``[specimen] mesh``).
    """
    return read_mesh(path, prim_path=prim_path, reorient=False)


def read_material_field_usd(
    path: str | Path, *, prim_path: str | None = None
) -> dict[str, np.ndarray]:
    """Read the per-tet material field of a TetMesh.

    Args:
        path: A scene written by :func:`warptissue.usd.write_simulation_usd` with a
            ``material_field``, or any stage whose TetMesh has those primvars.
        prim_path: The TetMesh prim; None takes the first TetMesh in traversal order.

    Returns:
        ``{"youngs_modulus_Pa": (M,), "poissons_ratio": (M,)}``, float64, in the order of
        ``tetVertexIndices`` (the order of :func:`read_tetmesh_usd`'s tets), from the uniform
        primvars ``primvars:tissue:youngsModulus`` and ``primvars:tissue:poissonsRatio``.

    Raises:
        InputError: A primvar is missing, has no default value, is not uniform or does not
            hold one value per tet.
    """

    path = Path(path)
    stage = open_stage(path)
    prim = tetmesh_prim(stage, path, prim_path)
    tetmesh = UsdGeom.TetMesh(prim)
    tet_count = len(tetmesh.GetTetVertexIndicesAttr().Get() or [])
    primvars = UsdGeom.PrimvarsAPI(prim)
    field = {}
    for key, (name, _) in MATERIAL_FIELD_PRIMVARS.items():
        primvar = primvars.GetPrimvar(name)
        value = primvar.ComputeFlattened() if primvar else None
        if value is None:
            raise InputError(f"TetMesh {prim.GetPath()} has no primvars:{name}", path=path)
        if primvar.GetInterpolation() != UsdGeom.Tokens.uniform or len(value) != tet_count:
            raise InputError(
                f"primvars:{name} of {prim.GetPath()} must be uniform with one value per tet "
                f"({tet_count}); it is {primvar.GetInterpolation()} with {len(value)}",
                path=path,
            )
        field[key] = np.asarray(value, dtype=np.float64)
    return field


def read_material_usd(path: str | Path) -> dict[str, Any]:
    """Read the physics material of a warptissue scene or material layer.

    Args:
        path: A scene written by :func:`warptissue.usd.write_simulation_usd` (the material
            bound to its TetMesh with purpose ``physics``) or a material layer written by
            :func:`warptissue.usd.write_material_usd` (its ``/World/Materials/Tissue``).

    Returns:
        ``{"material": to_dict()-form record (Prony terms as prony_g / prony_tau_s),
        "density_kg_per_m3", "youngs_modulus_Pa", "poissons_ratio", "trainer"}``: the
        ``physics:`` values (the tissue's small-strain equivalents, or in a trainer's asset
        the calibrated ones) and the trainer calibration (None in an asset with the true
        values); a trainer's asset also gives the tissue's own as
        ``"small_strain_youngs_modulus_Pa"`` and ``"small_strain_poissons_ratio"``.
    """

    path = Path(path)
    stage = open_stage(path)
    if any(prim.IsA(UsdGeom.TetMesh) for prim in stage.Traverse()):
        prim = tetmesh_prim(stage, path, None)
        bound, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial("physics")
        if not bound:
            raise InputError(f"TetMesh {prim.GetPath()} has no physics material", path=path)
        material = bound.GetPrim()
    else:
        material = stage.GetPrimAtPath(MATERIAL)
        if not material:
            raise InputError(f"the stage holds no TetMesh and no {MATERIAL}", path=path)
    values = {}
    for attr in material.GetAttributes():
        name = attr.GetName()
        for namespace in ("tissue:hyperelastic:", "tissue:viscoelastic:"):
            if (
                name.startswith(namespace)
                and attr.HasAuthoredValue()
                and name != ("tissue:hyperelastic:model")
            ):
                value = attr.Get(Usd.TimeCode.Default())
                values[name[len(namespace) :]] = (
                    list(value) if hasattr(value, "__len__") else float(value)
                )
    record = {
        "material": record_from_attributes(
            str(material.GetAttribute("tissue:hyperelastic:model").Get()), values
        ),
        "density_kg_per_m3": float(material.GetAttribute("physics:density").Get()),
        "youngs_modulus_Pa": float(material.GetAttribute("physics:youngsModulus").Get()),
        "poissons_ratio": float(material.GetAttribute("physics:poissonsRatio").Get()),
        "trainer": _plain(material.GetCustomDataByKey(TRAINER_KEY)),
    }
    for key, name in zip(
        ("small_strain_youngs_modulus_Pa", "small_strain_poissons_ratio"), SMALL_STRAIN, strict=True
    ):
        attr = material.GetAttribute(name)
        if attr and attr.HasAuthoredValue():
            record[key] = float(attr.Get())
    return record


def read_particle_radii_usd(path: str | Path, *, prim_path: str | None = None) -> np.ndarray | None:
    """The TetMesh's particle radii, ``primvars:widths`` / 2, (N,), m, in the order of its
    points; None where the asset has none (written without ``--trainer``).

    NVIDIA Newton 1.8's ``add_usd`` does not read widths of a TetMesh: set them with
    ``builder.particle_radius[start:end] = radii`` after the import.
    """
    path = Path(path)
    stage = open_stage(path)
    prim = tetmesh_prim(stage, path, prim_path)
    primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("widths")
    if not primvar or not primvar.HasValue():
        return None
    return 0.5 * np.asarray(primvar.Get(), dtype=np.float64)


def _plain(value: Any) -> Any:
    """customData as plain Python (dicts, lists, floats); None stays None."""
    if value is None:
        return None
    if hasattr(value, "items"):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)) or type(value).__name__.endswith("Array"):
        return [_plain(v) for v in value]
    return value


def read_probe_curve_usd(path: str | Path) -> dict[str, np.ndarray]:
    """Read the probe's time-sampled depth and reaction force.

    Args:
        path: The root layer of a scene written with a result.

    Returns:
        ``{"time_code": (S+1,), "depth_m": (S+1,), "reaction_force_N": (S+1,)}``, the rest state
        first.
    """
    path = Path(path)
    stage = open_stage(path)
    indenter = stage.GetPrimAtPath(INDENTER)
    depth = indenter.GetAttribute("tissue:probe:depth") if indenter else None
    if not depth or not depth.GetTimeSamples():
        raise InputError(
            "the scene holds no probe curve (was it written with a result?)", path=path
        )
    force = indenter.GetAttribute("tissue:probe:reactionForce")
    times = np.asarray(depth.GetTimeSamples(), dtype=np.float64)
    return {
        "time_code": times,
        "depth_m": np.array([depth.Get(t) for t in times]),
        "reaction_force_N": np.array([force.Get(t) for t in times]),
    }
