"""A solved study's files: ``force_curve.csv``, ``fields.vtu`` (and per step) and ``result.json``.

:func:`write_study_outputs` writes them atomically (their layout: :mod:`warptissue.simulate`);
:func:`force_curve_warnings` and :func:`penetration_warnings` are the warnings
``result.json`` carries.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import INTERRUPTED_EXIT_CODE, ConvergenceError
from warptissue.io import INDENTATION_COLUMNS, software_versions, write_csv, write_json
from warptissue.mesh import (
    write_mesh,
)
from warptissue.simulate.build import StudySetup
from warptissue.study import Study

FORCE_CURVE_COLUMNS: tuple[str, ...] = (*INDENTATION_COLUMNS, "step", "newton_iterations")
"""Columns of ``force_curve.csv``: an indentation record's
(:data:`warptissue.io.INDENTATION_COLUMNS`), then the solver's."""


CONTACT_CURVE_COLUMNS: tuple[str, ...] = ("contact_area_m2",)
"""Columns ``force_curve.csv`` adds after :data:`FORCE_CURVE_COLUMNS` under a rigid
indenter in contact."""


PENETRATION_WARNING_SHARE = 0.01
"""A penetration of the indenter into the specimen beyond this share of the depth is said
in ``result.json``'s warnings (the penalty is too soft; docs/fe.md "Contact" measures 1e-4
with the default penalty factor)."""


@dataclass(frozen=True)
class SimulationOutputs:
    """What :func:`run_study` computed and wrote.

    Attributes:
        status: ``"completed"`` (every load step converged), ``"stopped_early"`` (the
            cutbacks ran out) or ``"interrupted"`` (Ctrl-C).
        message: The solver's one-line status message.
        result: The :class:`warptissue.fem.IndentationResult`.
        summary: The content of ``result.json``.
        out_dir: The output folder.
        files: Output kind (``"force_curve"``, ``"result"``, ``"fields"``, ``"fields_NNN"``)
            to the path written.
    """

    status: str
    message: str
    result: Any
    summary: dict[str, Any]
    out_dir: Path
    files: dict[str, Path] = field(default_factory=dict)

    @property
    def completed(self) -> bool:
        """True when every load step converged."""
        return self.status == "completed"

    @property
    def exit_code(self) -> int:
        """0 when complete, 4 (convergence) when stopped early, 130 when interrupted."""
        return {"completed": 0, "interrupted": INTERRUPTED_EXIT_CODE}.get(
            self.status, ConvergenceError.exit_code
        )


def penetration_warnings(depths_m: np.ndarray, max_penetration_m: np.ndarray) -> list[str]:
    """A penetration of a rigid indenter beyond :data:`PENETRATION_WARNING_SHARE` of the
    depth, said for the first step concerned (empty when none is, or without contact)."""
    depths_m = np.asarray(depths_m, dtype=np.float64)
    penetration = np.asarray(max_penetration_m, dtype=np.float64)
    if penetration.size == 0:
        return []
    deep = np.flatnonzero(penetration > PENETRATION_WARNING_SHARE * np.abs(depths_m))
    if deep.size == 0:
        return []
    step = int(deep[0])
    return [
        f"the indenter penetrates the specimen by {penetration[step]:.3g} m at step "
        f"{step + 1} ({penetration[step] / max(abs(depths_m[step]), 1e-300):.2%} of the depth "
        f"{depths_m[step]:.6g} m): the contact penalty is too soft for this material; "
        "raise solver.penalty_factor"
    ]


def force_curve_warnings(depths_m: np.ndarray, forces_N: np.ndarray) -> list[str]:
    """What is implausible in an indentation force curve (empty when nothing is).

    A probe pushed into a specimen meets a positive reaction force that grows with the depth
    (monotonic loading of a hyperelastic solid); a force that is not positive, or that falls
    while the depth grows, points at a sign, unit or set-up error (or an instability). In a
    timed run the force may fall while the depth holds (relaxation) or goes back, and a
    bonded probe may pull on the way back: only the steps that go deeper are judged, and a
    force that is not positive only where the depth reaches a new deepest point.

    Args:
        depths_m: Depths of the converged steps, shape (S,), m.
        forces_N: Reaction forces there, shape (S,), N, positive pushing in.

    Returns:
        One sentence per finding, naming the first step concerned (a force that is not
        positive hides the falling one).
    """
    warnings: list[str] = []
    depths_m = np.asarray(depths_m, dtype=np.float64)
    forces_N = np.asarray(forces_N, dtype=np.float64)
    deepest = depths_m >= np.maximum.accumulate(depths_m)
    not_positive = np.flatnonzero(~(forces_N > 0.0) & deepest)
    if not_positive.size:
        step = int(not_positive[0])
        warnings.append(
            f"the reaction force is not positive at step {step + 1} "
            f"({forces_N[step]:.6g} N at depth {depths_m[step]:.6g} m): the probe should push"
        )
        return warnings
    falling = np.flatnonzero((np.diff(forces_N) < 0.0) & (np.diff(depths_m) > 0.0))
    if falling.size:
        step = int(falling[0]) + 1
        warnings.append(
            f"the reaction force falls from step {step} to {step + 1} "
            f"({forces_N[step - 1]:.6g} N to {forces_N[step]:.6g} N) while the depth grows"
        )
    return warnings


def _write_fields(
    out_dir: Path, mesh: Any, result: Any, *, every_step: bool, contact: bool = False
) -> dict[str, Path]:
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
    pressure = np.asarray(result.contact_pressure_Pa, dtype=np.float64) if contact else None

    def point_data(step: int | None) -> dict[str, np.ndarray]:
        """The nodal fields of one step (None: the last converged one, or the rest state)."""
        data = {"displacement_m": final if step is None else displacements[step]}
        if pressure is not None:
            if step is None:
                last = pressure[converged - 1] if converged else np.zeros(mesh.node_count)
                data["contact_pressure_Pa"] = last
            else:
                data["contact_pressure_Pa"] = pressure[step]
        return data

    files["fields"] = out_dir / "fields.vtu"
    write_mesh(
        files["fields"],
        mesh,
        point_data=point_data(None),
        cell_data={"cauchy_stress_Pa": stress, "von_mises_Pa": von_mises},
    )
    if every_step:
        for step in range(converged):
            name = f"fields_{step + 1:03d}"
            files[name] = out_dir / f"{name}.vtu"
            write_mesh(files[name], mesh, point_data=point_data(step))
    return files


def write_study_outputs(
    setup: StudySetup,
    result: Any,
    *,
    status: str,
    message: str,
    solve_s: float,
    vtu_every_step: bool = False,
    solved_together: int = 1,
) -> SimulationOutputs:
    """Write a solved study's ``force_curve.csv``, fields and ``result.json`` (atomically).

    Args:
        setup: The study's :class:`StudySetup`.
        result: Its :class:`warptissue.fem.IndentationResult` (the converged steps).
        status: ``"completed"``, ``"stopped_early"`` or ``"interrupted"``.
        message: The solver's one-line status message.
        solve_s: Wall time of the load steps, s (of the whole batched run when the study
            was solved together with others).
        vtu_every_step: Also write ``fields_NNN.vtu`` for every converged step.
        solved_together: How many studies the load steps were solved with, this one
            included (``result.json``'s ``solved_together``; 1 alone).

    Returns:
        The :class:`SimulationOutputs`.
    """
    study, problem, out_path, mesh = setup.study, setup.problem, setup.out_dir, setup.mesh
    times = setup.times_s
    converged = len(result.depths_m)
    steps = np.arange(1, converged + 1, dtype=np.int64)
    newton = np.asarray(result.newton_iterations, dtype=np.int64)
    depths = np.asarray(result.depths_m, dtype=np.float64)
    forces = np.asarray(result.reaction_force_N, dtype=np.float64)
    # Real time for a timed protocol; for a quasi-static one a pseudo-time, the step number.
    step_times = steps.astype(np.float64)
    if times is not None:
        step_times = np.asarray(result.times_s, dtype=np.float64)[:converged]
    is_contact = bool(problem.is_contact)
    curve_columns = {
        "time_s": np.concatenate([[0.0], step_times]),
        "displacement_m": np.concatenate([[0.0], depths]),
        "force_N": np.concatenate([[0.0], forces]),
        "step": np.arange(converged + 1, dtype=np.int64),
        "newton_iterations": np.concatenate([[0], newton]).astype(np.int64),
    }
    contact_curve, contact_summary = (
        _contact_outputs(study, problem, result, converged) if is_contact else ({}, {})
    )
    if is_contact:
        curve_columns["contact_area_m2"] = np.concatenate([[0.0], contact_curve["contact_area_m2"]])
    writing = time.perf_counter()
    files: dict[str, Path] = {
        "result": out_path / "result.json",
        "force_curve": write_csv(out_path / "force_curve.csv", curve_columns),
    }
    files.update(
        _write_fields(out_path, mesh, result, every_step=vtu_every_step, contact=is_contact)
    )
    written = time.perf_counter()
    summary = {
        "study": {"path": study.path, **study.to_dict()},
        "status": status,
        "completed": status == "completed",
        "message": message,
        "device": str(setup.device),
        "linear_solver": str(result.linear_solver),
        "cutbacks": int(result.cutbacks),
        "force_curve": {
            "step": steps,
            "time_s": step_times,
            "depth_m": depths,
            "reaction_force_N": forces,
            "newton_iterations": newton,
            "linear_iterations": np.asarray(result.linear_iterations, dtype=np.int64),
            "local_iterations": np.asarray(result.local_iterations, dtype=np.int64),
            **contact_curve,
        },
        **contact_summary,
        **_probe_summary(problem),
        "steps_requested": study.protocol.step_count,
        "steps_converged": converged,
        "warnings": force_curve_warnings(depths, forces)
        + (penetration_warnings(depths, contact_curve["max_penetration_m"]) if is_contact else []),
        "mesh": setup.mesh_statistics,
        "solved_together": int(solved_together),
        "timings_s": _timings(setup.setup_s, solve_s, written - writing),
        "newton_profile": None if result.timings is None else result.timings.to_dict(),
        "linear_solver_statistics": dict(result.linear_solver_statistics),
        "files": {kind: path.name for kind, path in files.items()},
        "software": software_versions(),
    }
    write_json(files["result"], summary)
    return SimulationOutputs(
        status=status,
        message=message,
        result=result,
        summary=summary,
        out_dir=out_path,
        files=files,
    )


def _contact_outputs(
    study: Study, problem: Any, result: Any, converged: int
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Under a rigid indenter: the per-step contact columns of ``result.json``'s
    ``force_curve`` (contact force, N; area, m^2; largest penetration, m; largest pressure,
    Pa; each shape (converged,)) and its ``contact`` summary."""
    area = np.asarray(result.contact_area_m2, dtype=np.float64)[:converged]
    penetration = np.asarray(result.max_penetration_m, dtype=np.float64)[:converged]
    pressure = np.asarray(result.contact_pressure_Pa, dtype=np.float64)[:converged]
    contact_curve = {
        "contact_force_N": np.asarray(result.contact_force_N, dtype=np.float64)[:converged],
        "contact_area_m2": area,
        "mean_contact_pressure_Pa": np.asarray(result.mean_contact_pressure_Pa, dtype=np.float64)[
            :converged
        ],
        "max_penetration_m": penetration,
        "max_contact_pressure_Pa": (pressure.max(axis=1) if pressure.size else np.zeros(converged)),
    }
    contact_summary = {
        "contact": {
            "indenter": study.indenter.kind,
            "penalty_factor": float(problem.penalty_factor),
            "contact_integration": problem.contact_integration,
            "penalty_stiffness_N_per_m": float(problem.rigid_contact().stiffness_N_per_m),
            "max_penetration_m": float(penetration.max()) if penetration.size else 0.0,
            "max_penetration_step": (int(np.argmax(penetration)) + 1 if penetration.size else None),
            "contact_area_m2": float(area[-1]) if area.size else 0.0,
        }
    }
    return contact_curve, contact_summary


def _probe_summary(problem: Any) -> dict[str, Any]:
    """``result.json``'s ``probe`` (site, direction and axes of a probe placed on a mesh
    specimen), or nothing."""
    if problem.frame is None:
        return {}
    return {
        "probe": {
            "site_m": problem.frame.origin_m.tolist(),
            "direction": problem.frame.direction.tolist(),
            "axes": problem.frame.axes.tolist(),
        }
    }


def _timings(setup_s: float, solve_s: float, write_s: float) -> dict[str, float]:
    """``result.json``'s ``timings_s``: meshing and set-up, load steps, writing the fields
    and their total, s."""
    return {
        "mesh_and_setup": setup_s,
        "solve": solve_s,
        "write_fields": write_s,
        "total": setup_s + solve_s + write_s,
    }
