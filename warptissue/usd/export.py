"""Export the outputs of ``warptissue simulate`` (or a study) as a USD scene.

``warptissue simulate STUDY --out DIR`` writes ``DIR/result.json`` (the study echoed back,
the force curve, completion status), ``DIR/force_curve.csv``, ``DIR/fields.vtu`` (mesh,
node sets as ``node_set:<name>`` point data, ``tet_region`` cell data, the last step's
``displacement_m``, ``cauchy_stress_Pa`` and ``von_mises_Pa``) and optionally
``DIR/fields_NNN.vtu`` (the displacement of every step). :func:`export_result_dir` turns such
a folder into a scene; :func:`export_study` writes a study's specimen and material without
results. ``warptissue simulate --usd`` and ``warptissue fit ... --usd`` call
:func:`export_result_dir`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.indenter import Indenter
from warptissue.mesh import TetMesh
from warptissue.usd.writer import UsdScenePaths, write_simulation_usd

__all__ = ["export_result_dir", "export_study", "read_fields_vtu"]

NODE_SET_PREFIX = "node_set:"
TET_REGION_KEY = "tet_region"
_CELL_TYPES = {"tetra": 4, "tetra10": 10}


def read_fields_vtu(
    path: str | Path,
) -> tuple[TetMesh, dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Read a ``fields.vtu`` written by ``warptissue simulate``.

    Args:
        path: The VTU file.

    Returns:
        ``(mesh, point_data, cell_data)``: the mesh with its node sets and regions, and the
        remaining nodal (N, ...) and per-tet (M, ...) fields by name.
    """
    import meshio

    path = Path(path)
    if not path.is_file():
        raise InputError("no such VTU file", path=path)
    try:
        data = meshio.read(path)
    except Exception as exc:  # meshio raises many types for malformed files
        raise InputError(f"cannot read VTU: {exc}", path=path) from None
    blocks = [i for i, block in enumerate(data.cells) if block.type in _CELL_TYPES]
    if len(blocks) != 1:
        raise InputError("expected exactly one tetra or tetra10 cell block", path=path)
    block = blocks[0]
    point_data = {k: np.asarray(v) for k, v in data.point_data.items()}
    cell_data = {k: np.asarray(v[block]) for k, v in data.cell_data.items()}
    node_sets = {
        name[len(NODE_SET_PREFIX) :]: np.flatnonzero(point_data.pop(name)).astype(np.int32)
        for name in list(point_data)
        if name.startswith(NODE_SET_PREFIX)
    }
    regions = cell_data.pop(TET_REGION_KEY, None)
    mesh = TetMesh(
        points=np.asarray(data.points, dtype=np.float64),
        tets=np.asarray(data.cells[block].data),
        node_sets=node_sets,
        tet_regions=None if regions is None else regions.astype(np.int32).ravel(),
    )
    return mesh, point_data, cell_data


def _read_summary(result_dir: Path) -> dict[str, Any]:
    path = result_dir / "result.json"
    if not path.is_file():
        raise InputError(
            "no result.json: is this a 'warptissue simulate' output folder?", path=path
        )
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise InputError(
            f"result.json is not valid JSON: {exc.msg}",
            path=path,
            line=exc.lineno,
            column=exc.colno,
        ) from None


def _read_indenter(spec: Any, path: Path) -> Indenter | None:
    """The indenter ``result.json`` echoes in ``study.indenter`` (None where it has none)."""
    if not spec:
        return None
    if not isinstance(spec, Mapping):
        raise InputError("study.indenter must be a table", path=path, value=spec)
    try:
        return Indenter.from_dict(spec)
    except InputError as exc:
        raise InputError(
            f"study.indenter.{exc.column}: {exc.message}", path=path, value=exc.value
        ) from None


def export_result_dir(
    result_dir: str | Path,
    usd_path: str | Path,
    *,
    material: Any = None,
    provenance: Mapping[str, Any] | None = None,
    density_kg_per_m3: float = 1000.0,
) -> UsdScenePaths:
    """Write a ``warptissue simulate`` output folder as a layered USD scene.

    Args:
        result_dir: The folder with ``result.json`` and ``fields.vtu``.
        usd_path: The root layer to write, ``NAME.usda``.
        material: The material to record; None takes ``result.json``'s ``study.material``
            (a fit passes its fitted material here).
        provenance: Extra provenance (data file, fit quality, ...) for ``/World``'s customData.
        density_kg_per_m3: Mass density for ``physics:density``.

    Returns:
        The paths written. Every step's deformed shape is written when ``fields_NNN.vtu``
        exist for all steps; otherwise only the last step's (time samples at 0 and S).
    """
    result_dir = Path(result_dir)
    summary = _read_summary(result_dir)
    mesh, point_data, cell_data = read_fields_vtu(result_dir / "fields.vtu")
    curve = summary.get("force_curve") or {}
    depths = np.asarray(curve.get("depth_m", []), dtype=np.float64)
    forces = np.asarray(curve.get("reaction_force_N", []), dtype=np.float64)
    study = summary.get("study") or {}
    if material is None:
        material = study.get("material")
    result = None
    if depths.size:
        step_files = [result_dir / f"fields_{k:03d}.vtu" for k in range(1, depths.size + 1)]
        if all(p.is_file() for p in step_files):
            displacement = np.stack([read_fields_vtu(p)[1]["displacement_m"] for p in step_files])
        else:
            displacement = point_data.get("displacement_m")
        result = {
            "depths_m": depths,
            "reaction_force_N": forces,
            "displacement_m": displacement,
            "cauchy_stress_Pa": cell_data.get("cauchy_stress_Pa"),
            "von_mises_Pa": cell_data.get("von_mises_Pa"),
            "completed": summary.get("completed"),
            "message": summary.get("message"),
        }
    indenter = _read_indenter(study.get("indenter"), result_dir / "result.json")
    info: dict[str, Any] = {
        "result_dir": str(result_dir.resolve()),
        "study_file": str(study.get("path", "")),
        "study_name": str(study.get("name", "")),
        "simulation_software": summary.get("software", {}),
    }
    if provenance:
        info.update(provenance)
    return write_simulation_usd(
        usd_path,
        mesh,
        material=material,
        result=result,
        provenance=info,
        density_kg_per_m3=density_kg_per_m3,
        indenter=indenter,
    )


def export_study(
    study_path: str | Path, usd_path: str | Path, *, density_kg_per_m3: float = 1000.0
) -> UsdScenePaths:
    """Write a study's specimen mesh, material and indenter as a USD scene (no results).

    Args:
        study_path: A study TOML file (see the README's study keys).
        usd_path: The root layer to write, ``NAME.usda``.
        density_kg_per_m3: Mass density for ``physics:density``.

    Returns:
        The paths written.
    """
    from warptissue.simulate import build_mesh
    from warptissue.study import load_study

    study = load_study(study_path)
    return write_simulation_usd(
        usd_path,
        build_mesh(study),
        material=study.material,
        provenance={"study_file": str(Path(study_path).resolve()), "study_name": study.name},
        density_kg_per_m3=density_kg_per_m3,
        indenter=study.indenter,
    )
