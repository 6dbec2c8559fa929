"""Solving indentation problems: the load path, the reaction force and the contact outputs.

The problem, its boundary conditions and its reaction weights are
:class:`warptissue.fem.indentation_problem.IndentationProblem`'s; the result is an
:class:`warptissue.fem.indentation_result.IndentationResult` (both still import from here).

The reaction force of a flat punch is the sum of the z-components of the internal force over
the punch nodes, times the symmetry factor (2 per symmetry plane), positive when the punch
pushes in. Under a sphere or a plate it is the base's: the sum of the z internal forces of the
"bottom" nodes times the symmetry factor, which equals the contact force at equilibrium (the
result reports both); as it is a reaction of prescribed dofs, the exact sensitivities
(:mod:`warptissue.fem.newton.sensitivity`) hold unchanged: the penalty's tangent enters through
``K``, and its one dependence on the material (``k`` follows ``mu0``) through ``dR/dtheta``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from warptissue.errors import ConvergenceError, InputError
from warptissue.fem.assembly import Assembler, von_mises
from warptissue.fem.contact import ContactState, ContactSurface
from warptissue.fem.indentation_problem import BASES, IndentationProblem, plane_axis
from warptissue.fem.indentation_result import IndentationResult
from warptissue.fem.newton import (
    ForceSensitivity,
    NewtonOptions,
    QuasistaticResult,
    SolveInterrupted,
    solve_quasistatic,
    solve_quasistatic_batch,
)
from warptissue.fem.newton.path import check_packed_assembler
from warptissue.fem.newton.sensitivity import check_sensitivity_names
from warptissue.fem.packing import PackedMeshes, pack_meshes
from warptissue.materials import Viscoelastic

__all__ = [
    "BASES",
    "IndentationProblem",
    "IndentationResult",
    "batch_assembler",
    "plane_axis",
    "simulate_indentation",
    "simulate_indentation_batch",
]


def simulate_indentation(
    problem: IndentationProblem,
    depths_m: np.ndarray,
    *,
    device: str | None = None,
    progress: bool = True,
    options: NewtonOptions | None = None,
    strict: bool = False,
    assembler: Assembler | None = None,
    sensitivities: Sequence[str] = (),
    sensitivity_factorization: str = "reuse",
    times_s: np.ndarray | None = None,
    profile: bool = False,
    warm_states_m: np.ndarray | None = None,
) -> IndentationResult:
    """Push the punch to each depth in turn and record the reaction force.

    Args:
        problem: The :class:`IndentationProblem`.
        depths_m: Depths, shape (S,), m: increasing and positive for a quasi-static run; with
            ``times_s``, any depths >= 0 (a loading history may hold and unload).
        device: Warp device (``"cpu"``, ``"cuda:0"``); None for Warp's default.
        progress: Show a tqdm progress bar over the depths.
        options: The Newton solver's settings (linear solver, tolerance, iterations,
            cutbacks, predictor, nonlinear elimination, damping), a
            :class:`warptissue.fem.NewtonOptions`; None: the defaults. See
            :func:`warptissue.fem.solve_quasistatic`.
        strict: Raise :class:`ConvergenceError` (carrying the partial result) instead of
            returning an incomplete one.
        assembler: Reuse an :class:`Assembler` built for this mesh, material and formulation
            (for repeated solves in a fit); built when None.
        sensitivities: Material parameters (keys of ``problem.material.to_dict()``:
            ``C10_Pa``, ``mu1_Pa``, ``alpha1``, ``bulk_modulus_Pa``, ...) to differentiate the
            force by, exactly, at each depth: ``result.force_sensitivity_N_per_unit``.
        sensitivity_factorization: ``"reuse"`` (Newton's last factors with iterative
            refinement; no new factorization) or ``"refactorize"`` (one factorization of the
            converged tangent per depth); see :mod:`warptissue.fem.newton.sensitivity`.
        times_s: The time of each depth, shape (S,), s, strictly increasing; the probe
            starts at depth 0 at t = 0 and its depth is linear in time between steps. Needed
            by a :class:`warptissue.materials.Viscoelastic` material (its history is carried
            forward in time, :mod:`warptissue.fem.viscous`; so are the sensitivities, Prony
            parameters included); an elastic material gives the same forces as without.
        profile: Time each phase of the Newton iterations into ``result.timings`` (see
            :func:`warptissue.fem.solve_quasistatic` and :mod:`warptissue.fem.timing`).
        warm_states_m: A warm start, (S', N, 3), m: the ``displacement_m`` of an earlier
            run of this mesh and indenter at the first S' of these depths (and times), for a
            nearby material (a fit's previous evaluation). Each depth is first tried from
            its state (:func:`warptissue.fem.solve_quasistatic`); the forces are those of a
            run without it, to the Newton tolerance.

    Returns:
        An :class:`IndentationResult` (``completed=False`` with a message when the cutbacks ran
        out; the curve up to there is kept).

    Raises:
        SolveInterrupted: Ctrl-C; its ``partial_result`` is the :class:`IndentationResult` of
            the depths that converged before it.
    """
    depths = _checked_depths(problem, depths_m, times_s)
    assembler = _problem_assembler(problem, assembler, device)
    weights = problem.reaction_weights()
    conditions = problem.dirichlet_conditions()
    names = check_sensitivity_names(sensitivities)
    sensitivity = None
    if names:
        sensitivity = ForceSensitivity(
            assembler, conditions, names, weights, factorization=sensitivity_factorization
        )
    try:
        path = solve_quasistatic(
            assembler,
            conditions,
            depths,
            reaction_weights=weights,
            options=options,
            progress=progress,
            progress_label="indentation depths",
            load_name="depth (m)",
            sensitivity=sensitivity,
            times_s=times_s,
            profile=profile,
            warm_states_m=warm_states_m,
        )
    except SolveInterrupted as interrupted:
        partial = _finished(problem, assembler, interrupted.partial_result, names)
        raise SolveInterrupted(interrupted.message, partial_result=partial) from interrupted
    result = _finished(problem, assembler, path, names)
    if strict and not result.completed:
        raise ConvergenceError(result.message, partial_result=result)
    return result


def _checked_depths(
    problem: IndentationProblem, depths_m: np.ndarray, times_s: np.ndarray | None
) -> np.ndarray:
    """The depths (S,) float64, checked as :func:`simulate_indentation` documents them."""
    depths = np.atleast_1d(np.asarray(depths_m, dtype=np.float64))
    if depths.ndim != 1 or depths.size == 0 or not np.all(np.isfinite(depths)):
        raise InputError("depths_m must be a non-empty 1-D sequence of numbers", value=depths_m)
    if times_s is None:
        if np.any(depths <= 0) or np.any(np.diff(depths) <= 0):
            raise InputError(
                "depths_m must be positive and strictly increasing (give times_s for a "
                "loading history that holds or unloads)",
                value=depths.tolist(),
            )
        if isinstance(problem.material, Viscoelastic):
            raise InputError(
                "a viscoelastic material needs the time of each depth (times_s)",
                key="times_s",
            )
    elif np.any(depths < 0):
        raise InputError(
            "depths_m must be >= 0 (the probe stays in contact)", value=depths.tolist()
        )
    return depths


def _problem_assembler(
    problem: IndentationProblem, assembler: Assembler | None, device: str | None
) -> Assembler:
    """An assembler of ``problem`` with its material, contact and springs: ``assembler``
    (checked to be of this mesh and formulation) or a new one on ``device``."""
    mesh = problem.mesh
    if assembler is None:
        assembler = Assembler(
            mesh, problem.material, formulation=problem.formulation, device=device
        )
    elif assembler.node_count != mesh.node_count or assembler.formulation != problem.formulation:
        raise InputError("the assembler was built for another mesh or formulation")
    else:
        assembler.set_material(problem.material)  # also resets a viscous history
    assembler.set_contact(problem.rigid_contact())
    assembler.set_springs(problem.support_springs())
    return assembler


def _last_stress(assembler: Assembler, path: QuasistaticResult) -> np.ndarray:
    """The Cauchy stress (M, 6) at a single run's last converged state ((0, 6) without one)."""
    if not len(path.loads):
        return np.zeros((0, 6))
    return assembler.cauchy_stress(path.displacement_m[-1])


def _contact_states(assembler: Assembler, path: QuasistaticResult) -> list[ContactState] | None:
    """A single run's rigid contact at each converged depth (None without a contact).

    Leaves the contact at the last depth of ``path``.
    """
    if assembler.contact is None:
        return None
    states = []
    for depth, u in zip(path.loads, path.displacement_m, strict=True):
        assembler.set_load(depth)
        states.append(assembler.contact_state(u))
    return states


def _finished(
    problem: IndentationProblem,
    assembler: Assembler,
    path: QuasistaticResult,
    sensitivity_names: tuple[str, ...],
) -> IndentationResult:
    """The indentation result of a single run's load path (complete or interrupted), with
    the stress and contact states of its last state read from ``assembler``."""
    return _indentation_result(
        problem,
        path,
        sensitivity_names,
        stress_Pa=_last_stress(assembler, path),
        contact_states=_contact_states(assembler, path),
    )


def _indentation_result(
    problem: IndentationProblem,
    path: QuasistaticResult,
    sensitivity_names: tuple[str, ...] = (),
    *,
    stress_Pa: np.ndarray,
    contact_states: Sequence[ContactState] | None = None,
) -> IndentationResult:
    """The indentation result of a load path: the curve, the fields at its last state.

    Args:
        problem: The problem solved.
        path: Its load path, in the problem's own node numbering.
        sensitivity_names: The parameters of ``path.reaction_sensitivity``'s columns.
        stress_Pa: The Cauchy stress (M, 6) at the last converged state ((0, 6) without one).
        contact_states: Under a rigid indenter, the contact at each converged depth, in the
            problem's own node numbering (:meth:`warptissue.fem.Assembler.contact_state`);
            None for a sharp flat punch.
    """
    stress = stress_Pa
    contact_force, penetration, area = np.zeros(0), np.zeros(0), np.zeros(0)
    tangential = np.zeros(0)
    along = problem.probe_direction
    pressure = np.zeros((0, problem.mesh.node_count))
    if contact_states is not None:
        steps = len(path.loads)
        surface = ContactSurface.for_mesh(problem.mesh, surface=problem.surface)
        contact_force, penetration, area = np.empty(steps), np.empty(steps), np.empty(steps)
        tangential = np.zeros(steps)
        pressure = np.empty((steps, problem.mesh.node_count))
        for i, (state, u) in enumerate(zip(contact_states, path.displacement_m, strict=True)):
            total = state.total_force_N
            if problem.frame is None:
                contact_force[i] = -problem.symmetry_factor * total[2]
            else:
                contact_force[i] = problem.symmetry_factor * float(np.dot(total, along))
            if not problem.symmetry_planes:
                tangential[i] = np.linalg.norm(total - np.dot(total, along) * along)
            penetration[i] = state.max_penetration_m
            current = problem.mesh.points + u
            area[i] = problem.symmetry_factor * surface.contact_area_m2(state, current)
            pressure[i] = surface.pressure_Pa(state, current)
    return IndentationResult(
        depths_m=path.loads,
        reaction_force_N=path.reaction,
        newton_iterations=path.newton_iterations,
        linear_iterations=path.linear_iterations,
        local_iterations=path.local_iterations,
        displacement_m=path.displacement_m,
        cauchy_stress_Pa=stress,
        von_mises_Pa=von_mises(stress) if len(stress) else np.zeros(0),
        completed=path.completed,
        message=path.message,
        cutbacks=path.cutbacks,
        formulation=problem.formulation,
        element_type=problem.mesh.element_type,
        symmetry_factor=problem.symmetry_factor,
        linear_solver=path.linear_solver,
        sensitivity_names=sensitivity_names,
        force_sensitivity_N_per_unit=path.reaction_sensitivity,
        times_s=path.times_s,
        contact_force_N=contact_force,
        max_penetration_m=penetration,
        contact_area_m2=area,
        contact_pressure_Pa=pressure,
        tangential_force_N=tangential,
        mean_contact_pressure_Pa=np.divide(
            contact_force, area, out=np.zeros_like(area), where=area > 0.0
        ),
        increments=list(path.history),
        timings=path.timings,
        linear_solver_statistics=path.linear_solver_statistics,
    )


def simulate_indentation_batch(
    problems: Sequence[IndentationProblem],
    depths_m: Sequence[np.ndarray],
    *,
    device: str | None = None,
    options: NewtonOptions | None = None,
    sensitivities: Sequence[str] = (),
    assembler: Assembler | None = None,
    times_s: Sequence[np.ndarray | None] | None = None,
    warm_states_m: Sequence[np.ndarray | None] | None = None,
) -> list[IndentationResult]:
    """K indentations solved together on one device, in one Newton loop.

    Args:
        problems: Problems all of one element type and formulation (meshes, materials,
            viscoelastic histories, indenters and their contact conditions may differ:
            bonded or frictionless flat punches, and rigid indenters in contact, each with
            its own penalty stiffness; :mod:`warptissue.fem.contact`).
        depths_m: Each problem's depths, m: positive and strictly increasing, or with its
            times any depths >= 0 (as :func:`simulate_indentation`).
        device: Warp device; None for Warp's default.
        options: The Newton settings (every one applies per problem,
            :func:`warptissue.fem.solve_quasistatic_batch`).
        sensitivities: Material parameters (``C10_Pa``, ``bulk_modulus_Pa``, ...; moduli,
            not Ogden exponents) to differentiate each problem's force by, exactly, at each
            depth: ``result.force_sensitivity_N_per_unit``.
        assembler: An assembler of these problems' meshes, in this order, from
            :func:`batch_assembler`, to reuse across calls that change only the materials
            (a batched fit's trial points); it takes the problems' materials, and the run
            uses its device. None builds one on ``device``.
        times_s: Each problem's times, s (None entries, or None: quasi-static paths); a
            viscoelastic material needs them.
        warm_states_m: Each problem's warm start (None entries, or None: none), as
            :func:`simulate_indentation`'s.

    Returns:
        One :class:`warptissue.fem.IndentationResult` per problem, as
        :func:`warptissue.fem.simulate_indentation` gives it (equal forces to the Newton
        tolerance), with the contact outputs (contact force, penetration, area, pressure)
        of a rigid indenter. Where any problem has a rigid indenter other than a plate,
        every problem's increments take the penalty ramp
        (:func:`warptissue.fem.newton.increment.penalty_ramped_increment`): the path to the
        solution changes, not the converged state.

    Raises:
        InputError: No problem, a problem this batch cannot take (another element type or
            formulation), bad depths or times, or an assembler of other meshes or another
            formulation.
    """
    problems = list(problems)
    depths, times_list = _batch_paths(problems, depths_m, times_s)
    formulation = problems[0].formulation
    packed = pack_meshes([problem.mesh for problem in problems])
    if assembler is None:
        assembler = _packed_assembler(problems, packed, device)
    else:
        check_packed_assembler(assembler, packed, formulation)
        assembler.set_material([problem.material for problem in problems])
    # Each contact's stiffness follows its problem's material: set on every call.
    assembler.set_contact([problem.rigid_contact() for problem in problems])
    assembler.set_springs([problem.support_springs() for problem in problems])
    paths = solve_quasistatic_batch(
        assembler,
        packed,
        [problem.dirichlet_conditions() for problem in problems],
        depths,
        reaction_weights=[problem.reaction_weights() for problem in problems],
        options=options,
        load_name="depth (m)",
        sensitivities=sensitivities,
        times_s=times_list,
        warm_states_m=warm_states_m,
    )
    return _batch_results(problems, assembler, packed, paths, tuple(sensitivities))


def _batch_paths(
    problems: list[IndentationProblem],
    depths_m: Sequence[np.ndarray],
    times_s: Sequence[np.ndarray | None] | None,
) -> tuple[list[np.ndarray], list[np.ndarray | None]]:
    """Each problem's depths (float64) and times (None entries for a quasi-static path),
    checked as :func:`simulate_indentation_batch` documents them."""
    if not problems:
        raise InputError("at least one problem is needed", key="problems", value=0)
    if len(depths_m) != len(problems):
        raise InputError(
            f"one depth sequence per problem ({len(problems)})", key="depths_m", value=len(depths_m)
        )
    formulation = problems[0].formulation
    for k, problem in enumerate(problems):
        if problem.formulation != formulation:
            raise InputError(
                f"problem {k}: every problem of a batch has one formulation ({formulation!r})",
                key="formulation",
                value=problem.formulation,
            )
    times_list = [None] * len(problems) if times_s is None else list(times_s)
    if len(times_list) != len(problems):
        raise InputError(
            f"one time sequence per problem ({len(problems)})", key="times_s", value=len(times_list)
        )
    depths = []
    for k, values in enumerate(depths_m):
        path = np.atleast_1d(np.asarray(values, dtype=np.float64))
        timed = times_list[k] is not None
        if (
            path.ndim != 1
            or path.size == 0
            or not np.all(np.isfinite(path))
            or (not timed and (np.any(path <= 0) or np.any(np.diff(path) <= 0)))
            or (timed and np.any(path < 0))
        ):
            raise InputError(
                f"problem {k}: depths_m must be positive and strictly increasing (or >= 0 "
                "with times_s)",
                key="depths_m",
                value=path.tolist(),
            )
        depths.append(path)
    return depths, times_list


def _batch_results(
    problems: list[IndentationProblem],
    assembler: Assembler,
    packed: PackedMeshes,
    paths: Sequence[QuasistaticResult],
    sensitivity_names: tuple[str, ...],
) -> list[IndentationResult]:
    """Each packed problem's result, with every problem's stress at its last converged state
    and its contact states read from ``assembler`` in launches over the union."""
    last = np.zeros((packed.mesh.node_count, 3))
    for k, path in enumerate(paths):
        if len(path.loads):
            last[packed.nodes(k)] = path.displacement_m[-1]
    stress = assembler.cauchy_stress(last)
    states = _packed_contact_states(assembler, packed, paths)
    results = []
    for k, (problem, path) in enumerate(zip(problems, paths, strict=True)):
        tets = slice(int(packed.tet_offsets[k]), int(packed.tet_offsets[k + 1]))
        results.append(
            _indentation_result(
                problem,
                path,
                sensitivity_names,
                stress_Pa=stress[tets] if len(path.loads) else np.zeros((0, 6)),
                contact_states=states[k],
            )
        )
    return results


def _packed_contact_states(
    assembler: Assembler, packed: PackedMeshes, paths: Sequence[QuasistaticResult]
) -> list[list[ContactState] | None]:
    """Each packed problem's rigid contact at each of its converged depths (None for a
    problem without one), in its own node numbering: step i of every problem that reached
    it in one launch (:meth:`warptissue.fem.Assembler.contact_states`)."""
    states: list[list[ContactState] | None] = [
        None if contact is None else [] for contact in assembler.contacts
    ]
    if not assembler.has_contact:
        return states
    for i in range(max(len(path.loads) for path in paths)):
        u = np.zeros((packed.mesh.node_count, 3))
        depths = np.zeros(len(paths))
        for k, path in enumerate(paths):
            if i < len(path.loads):
                u[packed.nodes(k)] = path.displacement_m[i]
                depths[k] = path.loads[i]
        assembler.set_load(depths)
        for k, state in enumerate(assembler.contact_states(u)):
            if state is not None and i < len(paths[k].loads):
                states[k].append(state)
    return states


def batch_assembler(
    problems: Sequence[IndentationProblem], *, device: str | None = None
) -> Assembler:
    """The assembler of K problems' packed meshes, for :func:`simulate_indentation_batch`.

    Building it (element geometry and the sparsity pattern of the union) costs about as much
    as a few Newton iterations; a caller that solves the same meshes with other materials
    (the trial points of batched fits) builds it once and passes it to every call.

    Args:
        problems: The problems, in the order of the calls that will use it.
        device: Warp device; None for Warp's default.

    Returns:
        An :class:`warptissue.fem.Assembler` of the packed meshes, one material per problem.
    """
    problems = list(problems)
    if not problems:
        raise InputError("at least one problem is needed", key="problems", value=0)
    return _packed_assembler(problems, pack_meshes([p.mesh for p in problems]), device)


def _packed_assembler(
    problems: list[IndentationProblem], packed: PackedMeshes, device: str | None
) -> Assembler:
    return Assembler(
        packed.mesh,
        [problem.material for problem in problems],
        formulation=problems[0].formulation,
        device=device,
        element_problem=packed.element_problem,
    )
