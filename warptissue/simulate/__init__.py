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

The package holds one job a module: :mod:`warptissue.simulate.build` (the mesh and the problem
from a study), :mod:`warptissue.simulate.outputs` (the files of a solved study),
:mod:`warptissue.simulate.together` (several studies in one batched run) and this module
(running a study). Every name above is importable from ``warptissue.simulate``.
"""

from __future__ import annotations

import os
import re
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

import warptissue.kernels.assembly
import warptissue.kernels.sparse
from warptissue.acquisition import ForceCurveTissue
from warptissue.device import resolve_device
from warptissue.errors import InputError
from warptissue.fem import (
    SolveInterrupted,
    simulate_indentation,
)
from warptissue.materials import prony_term
from warptissue.mesh import (
    check_mesh,
)
from warptissue.simulate.build import (  # noqa: F401
    StudySetup,
    build_mesh,
    build_problem,
    check_linear_solver,
    estimate_mesh,
    record_problems,
    size_near_reason,
)
from warptissue.simulate.outputs import (  # noqa: F401
    CONTACT_CURVE_COLUMNS,
    FORCE_CURVE_COLUMNS,
    PENETRATION_WARNING_SHARE,
    SimulationOutputs,
    force_curve_warnings,
    penetration_warnings,
    write_study_outputs,
)
from warptissue.simulate.together import (  # noqa: F401
    run_studies_together,
    together_settings,
)
from warptissue.study import (
    Study,
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

COMPILE_NOTICE = "compiling Warp kernels (first run only, about a minute)..."
"""Said once on standard error before a run whose kernels are not in Warp's cache."""
_STEP_FIELDS = re.compile(r"^fields_\d{3,}\.vtu$")


def _mesh_statistics(mesh: Any) -> dict[str, Any]:
    """Size and shape quality of the mesh (raises MeshError on an inverted or flat tet)."""

    quality = check_mesh(mesh)
    return {**asdict(quality), "displacement_dof_count": 3 * mesh.node_count}


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


def _is_viscoelastic(material: Any) -> bool:
    """True for a material with a Prony series (its parameters hold ``g1``, ``tau1_s``...)."""
    return any(prony_term(name) is not None for name in material.parameter_names)


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
