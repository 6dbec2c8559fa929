"""The trainer-calibrated physics material and contact sizes of an asset.

A real-time simulator reads ``physics:youngsModulus`` and ``physics:poissonsRatio`` and runs
them on linear tets, which lock near incompressibility. An asset written with a
:class:`warptissue.fit.trainer.TrainerCalibration` carries, on ``/World/Materials/Tissue``:

- ``physics:youngsModulus`` / ``physics:poissonsRatio``: the calibrated values, which make
  the trainer's linear tets reproduce the tissue's force;
- ``tissue:smallStrain:youngsModulus`` / ``tissue:smallStrain:poissonsRatio``: the tissue's
  own small-strain equivalents (what ``export --physics true`` writes as ``physics:``), beside
  the full fitted model in ``tissue:hyperelastic:*`` and ``tissue:viscoelastic:*``;
- ``customData["warptissue:trainer"]``: the calibration (its probes' force curves, errors,
  the volume change, what it cannot match).

And on the TetMesh, for contact: ``primvars:widths`` (vertex, m), each particle's diameter,
the mean length of the edges that meet at it (neighbouring particles' spheres just touch), and
``customData["warptissue:contact"]`` with the smallest and largest particle radius and the
contact margin (the largest radius). NVIDIA Newton 1.8's ``add_usd`` reads widths for
``UsdGeom.Points`` but not for a TetMesh; :func:`particle_radii_usd` reads them back to set
``ModelBuilder.particle_radius`` (docs/usd.md shows the two lines).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from pxr import Sdf, UsdGeom, Vt

from warptissue.errors import InputError

__all__ = [
    "CONTACT_KEY",
    "TRAINER_KEY",
    "author_contact_sizes",
    "author_trainer_material",
    "particle_radii",
]

TRAINER_KEY = "warptissue:trainer"
CONTACT_KEY = "warptissue:contact"
SMALL_STRAIN = ("tissue:smallStrain:youngsModulus", "tissue:smallStrain:poissonsRatio")


def particle_radii(points_m: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Half the mean length of the edges at each node of a TET4 mesh, (N,), m.

    Args:
        points_m: Node coordinates, (N, 3), m.
        tets: Corner indices, (M, 4).
    """
    tets = np.asarray(tets, dtype=np.int64)[:, :4]
    pairs = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])
    edges = np.sort(tets[:, pairs].reshape(-1, 2), axis=1)
    edges = np.unique(edges, axis=0)
    lengths = np.linalg.norm(points_m[edges[:, 0]] - points_m[edges[:, 1]], axis=1)
    total = np.bincount(edges.ravel(), weights=np.repeat(lengths, 2), minlength=len(points_m))
    count = np.bincount(edges.ravel(), minlength=len(points_m))
    return 0.5 * total / np.maximum(count, 1)


def author_contact_sizes(volume_prim: Any, points_m: np.ndarray, tets: np.ndarray) -> None:
    """``primvars:widths`` (vertex, particle diameters, m) and the contact customData."""
    radii = particle_radii(points_m, tets)
    primvar = UsdGeom.PrimvarsAPI(volume_prim).CreatePrimvar(
        "widths", Sdf.ValueTypeNames.FloatArray, UsdGeom.Tokens.vertex
    )
    primvar.Set(Vt.FloatArray.FromNumpy((2.0 * radii).astype(np.float32)))
    primvar.GetAttr().SetCustomDataByKey("unit", "m")
    volume_prim.SetCustomDataByKey(
        CONTACT_KEY,
        {
            "particle_radius_min_m": float(radii.min()),
            "particle_radius_max_m": float(radii.max()),
            "contact_margin_m": float(radii.max()),
            "rule": "particle radius = half the mean length of the edges at the node",
        },
    )


def author_trainer_material(
    material_prim: Any, calibration: Mapping[str, Any], custom_data: Any
) -> None:
    """Move the tissue's small-strain E and nu to ``tissue:smallStrain:*``, write the
    calibrated ones as ``physics:youngsModulus`` / ``physics:poissonsRatio`` and the
    calibration (``custom_data``, its customData form) under :data:`TRAINER_KEY`."""
    for key in ("youngs_modulus_Pa", "poissons_ratio"):
        if key not in calibration:
            raise InputError("the trainer calibration has no value", key=key)
    youngs = material_prim.GetAttribute("physics:youngsModulus")
    poisson = material_prim.GetAttribute("physics:poissonsRatio")
    for name, attr in zip(SMALL_STRAIN, (youngs, poisson), strict=True):
        material_prim.CreateAttribute(
            name, Sdf.ValueTypeNames.Double, custom=False, variability=Sdf.VariabilityUniform
        ).Set(float(attr.Get()))
    youngs.Set(float(calibration["youngs_modulus_Pa"]))
    poisson.Set(float(calibration["poissons_ratio"]))
    material_prim.SetCustomDataByKey(TRAINER_KEY, custom_data)
