"""The scene's prim paths and the small pieces every layer writer shares: the written
paths, the corner mesh of a TET10, customData values, the stage metadata, the density check."""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pxr import Vt

from warptissue.errors import InputError
from warptissue.io import to_jsonable
from warptissue.mesh import TetMesh

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


def set_stage_metadata(layer: Any) -> None:
    """SI units and z up: the project's coordinates (indentation along -z) need no rotation."""
    layer.defaultPrim = "World"
    metadata = {"metersPerUnit": 1.0, "kilogramsPerUnit": 1.0, "upAxis": "Z"}
    pseudo = layer.pseudoRoot
    for key, value in metadata.items():
        pseudo.SetInfo(key, value)


def check_density(density_kg_per_m3: float) -> None:
    """Refuse a mass density that is not a positive number (kg/m^3)."""
    if not (np.isfinite(density_kg_per_m3) and density_kg_per_m3 > 0):
        raise InputError("density must be positive", value=density_kg_per_m3)
