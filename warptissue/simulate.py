"""Run a study: mesh, material, indentation problem, load steps, outputs on disk.

:func:`run_study` is the Python API behind ``warptissue simulate``. It builds the specimen
mesh, the material and the indentation problem from a :class:`~warptissue.study.Study`, runs
the load steps with :func:`warptissue.fem.simulate_indentation`, and writes (atomically)

- ``force_curve.csv``: ``time_s,displacement_m,force_N,step,newton_iterations``, a row for the
  undeformed state (step 0) and one per converged load step. ``displacement_m`` is the probe
  depth (positive into the specimen) and ``force_N`` the reaction force (positive pushing
  in), so that the file reads as an indentation record
  (:func:`warptissue.io.read_experiment_csv`: ``warptissue fit punch-modulus``,
  ``warptissue rig-sim --tissue curve --force-curve``). For a timed protocol
  (:attr:`warptissue.study.Protocol.timed`: ramp-and-hold, sine, a record's history)
  ``time_s`` is the time of each step (s), and a viscoelastic material relaxes; for a
  quasi-static one (rate-independent) it is a pseudo-time, the load-step number. Under a
  rigid indenter in contact (sphere, plate, wedge, rounded punch) a last column
  ``contact_area_m2`` holds the contact area of the whole specimen
  (:attr:`warptissue.fem.IndentationResult.contact_area_m2`);
- ``result.json``: the study echoed back with every default, the force curve, iterations,
  ``status`` (``"completed"``, ``"stopped_early"`` or ``"interrupted"``) and message,
  ``warnings`` (an implausible force curve: :func:`force_curve_warnings`; a penetration of
  the indenter beyond :data:`PENETRATION_WARNING_SHARE` of the depth), mesh statistics,
  timings, ``solved_together`` (the number of studies solved in one batched FE run, 1
  alone), ``newton_profile`` (where the solve's time went, per phase of the Newton
  iterations, when run with ``profile=True``; else null: :class:`warptissue.fem.NewtonTimings`)
  and software versions; under a rigid indenter in contact also, per step, the
  contact force, the contact area, the largest penetration and the largest contact
  pressure in ``force_curve``, and the largest penetration of the run in ``contact``;
- ``fields.vtu``: the mesh with nodal displacement (point data ``displacement_m``) and per-tet
  Cauchy stress (cell data ``cauchy_stress_Pa``, Voigt order xx, yy, zz, yz, xz, xy) and von
  Mises stress (``von_mises_Pa``) at the last converged load step; under a rigid indenter
  in contact also the contact pressure (point data ``contact_pressure_Pa``, Pa, zero off the
  contact; :class:`warptissue.fem.contact.ContactSurface`);
- ``fields_NNN.vtu`` (only when asked): the displacement (and under a rigid indenter the
  contact pressure) of every converged load step NNN.
  Those of an earlier run in the same folder are removed first.

A run that stops early (the load-step cutback is exhausted) or is interrupted (Ctrl-C) still
writes all of this for the steps that converged: the first returns ``completed = False``
with the solver's message, the second raises :class:`warptissue.fem.SolveInterrupted`
carrying the :class:`SimulationOutputs`.

:func:`run_studies_together` solves several studies' load steps in one batched FE run
(:func:`warptissue.fem.simulate_indentation_batch`) and writes each study's files as
:func:`run_study` does (``warptissue batch --together``); :func:`prepare_study`,
:func:`solve_study` and :func:`write_study_outputs` are :func:`run_study`'s three parts.

Before meshing, a study whose mesh would not fit in memory is refused with the estimate
(:func:`warptissue.mesh.estimate_indentation_mesh`), and the first run on a machine says
once, on standard error, that Warp is compiling its kernels.
"""

from __future__ import annotations

import os
import re
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

import warptissue.kernels.assembly
import warptissue.kernels.sparse
from warptissue.acquisition import ForceCurveTissue
from warptissue.device import resolve_device
from warptissue.errors import INTERRUPTED_EXIT_CODE, ConvergenceError, InputError
from warptissue.fem import (
    IndentationProblem,
    LinearSolver,
    SolveInterrupted,
    simulate_indentation,
    simulate_indentation_batch,
)
from warptissue.io import INDENTATION_COLUMNS, software_versions, write_csv, write_json
from warptissue.materials import prony_term
from warptissue.mesh import (
    MeshSizeEstimate,
    check_mesh,
    estimate_indentation_mesh,
    indentation_block,
    indentation_disc,
    near_size_choice,
    write_mesh,
)
from warptissue.study import (
    Study,
    organ_mesh,
    probe_placement,
    specimen_mesh,
    support_nodes,
)

__all__ = [
    "CONTACT_CURVE_COLUMNS",
    "FORCE_CURVE_COLUMNS",
    "PENETRATION_WARNING_SHARE",
    "SimulationOutputs",
    "StudySetup",
    "build_mesh",
    "build_problem",
    "check_linear_solver",
    "estimate_mesh",
    "force_curve_warnings",
    "kernels_need_compiling",
    "penetration_warnings",
    "record_problems",
    "prepare_study",
    "run_studies_together",
    "run_study",
    "size_near_reason",
    "solve_study",
    "together_settings",
    "write_study_outputs",
]

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
COMPILE_NOTICE = "compiling Warp kernels (first run only, about a minute)..."
"""Said once on standard error before a run whose kernels are not in Warp's cache."""
_STEP_FIELDS = re.compile(r"^fields_\d{3,}\.vtu$")


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


def build_mesh(study: Study) -> Any:
    """Generate the specimen mesh a study describes.

    Args:
        study: The study.

    Returns:
        A :class:`warptissue.mesh.TetMesh` with the standard indentation node sets.
    """

    specimen = study.specimen
    if specimen.shape == "mesh":
        return _organ_mesh(study)
    common = {
        "thickness_m": specimen.thickness_m,
        "probe_radius_m": study.mesh_probe_radius_m,
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


def size_near_reason(study: Study) -> str | None:
    """Which near size ``specimen.force_accuracy`` chose, and why; None where the study gives
    ``size_near_m`` (or leaves it at its default) instead.

    Args:
        study: The study.

    Returns:
        One sentence (:meth:`warptissue.mesh.NearSizeChoice.reason`), or None.
    """

    specimen = study.specimen
    if specimen.force_accuracy is None:
        return None
    if specimen.shape == "mesh":  # refined around its sites, TetGen's tets: the study's site
        return near_size_choice(
            specimen.force_accuracy,
            probe_radius_m=specimen.refine_zones[0][3],
            mesher="delaunay",
            element=specimen.element,
        ).reason()
    return near_size_choice(
        specimen.force_accuracy,
        probe_radius_m=study.mesh_probe_radius_m,
        mesher=specimen.mesher,
        element=specimen.element,
    ).reason()


def estimate_mesh(study: Study) -> Any:
    """The size of the study's mesh and the memory it takes, before it is generated.

    Args:
        study: The study.

    Returns:
        A :class:`warptissue.mesh.MeshSizeEstimate` (tets, nodes, bytes to generate and to
        solve on the CPU).
    """

    specimen = study.specimen
    if specimen.shape == "mesh":
        mesh = specimen_mesh(
            specimen.mesh_path,
            unit=specimen.unit,
            element=specimen.element,
            zones=specimen.refine_zones,
        )
        return MeshSizeEstimate(  # the mesh is already made: its solve is not counted
            tet_count=mesh.tet_count,
            node_count=mesh.node_count,
            element=specimen.element,
            mesh_bytes=0,
            solve_bytes=0,
        )
    half_size_m = specimen.half_size_m
    return estimate_indentation_mesh(
        shape=specimen.shape,
        half_extent_m=half_size_m,
        thickness_m=specimen.thickness_m,
        probe_radius_m=study.mesh_probe_radius_m,
        quarter=specimen.quarter,
        element=specimen.element,
        size_near_m=specimen.size_near_m,
        size_far_m=specimen.size_far_m,
        growth=specimen.growth,
    )


def build_problem(study: Study, mesh: Any) -> Any:
    """Build the indentation problem (mesh, material, punch, boundary conditions).

    Args:
        study: The study.
        mesh: The specimen mesh from :func:`build_mesh`.

    Returns:
        A :class:`warptissue.fem.IndentationProblem`.
    """

    placement = {}
    if study.site_m is not None:
        placement = {"site_m": study.site_m, "direction": study.direction, "edge": study.edge}
    return IndentationProblem(
        mesh,
        study.material,
        study.indenter,
        base=study.boundary.base,
        foundation=study.boundary.foundation,
        symmetry_planes=("symmetry_x", "symmetry_y") if study.specimen.quarter else (),
        formulation=study.solver.formulation,
        penalty_factor=study.solver.penalty_factor,
        **placement,
    )


def record_problems(study: Study, material: Any = None) -> tuple[list[Any], list[int]]:
    """The indentation problems of a study's ``[[data]]`` records: one per distinct probe
    (indenter, site and direction, :meth:`warptissue.study.Study.probe_of`).

    Args:
        study: A study with records.
        material: The problems' material; None: the study's.

    Returns:
        ``(problems, index)``: the distinct problems, in the order their first record
        comes, and for each record the index of its problem. Problems whose supports hold
        the same nodes share one mesh (and so one assembler).
    """
    material = study.material if material is None else material
    problems: list[Any] = []
    keys: list[tuple] = []
    index: list[int] = []
    for record in study.data:
        key = study.probe_of(record)
        if key not in keys:
            indenter, site_m, direction = key
            placed = replace(
                study, indenter=indenter, site_m=site_m, direction=direction, material=material
            )
            mesh = build_mesh(placed)
            held = mesh.node_sets["bottom"]
            for earlier in problems:  # one organ, one support: the earlier site's mesh
                other = earlier.mesh
                if other.points is mesh.points and np.array_equal(other.node_sets["bottom"], held):
                    mesh = other
                    break
            keys.append(key)
            problems.append(build_problem(placed, mesh))
        index.append(keys.index(key))
    return problems, index


def _organ_mesh(study: Study) -> Any:
    """A mesh specimen's mesh with its support as ``"bottom"`` and the rest of its surface
    as ``"top"`` (:mod:`warptissue.study`'s ``[specimen] mesh``)."""
    specimen = study.specimen
    mesh = specimen_mesh(
        specimen.mesh_path,
        unit=specimen.unit,
        element=specimen.element,
        zones=specimen.refine_zones,
    )
    site, along = probe_placement(
        mesh, study.site_m, study.direction, radius_m=study.indenter.radius_m
    )
    support = support_nodes(mesh, study.boundary.support, site_m=site, direction=along)
    return organ_mesh(mesh, support)


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


def _mesh_statistics(mesh: Any) -> dict[str, Any]:
    """Size and shape quality of the mesh (raises MeshError on an inverted or flat tet)."""

    quality = check_mesh(mesh)
    return {**asdict(quality), "displacement_dof_count": 3 * mesh.node_count}


@dataclass(frozen=True)
class StudySetup:
    """A simulation study made ready to solve (:func:`prepare_study`).

    Attributes:
        study: The study.
        out_dir: Its output folder (created, writable).
        device: The Warp device it runs on.
        mesh: The specimen mesh (:func:`build_mesh`).
        mesh_statistics: ``result.json``'s ``mesh``.
        problem: The :class:`warptissue.fem.IndentationProblem` (:func:`build_problem`).
        depths_m: The protocol's depths, (S,), m.
        times_s: The protocol's times, (S,), s; None for a quasi-static one.
        setup_s: Wall time of meshing and setting up, s.
    """

    study: Study
    out_dir: Path
    device: Any
    mesh: Any
    mesh_statistics: dict[str, Any]
    problem: Any
    depths_m: np.ndarray
    times_s: np.ndarray | None
    setup_s: float


def _prepare_out_dir(out_path: Path) -> None:
    """Create the output folder, or refuse one that is a file or cannot be written, before
    any work; remove the per-step fields of an earlier run (they would mix with this one's)."""
    if out_path.exists() and not out_path.is_dir():
        raise InputError("the output folder is a file", path=out_path)
    try:
        out_path.mkdir(parents=True, exist_ok=True)
        probe = out_path / ".warptissue-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise InputError(
            f"cannot write to the output folder: {exc.strerror}", path=out_path
        ) from None
    for stale in out_path.iterdir():
        if _STEP_FIELDS.match(stale.name) and stale.is_file():
            stale.unlink()


def check_linear_solver(study: Study, device: Any) -> None:
    """Refuse, before any work, a linear solver that does not run on the device.

    Args:
        study: The study (its ``solver.linear_solver``).
        device: The Warp device the study runs on.

    Raises:
        InputError: The linear solver is unknown or does not run on ``device``.
    """

    try:
        LinearSolver(method=study.solver.options.linear_solver, device=device)
    except InputError as exc:
        raise InputError(
            f"solver.{exc.column or 'linear_solver'}: {exc.message}",
            path=study.path,
            value=exc.value,
        ) from None


def _is_viscoelastic(material: Any) -> bool:
    """True for a material with a Prony series (its parameters hold ``g1``, ``tau1_s``...)."""
    return any(prony_term(name) is not None for name in material.parameter_names)


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


def kernels_need_compiling(device: Any) -> bool:
    """Whether the project's Warp kernels are missing from Warp's kernel cache for a device.

    Args:
        device: An initialized Warp device.

    Returns:
        True when a Warp module of :mod:`warptissue.kernels` that a simulation launches (that
        of ``assembly.py``, which holds the kernels of ``viscous.py`` and ``contact.py`` too,
        and ``sparse``) has no compiled binary for ``device`` in
        ``warp.config.kernel_cache_dir`` (so the first launch compiles it, about a minute on
        the CPU).
    """

    for kernels in (warptissue.kernels.assembly, warptissue.kernels.sparse):
        module = wp.get_module(kernels.__name__)
        # Warp launches on the CPU with one thread per block (its kernel cache key).
        block_dim = 1 if device.is_cpu else module.options["block_dim"]
        try:
            binary = os.path.join(
                wp.config.kernel_cache_dir,
                module.get_module_identifier(block_dim),
                module._get_compile_output_name(device, block_dim=block_dim),
            )
        except Exception:  # Warp's cache layout is not public API: where unknown, say nothing
            return False
        if not os.path.exists(binary):
            return True
    return False


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


def run_study(
    study: Study,
    *,
    out_dir: str | Path,
    device: str | None = None,
    progress: bool = True,
    vtu_every_step: bool = False,
    announce: bool = True,
    profile: bool = False,
) -> SimulationOutputs:
    """Run a study's indentation simulation and write its outputs.

    Args:
        study: A validated study (see :func:`warptissue.study.load_study`).
        out_dir: Output folder, created if needed. Existing output files are replaced.
        device: Warp device (``"cpu"``, ``"cuda"``, ``"cuda:N"``); None uses the study's
            ``solver.device`` (``"auto"``: a GPU where present, else the CPU).
        progress: Show a progress bar over the load steps.
        vtu_every_step: Also write ``fields_NNN.vtu`` with the displacement of every step.
        announce: Say on standard error, once, that Warp compiles its kernels where they are
            not in its cache yet (the first run on a machine; about a minute).
        profile: Time each phase of the Newton iterations (assembly, factorization, solve,
            line search, nonlinear elimination, host work) into ``result.timings`` and
            ``result.json``'s ``newton_profile`` (:mod:`warptissue.fem.timing`; on a GPU
            this synchronizes the device at every phase boundary).

    Returns:
        The outputs. ``status`` is ``"stopped_early"`` when the cutbacks ran out; the files
        then hold the load steps that converged.

    Raises:
        InputError: The study cannot be meshed or set up, or the output folder cannot be
            written.
        MeshError: The mesh would not fit in memory (refused before it is made, with the
            estimate), or the generated mesh is invalid.
        DeviceError: The device does not exist.
        SolveInterrupted: Ctrl-C during the load steps, after the outputs of the converged
            steps were written (``status`` ``"interrupted"``); its ``partial_result`` is the
            :class:`SimulationOutputs`.
    """
    setup = prepare_study(study, out_dir=out_dir, device=device, announce=announce)
    return solve_study(setup, progress=progress, vtu_every_step=vtu_every_step, profile=profile)


def solve_study(
    setup: StudySetup,
    *,
    progress: bool = True,
    vtu_every_step: bool = False,
    profile: bool = False,
) -> SimulationOutputs:
    """Run a prepared study's load steps alone and write its outputs.

    The part of :func:`run_study` after :func:`prepare_study`; the arguments and what it
    returns and raises are :func:`run_study`'s.

    Args:
        setup: The study's :class:`StudySetup`.
        progress: Show a progress bar over the load steps.
        vtu_every_step: Also write ``fields_NNN.vtu`` for every converged step.
        profile: Time each phase of the Newton iterations into ``result.json``.

    Returns:
        The :class:`SimulationOutputs`.

    Raises:
        SolveInterrupted: Ctrl-C during the load steps, after the outputs of the converged
            steps were written.
    """

    started = time.perf_counter()
    interrupted = None
    try:
        result = simulate_indentation(
            setup.problem,
            setup.depths_m,
            device=setup.device,
            progress=progress,
            options=setup.study.solver.options,
            times_s=setup.times_s,
            profile=profile,
        )
        status = "completed" if result.completed else "stopped_early"
    except SolveInterrupted as exc:
        interrupted, result, status = exc, exc.partial_result, "interrupted"
    message = interrupted.message if interrupted is not None else str(result.message)
    outputs = write_study_outputs(
        setup,
        result,
        status=status,
        message=message,
        solve_s=time.perf_counter() - started,
        vtu_every_step=vtu_every_step,
    )
    if interrupted is not None:
        raise SolveInterrupted(message, partial_result=outputs) from interrupted
    return outputs


def force_curve_tissue(study: Study, *, device: str | None = None) -> ForceCurveTissue:
    """A simulated rig's specimen whose force is the study's FE force response
    (``warptissue rig-sim --tissue study:FILE``).

    The study's material is elastic, so its FE force depends on the depth only (a
    hyperelastic response is path independent) and the force on any path the rig is
    commanded is that of the FE force-depth curve: the FE runs once on the study's own
    ``[protocol]`` depths (the same mesh, problem and solver as ``warptissue simulate``),
    and the rig interpolates its force linearly in depth (zero at depth 0). Deeper than the
    protocol's deepest step the force stays at the last one: give the study a
    ``[protocol] max_depth_m`` at least as deep as the rig will indent.

    Args:
        study: A study with an elastic material (:func:`warptissue.study.load_study`).
        device: Warp device; None uses the study's ``solver.device``.

    Returns:
        The :class:`~warptissue.acquisition.ForceCurveTissue` of the FE curve.

    Raises:
        InputError: A viscoelastic material (its force depends on the whole path, which the
            rig learns only as it is commanded), or an FE run that did not reach the
            protocol's deepest step (naming the study file).
        MeshError: The mesh would not fit in memory, or the generated mesh is invalid.
        DeviceError: The device does not exist.
    """
    if _is_viscoelastic(study.material):
        raise InputError(
            "a rig-sim study tissue takes an elastic material: a viscoelastic force depends "
            "on the whole depth-time path, which the rig learns only as it is commanded",
            path=study.path,
            key="material",
        )
    chosen = device if device is not None else study.solver.device
    warp_device = resolve_device(None if chosen == "auto" else chosen)
    check_linear_solver(study, warp_device)
    depths_m = np.asarray(study.protocol.depths_m, dtype=np.float64)
    result = simulate_indentation(
        build_problem(study, build_mesh(study)),
        depths_m,
        device=warp_device,
        progress=False,
        options=study.solver.options,
    )
    if not result.completed:
        raise InputError(
            f"the FE stopped before the protocol's deepest step: {result.message}",
            path=study.path,
            key="protocol",
        )
    return ForceCurveTissue(depths_m, np.asarray(result.reaction_force_N, dtype=np.float64))


def prepare_study(
    study: Study, *, out_dir: str | Path, device: str | None = None, announce: bool = True
) -> StudySetup:
    """Check a simulation study, make its output folder, mesh and set up its problem.

    The part of :func:`run_study` before the load steps; :func:`run_studies_together` takes
    several of these.

    Args:
        study: A validated study (see :func:`warptissue.study.load_study`).
        out_dir: Output folder, created if needed (its per-step fields of an earlier run
            are removed).
        device: Warp device; None uses the study's ``solver.device``.
        announce: Say on standard error, once, that Warp compiles its kernels where they are
            not in its cache yet.

    Returns:
        The :class:`StudySetup`.

    Raises:
        InputError: A viscoelastic material under a quasi-static protocol, a linear solver
            that does not run on the device, a study that cannot be meshed, or an output
            folder that cannot be written.
        MeshError: The mesh would not fit in memory, or the generated mesh is invalid.
        DeviceError: The device does not exist.
    """

    times = study.protocol.times_s
    if times is None and _is_viscoelastic(study.material):
        raise InputError(
            "protocol: a viscoelastic [material] (Prony terms) needs a timed protocol "
            "(kind = 'ramp_hold', 'sine' or 'record', or depths_m with times_s): a "
            "quasi-static one has no time to relax in",
            path=study.path,
            value=study.protocol.kind,
        )
    out_path = Path(out_dir)
    _prepare_out_dir(out_path)
    chosen = device if device is not None else study.solver.device
    warp_device = resolve_device(None if chosen == "auto" else chosen)
    check_linear_solver(study, warp_device)
    estimate_mesh(study).require_fits(solve=warp_device.is_cpu, what="study's mesh")
    started = time.perf_counter()
    mesh = build_mesh(study)
    mesh_statistics = _mesh_statistics(mesh)
    mesh_statistics.update(
        size_near_m=study.specimen.size_near_m,
        size_far_m=study.specimen.size_far_m,
        size_near_reason=size_near_reason(study),
    )
    problem = build_problem(study, mesh)
    if announce and kernels_need_compiling(warp_device):
        print(f"warptissue: {COMPILE_NOTICE}", file=sys.stderr, flush=True)
    return StudySetup(
        study=study,
        out_dir=out_path,
        device=warp_device,
        mesh=mesh,
        mesh_statistics=mesh_statistics,
        problem=problem,
        depths_m=np.asarray(study.protocol.depths_m, dtype=np.float64),
        times_s=None if times is None else np.asarray(times, dtype=np.float64),
        setup_s=time.perf_counter() - started,
    )


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
    step_times = (
        np.asarray(result.times_s, dtype=np.float64)[:converged]
        if times is not None
        else steps.astype(np.float64)
    )
    is_contact = bool(problem.is_contact)
    curve_columns = {
        "time_s": np.concatenate([[0.0], step_times]),
        "displacement_m": np.concatenate([[0.0], depths]),
        "force_N": np.concatenate([[0.0], forces]),
        "step": np.arange(converged + 1, dtype=np.int64),
        "newton_iterations": np.concatenate([[0], newton]).astype(np.int64),
    }
    contact_curve: dict[str, Any] = {}
    contact_summary: dict[str, Any] = {}
    if is_contact:
        area = np.asarray(result.contact_area_m2, dtype=np.float64)[:converged]
        penetration = np.asarray(result.max_penetration_m, dtype=np.float64)[:converged]
        pressure = np.asarray(result.contact_pressure_Pa, dtype=np.float64)[:converged]
        curve_columns["contact_area_m2"] = np.concatenate([[0.0], area])
        contact_curve = {
            "contact_force_N": np.asarray(result.contact_force_N, dtype=np.float64)[:converged],
            "contact_area_m2": area,
            "max_penetration_m": penetration,
            "max_contact_pressure_Pa": (
                pressure.max(axis=1) if pressure.size else np.zeros(converged)
            ),
        }
        contact_summary = {
            "contact": {
                "indenter": study.indenter.kind,
                "penalty_factor": float(problem.penalty_factor),
                "penalty_stiffness_N_per_m": float(problem.rigid_contact().stiffness_N_per_m),
                "max_penetration_m": float(penetration.max()) if penetration.size else 0.0,
                "max_penetration_step": (
                    int(np.argmax(penetration)) + 1 if penetration.size else None
                ),
                "contact_area_m2": float(area[-1]) if area.size else 0.0,
            }
        }
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
        **(
            {}
            if problem.frame is None
            else {
                "probe": {
                    "site_m": problem.frame.origin_m.tolist(),
                    "direction": problem.frame.direction.tolist(),
                    "axes": problem.frame.axes.tolist(),
                }
            }
        ),
        "steps_requested": study.protocol.step_count,
        "steps_converged": converged,
        "warnings": force_curve_warnings(depths, forces)
        + (penetration_warnings(depths, contact_curve["max_penetration_m"]) if is_contact else []),
        "mesh": setup.mesh_statistics,
        "solved_together": int(solved_together),
        "timings_s": {
            "mesh_and_setup": setup.setup_s,
            "solve": solve_s,
            "write_fields": written - writing,
            "total": setup.setup_s + solve_s + (written - writing),
        },
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


def together_settings(setup: StudySetup) -> dict[str, Any]:
    """What studies solved together must share (:func:`run_studies_together`).

    Args:
        setup: The study's :class:`StudySetup`.

    Returns:
        ``device`` (its name), ``solver.formulation`` and ``solver`` (the Newton options),
        to compare with ``==``.
    """
    return {
        "device": str(setup.device),
        "solver.formulation": setup.problem.formulation,
        "solver": setup.study.solver.options,
    }


def run_studies_together(setups: Sequence[StudySetup]) -> list[SimulationOutputs]:
    """Solve several simulation studies in the same launches and write each one's outputs.

    The load steps of all the studies run as one batched FE run
    (:func:`warptissue.fem.simulate_indentation_batch`: one assembly launch and one
    factorization of the block-diagonal tangent per Newton iteration, each study with its
    own increments, convergence and cutbacks); then each study's folder gets what
    :func:`run_study` writes, with ``solved_together`` = the number of studies in
    ``result.json``.

    Args:
        setups: The studies, from :func:`prepare_study`: any indenter, elastic or
            viscoelastic, quasi-static or timed protocols, on one device, with one
            formulation and equal ``[solver]`` settings.

    Returns:
        One :class:`SimulationOutputs` per study, in order.

    Raises:
        InputError: No study, or one whose device, formulation or solver settings differ
            from the first study's (quoting both).

    Notes:
        The forces equal those of :func:`run_study` to the Newton tolerance: every study
        runs the one Newton loop with its own decisions; only the shared factorization's
        reuse is decided for all at once, which changes the path to the solution, not the
        converged state (docs/design-notes/batched-fe.md).
    """

    setups = list(setups)
    if not setups:
        raise InputError("at least one study is needed", key="studies", value=0)
    first = setups[0]
    for setup in setups[1:]:
        for (key, mine), theirs in zip(
            together_settings(setup).items(), together_settings(first).values(), strict=True
        ):
            if mine != theirs:
                raise InputError(
                    f"studies solved together need one {key}; {first.study.path} has {theirs!r}",
                    path=setup.study.path,
                    key=key,
                    value=mine,
                )
    started = time.perf_counter()
    results = simulate_indentation_batch(
        [setup.problem for setup in setups],
        [setup.depths_m for setup in setups],
        device=str(first.device),
        options=first.study.solver.options,
        times_s=[setup.times_s for setup in setups],
    )
    solve_s = time.perf_counter() - started
    return [
        write_study_outputs(
            setup,
            result,
            status="completed" if result.completed else "stopped_early",
            message=str(result.message),
            solve_s=solve_s,
            solved_together=len(setups),
        )
        for setup, result in zip(setups, results, strict=True)
    ]
