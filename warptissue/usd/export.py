"""Export the outputs of ``warptissue simulate`` (or a study) as a USD scene.

``warptissue simulate STUDY --out DIR`` writes ``DIR/result.json`` (the study echoed back,
the force curve, completion status), ``DIR/force_curve.csv``, ``DIR/fields.vtu`` (mesh,
node sets as ``node_set:<name>`` point data, ``tet_region`` cell data, the last step's
``displacement_m``, ``cauchy_stress_Pa`` and ``von_mises_Pa``, and under a rigid indenter
``contact_pressure_Pa``) and optionally ``DIR/fields_NNN.vtu`` (the displacement, and the
contact pressure, of every step). :func:`export_result_dir` turns such a folder into a
scene (the contact pressure and ``result.json``'s contact area become its
``tissue:contactPressure`` primvar and ``tissue:probe:contactArea``); :func:`export_study`
writes a study's specimen and material without results. ``warptissue simulate --usd`` and
``warptissue fit ... --usd`` call :func:`export_result_dir`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.fit.trainer import TrainerCalibration, calibrate_trainer_material, trainer_mesh
from warptissue.indenter import Indenter
from warptissue.mesh import NODE_SET_PREFIX, TET_REGION_KEY, TetMesh
from warptissue.simulate import build_mesh
from warptissue.study import load_study
from warptissue.usd.over import write_results_over_asset
from warptissue.usd.writer import UsdScenePaths, write_simulation_usd

__all__ = ["export_result_dir", "export_study", "export_trainer", "read_fields_vtu"]

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
    printed = io.StringIO()
    try:
        # meshio prints its complaints and exits (SystemExit) on a file it cannot parse.
        with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(printed):
            data = meshio.read(path, file_format="vtu")
    except (Exception, SystemExit) as exc:
        detail = " ".join(printed.getvalue().split()) or str(exc)
        raise InputError(f"cannot read VTU: {detail}", path=path) from None
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
        summary = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise InputError("result.json is not UTF-8 text", path=path) from None
    except json.JSONDecodeError as exc:
        raise InputError(
            f"result.json is not valid JSON: {exc.msg}", path=path, line=exc.lineno
        ) from None
    if not isinstance(summary, Mapping):
        raise InputError("result.json must hold a JSON object", path=path)
    for key in ("study", "force_curve"):
        if not isinstance(summary.get(key, {}), Mapping):
            raise InputError(f"result.json's {key!r} must be a JSON object", path=path)
    return summary


def _curve(summary: Mapping[str, Any], key: str, path: Path) -> np.ndarray:
    """One column of ``result.json``'s force curve as float64, shape (S,)."""
    values = (summary.get("force_curve") or {}).get(key, [])
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"force_curve.{key} must be a list of numbers", path=path) from None
    if array.ndim != 1 or not np.all(np.isfinite(array)):
        raise InputError(f"force_curve.{key} must be a list of finite numbers", path=path)
    return array


def _step_fields(step_files: list[Path], node_count: int) -> tuple[np.ndarray, np.ndarray | None]:
    """The ``displacement_m`` of each ``fields_NNN.vtu``, shape (S, N, 3), and their
    ``contact_pressure_Pa``, (S, N) (None where a file has none: no rigid contact)."""
    steps, pressures = [], []
    for step_file in step_files:
        point_data = read_fields_vtu(step_file)[1]
        displacement = point_data.get("displacement_m")
        if displacement is None or np.shape(displacement) != (node_count, 3):
            raise InputError(
                f"no displacement_m of shape ({node_count}, 3) as in fields.vtu: "
                "is it from another run?",
                path=step_file,
            )
        steps.append(displacement)
        pressures.append(point_data.get("contact_pressure_Pa"))
    if any(p is None or np.shape(p) != (node_count,) for p in pressures):
        return np.stack(steps), None
    return np.stack(steps), np.stack(pressures)


def _read_indenter(spec: Any, path: Path) -> Indenter | None:
    """The indenter ``result.json`` echoes in ``study.indenter`` (None where it has none)."""
    if not spec:
        return None
    if not isinstance(spec, Mapping):
        raise InputError("study.indenter must be a table", path=path, value=spec)
    spec = dict(spec)
    site = spec.pop("site_m", None)
    spec.pop("direction", None)  # the frame is result.json's "probe" (export_result_dir)
    spec.pop("edge", None)
    if site is not None:
        spec.update(x_m=site[0], y_m=site[1], z_m=site[2])
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
    density_kg_per_m3: float | None = None,
    over: str | Path | None = None,
) -> UsdScenePaths:
    """Write a ``warptissue simulate`` output folder as a layered USD scene.

    Args:
        result_dir: The folder with ``result.json`` and ``fields.vtu``.
        usd_path: The root layer to write, ``NAME.usda``.
        material: The material to record; None takes ``result.json``'s ``study.material``
            (a fit passes its fitted material here).
        provenance: Extra provenance (data file, fit quality, ...) for ``/World``'s customData.
        density_kg_per_m3: Mass density for ``physics:density``; None: 1000, or layered
            over an asset the asset's.
        over: An organ's USD asset that the run's mesh was read from: the result is layered
            over it (:func:`warptissue.usd.over.write_results_over_asset`) instead of
            written with its own asset layer.

    Returns:
        The paths written. Every step's deformed shape is written when ``fields_NNN.vtu``
        exist for all steps; otherwise only the last step's (time samples at 0 and S).
    """
    result_dir = Path(result_dir)
    summary = _read_summary(result_dir)
    summary_path = result_dir / "result.json"
    mesh, point_data, cell_data = read_fields_vtu(result_dir / "fields.vtu")
    depths = _curve(summary, "depth_m", summary_path)
    forces = _curve(summary, "reaction_force_N", summary_path)
    study = summary.get("study") or {}
    if material is None:
        material = study.get("material")
        if material is None:
            raise InputError("result.json has no study.material to write", path=summary_path)
    result = None
    if depths.size:
        step_files = [result_dir / f"fields_{k:03d}.vtu" for k in range(1, depths.size + 1)]
        pressure = point_data.get("contact_pressure_Pa")  # the last step's, or None
        if all(p.is_file() for p in step_files):
            displacement, step_pressure = _step_fields(step_files, mesh.node_count)
            pressure = step_pressure if step_pressure is not None else pressure
        else:
            displacement = point_data.get("displacement_m")
        contact = {}
        if pressure is not None:
            contact["contact_pressure_Pa"] = pressure
            if (summary.get("force_curve") or {}).get("contact_area_m2") is not None:
                contact["contact_area_m2"] = _curve(summary, "contact_area_m2", summary_path)
        result = {
            **contact,
            "depths_m": depths,
            "reaction_force_N": forces,
            "displacement_m": displacement,
            "cauchy_stress_Pa": cell_data.get("cauchy_stress_Pa"),
            "von_mises_Pa": cell_data.get("von_mises_Pa"),
            "completed": summary.get("completed"),
            "message": summary.get("message"),
        }
    indenter = _read_indenter(study.get("indenter"), summary_path)
    axes = None
    probe = summary.get("probe")
    if indenter is not None and isinstance(probe, Mapping):  # a probe at a site: its frame
        site = np.asarray(probe.get("site_m"), dtype=np.float64)
        axes = np.asarray(probe.get("axes"), dtype=np.float64)
        if site.shape != (3,) or axes.shape != (3, 3):
            raise InputError(
                "result.json's probe has no site_m (3,) and axes (3, 3)", path=summary_path
            )
        indenter = dataclasses.replace(indenter, x_m=site[0], y_m=site[1], z_m=site[2])
    info: dict[str, Any] = {
        "result_dir": str(result_dir.resolve()),
        "study_file": str(study.get("path", "")),
        "study_name": str(study.get("name", "")),
        "simulation_software": summary.get("software", {}),
    }
    if provenance:
        info.update(provenance)
    if over is not None:
        if result is None:
            raise InputError("the run has no converged step to layer", path=summary_path)
        return write_results_over_asset(
            usd_path,
            over,
            mesh,
            result=result,
            material=material,
            provenance=info,
            density_kg_per_m3=density_kg_per_m3,
            indenter=indenter,
            indenter_axes=axes,
        )
    return write_simulation_usd(
        usd_path,
        mesh,
        material=material,
        result=result,
        provenance=info,
        density_kg_per_m3=1000.0 if density_kg_per_m3 is None else density_kg_per_m3,
        indenter=indenter,
        indenter_axes=axes,
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

    study = load_study(study_path)
    return write_simulation_usd(
        usd_path,
        build_mesh(study),
        material=study.material,
        provenance={"study_file": str(Path(study_path).resolve()), "study_name": study.name},
        density_kg_per_m3=density_kg_per_m3,
        indenter=study.indenter,
    )


def export_trainer(
    source: str | Path,
    usd_path: str | Path,
    *,
    max_tets: int | None = None,
    density_kg_per_m3: float = 1000.0,
    device: str = "cpu",
) -> tuple[UsdScenePaths, TrainerCalibration]:
    """Write a study's specimen as a trainer's asset: the whole body on linear tets, its
    physics material calibrated for them (:func:`warptissue.fit.trainer.
    calibrate_trainer_material`), the fitted model kept in ``tissue:*``, particle sizes for
    contact (:mod:`warptissue.usd.trainer`).

    Args:
        source: A study TOML, or a ``warptissue fit indentation`` output folder (its
            ``fitted_study.toml``).
        usd_path: The root layer to write, ``NAME.usda``.
        max_tets: The most tets of the trainer's mesh (None: the study's sizes).
        density_kg_per_m3: Mass density for ``physics:density``.
        device: Warp device of the calibration's FE runs.

    Returns:
        The paths written and the calibration.
    """
    source = Path(source)
    study_path = source / "fitted_study.toml" if source.is_dir() else source
    if not study_path.is_file() or study_path.suffix != ".toml":
        raise InputError(
            "--trainer takes a study .toml or a fit output folder with fitted_study.toml",
            path=source,
        )
    study = load_study(study_path)
    mesh = trainer_mesh(study, max_tets=max_tets)
    calibration = calibrate_trainer_material(study, mesh=mesh, device=device)
    paths = write_simulation_usd(
        usd_path,
        mesh,
        material=study.material,
        provenance={
            "study_file": str(study_path.resolve()),
            "study_name": study.name,
            "physics_material": "trainer",
        },
        density_kg_per_m3=density_kg_per_m3,
        indenter=study.indenter,
        trainer=calibration.to_dict(),
    )
    return paths, calibration
