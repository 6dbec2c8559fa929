"""Run a study: mesh, material, indentation problem, load steps, outputs on disk.

:func:`run_study` is the Python API behind ``warptissue simulate``. It builds the specimen
mesh, the material and the indentation problem from a :class:`~warptissue.study.Study`, runs
the load steps with :func:`warptissue.fem.simulate_indentation`, and writes (atomically)

- ``force_curve.csv``: ``step,depth_m,reaction_force_N,newton_iterations``, one row per
  converged load step;
- ``result.json``: the study echoed back with every default, the force curve, iterations,
  completion status and message, mesh statistics, timings and software versions;
- ``fields.vtu``: the mesh with nodal displacement (point data ``displacement_m``) and per-tet
  Cauchy stress (cell data ``cauchy_stress_Pa``, Voigt order xx, yy, zz, yz, xz, xy) and von
  Mises stress (``von_mises_Pa``) at the last converged load step;
- ``fields_NNN.vtu`` (only when asked): the displacement of every converged load step NNN.

A run that stops early (the load-step cutback is exhausted) still writes all of this for the
steps that converged, and reports ``completed = False`` with the solver's message.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import ConvergenceError
from warptissue.io import software_versions, write_csv, write_json
from warptissue.study import Study

__all__ = ["SimulationOutputs", "build_mesh", "build_problem", "run_study"]

FORCE_CURVE_COLUMNS: tuple[str, ...] = ("step", "depth_m", "reaction_force_N", "newton_iterations")
"""Columns of ``force_curve.csv``."""


@dataclass(frozen=True)
class SimulationOutputs:
    """What :func:`run_study` computed and wrote.

    Attributes:
        completed: True when every load step converged.
        message: The solver's one-line status message.
        result: The :class:`warptissue.fem.IndentationResult`.
        summary: The content of ``result.json``.
        out_dir: The output folder.
        files: Output kind (``"force_curve"``, ``"result"``, ``"fields"``, ``"fields_NNN"``)
            to the path written.
    """

    completed: bool
    message: str
    result: Any
    summary: dict[str, Any]
    out_dir: Path
    files: dict[str, Path] = field(default_factory=dict)

    @property
    def exit_code(self) -> int:
        """0 when complete, else the convergence-error exit status (4)."""
        return 0 if self.completed else ConvergenceError.exit_code


def build_mesh(study: Study) -> Any:
    """Generate the specimen mesh a study describes.

    Args:
        study: The study.

    Returns:
        A :class:`warptissue.mesh.TetMesh` with the standard indentation node sets.
    """
    from warptissue.mesh import indentation_block, indentation_disc

    specimen = study.specimen
    common = {
        "thickness_m": specimen.thickness_m,
        "probe_radius_m": study.indenter.radius_m,
        "quarter": specimen.quarter,
        "element": specimen.element,
        "size_near_m": specimen.size_near_m,
        "size_far_m": specimen.size_far_m,
        "growth": specimen.growth,
        "mesher": specimen.mesher,
    }
    if specimen.shape == "block":
        return indentation_block(width_m=specimen.width_m, **common)
    return indentation_disc(radius_m=specimen.radius_m, **common)


def build_problem(study: Study, mesh: Any) -> Any:
    """Build the indentation problem (mesh, material, punch, boundary conditions).

    Args:
        study: The study.
        mesh: The specimen mesh from :func:`build_mesh`.

    Returns:
        A :class:`warptissue.fem.IndentationProblem`.
    """
    from warptissue.fem import IndentationProblem

    return IndentationProblem(
        mesh,
        study.material,
        study.indenter,
        base=study.boundary.base,
        symmetry_planes=("symmetry_x", "symmetry_y") if study.specimen.quarter else (),
        formulation=study.solver.formulation,
    )


def _mesh_statistics(mesh: Any) -> dict[str, Any]:
    """Size and shape quality of the mesh (raises MeshError on an inverted or flat tet)."""
    from warptissue.mesh import check_mesh

    quality = check_mesh(mesh)
    return {**asdict(quality), "displacement_dof_count": 3 * mesh.node_count}


def _write_fields(out_dir: Path, mesh: Any, result: Any, *, every_step: bool) -> dict[str, Path]:
    from warptissue.mesh import write_mesh

    files: dict[str, Path] = {}
    converged = len(result.depths_m)
    displacements = np.asarray(result.displacement_m, dtype=np.float64)
    if converged:
        final = displacements[-1]
        stress = np.asarray(result.cauchy_stress_Pa, dtype=np.float64)
        von_mises = np.asarray(result.von_mises_Pa, dtype=np.float64)
    else:  # nothing converged: the undeformed, unstressed state
        final = np.zeros_like(mesh.points)
        stress = np.zeros((mesh.tet_count, 6))
        von_mises = np.zeros(mesh.tet_count)
    files["fields"] = out_dir / "fields.vtu"
    write_mesh(
        files["fields"],
        mesh,
        point_data={"displacement_m": final},
        cell_data={"cauchy_stress_Pa": stress, "von_mises_Pa": von_mises},
    )
    if every_step:
        for step in range(converged):
            name = f"fields_{step + 1:03d}"
            files[name] = out_dir / f"{name}.vtu"
            write_mesh(files[name], mesh, point_data={"displacement_m": displacements[step]})
    return files


def run_study(
    study: Study,
    *,
    out_dir: str | Path,
    device: str | None = None,
    progress: bool = True,
    vtu_every_step: bool = False,
) -> SimulationOutputs:
    """Run a study's indentation simulation and write its outputs.

    Args:
        study: A validated study (see :func:`warptissue.study.load_study`).
        out_dir: Output folder, created if needed. Existing output files are replaced.
        device: Warp device (``"cpu"``, ``"cuda"``, ``"cuda:N"``); None uses the study's
            ``solver.device`` (``"auto"``: a GPU where present, else the CPU).
        progress: Show a progress bar over the load steps.
        vtu_every_step: Also write ``fields_NNN.vtu`` with the displacement of every step.

    Returns:
        The outputs. ``completed`` is False when the run stopped early; the files then hold
        the load steps that converged.

    Raises:
        InputError: The study cannot be meshed or set up.
        MeshError: The generated mesh is invalid.
        DeviceError: The device does not exist.
    """
    from warptissue.device import resolve_device
    from warptissue.fem import simulate_indentation

    out_path = Path(out_dir)
    chosen = device if device is not None else study.solver.device
    warp_device = resolve_device(None if chosen == "auto" else chosen)
    started = time.perf_counter()
    mesh = build_mesh(study)
    mesh_statistics = _mesh_statistics(mesh)
    problem = build_problem(study, mesh)
    meshed = time.perf_counter()
    result = simulate_indentation(
        problem,
        np.asarray(study.protocol.depths_m, dtype=np.float64),
        device=warp_device,
        progress=progress,
        options=study.solver.options,
    )
    solved = time.perf_counter()

    converged = len(result.depths_m)
    steps = np.arange(1, converged + 1, dtype=np.int64)
    newton = np.asarray(result.newton_iterations, dtype=np.int64)
    files: dict[str, Path] = {
        "result": out_path / "result.json",
        "force_curve": write_csv(
            out_path / "force_curve.csv",
            {
                "step": steps,
                "depth_m": np.asarray(result.depths_m, dtype=np.float64),
                "reaction_force_N": np.asarray(result.reaction_force_N, dtype=np.float64),
                "newton_iterations": newton,
            },
        ),
    }
    files.update(_write_fields(out_path, mesh, result, every_step=vtu_every_step))
    written = time.perf_counter()
    summary = {
        "study": {"path": study.path, **study.to_dict()},
        "completed": bool(result.completed),
        "message": str(result.message),
        "device": str(warp_device),
        "linear_solver": str(result.linear_solver),
        "cutbacks": int(result.cutbacks),
        "force_curve": {
            "step": steps,
            "depth_m": result.depths_m,
            "reaction_force_N": result.reaction_force_N,
            "newton_iterations": newton,
            "linear_iterations": np.asarray(result.linear_iterations, dtype=np.int64),
            "local_iterations": np.asarray(result.local_iterations, dtype=np.int64),
        },
        "steps_requested": study.protocol.step_count,
        "steps_converged": converged,
        "mesh": mesh_statistics,
        "timings_s": {
            "mesh_and_setup": meshed - started,
            "solve": solved - meshed,
            "write_fields": written - solved,
            "total": written - started,
        },
        "files": {kind: path.name for kind, path in files.items()},
        "software": software_versions(),
    }
    write_json(files["result"], summary)
    return SimulationOutputs(
        completed=bool(result.completed),
        message=str(result.message),
        result=result,
        summary=summary,
        out_dir=out_path,
        files=files,
    )
