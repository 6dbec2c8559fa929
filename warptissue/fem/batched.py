"""Many independent load paths solved together: one assembly, one factorization and one line
search evaluation per Newton iteration for all of them.

K problems packed into one mesh (:func:`warptissue.fem.packing.pack_meshes`) share an
:class:`warptissue.fem.Assembler` whose tangent is block diagonal. Each Newton iteration
assembles all problems still iterating in one launch and factorizes their tangent once
(cuDSS or PARDISO see one matrix with K independent blocks); everything else is per problem:
its own load increment, convergence test, line search step, cutbacks and result. A problem
that has converged, or failed, is masked out (its rows become identity rows with a zero
right-hand side) and waits without work for the others' iterations.

:func:`simulate_indentation_batch` runs K flat-punch indentations this way and returns one
:class:`warptissue.fem.IndentationResult` per problem, equal to
:func:`warptissue.fem.simulate_indentation`'s to the Newton tolerance.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import warp as wp
import warp.sparse as wps

from warptissue.errors import InputError
from warptissue.fem.assembly import Assembler
from warptissue.fem.indentation import (
    IndentationProblem,
    IndentationResult,
    _indentation_result,
)
from warptissue.fem.packing import PackedMeshes, pack_meshes
from warptissue.fem.sensitivity import check_sensitivity_names
from warptissue.fem.solvers import (
    DirichletConditions,
    LinearSolver,
    NewtonOptions,
    QuasistaticResult,
    _checked_options,
)
from warptissue.materials import Viscoelastic

__all__ = ["batch_assembler", "simulate_indentation_batch", "solve_quasistatic_batch"]

LINE_SEARCH_EVALUATIONS = 10
"""Residual assemblies of one batched line search (as the single-problem line search)."""
FIRST_STEP_HALVINGS = 8
"""Halvings of the first iteration's free step while a problem's element inverts."""


@dataclass
class _Increment:
    """Outcome of one batched load increment, per problem (K,)."""

    displacement: Any
    converged: np.ndarray
    iterations: np.ndarray
    reactions: np.ndarray
    reasons: list[str] = field(default_factory=list)


class _Segments:
    """Sums over each problem's nodes of the union, in the Newton loop's array library.

    Each problem's nodes are one contiguous range of the union (``node_offsets``). A sum
    gathers every problem's range into one row of a (K, longest range) array, zero-padded,
    and reduces the rows: one gather and one row reduction for all problems and arrays.
    (A weighted ``bincount`` over the node-to-problem map, the first version, adds every
    node into K bins with atomics; on an H100 that took 64 % of a 16-problem run.)
    """

    def __init__(self, arrays: Any, node_offsets: np.ndarray) -> None:
        self.arrays = arrays
        offsets = np.asarray(node_offsets, dtype=np.int64)
        self.count = offsets.size - 1
        sizes = np.diff(offsets)
        node_count = int(offsets[-1])
        rows = np.full((self.count, int(sizes.max())), node_count, dtype=np.int64)
        for k in range(self.count):
            rows[k, : sizes[k]] = np.arange(offsets[k], offsets[k + 1])
        self._rows = arrays.xp.asarray(rows)
        self._node_problem = arrays.xp.asarray(np.repeat(np.arange(self.count), sizes))

    def sums(self, *rowwise: Any) -> list[np.ndarray]:
        """Per-problem sums of nodal arrays of shape (N,) or (N, 3), read in one copy."""
        xp = self.arrays.xp
        columns = [values.sum(axis=1) if values.ndim == 2 else values for values in rowwise]
        padded = xp.zeros((len(columns), columns[0].shape[0] + 1))
        padded[:, :-1] = xp.stack(columns)
        host = self.arrays.host(padded[:, self._rows].sum(axis=2))
        return [host[i] for i in range(len(rowwise))]

    def per_node(self, values: np.ndarray) -> Any:
        """A per-problem array (K,) spread to the nodes, as an (N, 1) array of the library."""
        xp = self.arrays.xp
        return xp.asarray(values, dtype=xp.float64)[self._node_problem][:, None]


def _batched_line_search(
    assembler: Assembler,
    segments: _Segments,
    u: Any,
    direction: Any,
    free: Any,
    searching: np.ndarray,
    energies: np.ndarray,
    slopes: np.ndarray,
    residual_norms: np.ndarray,
    *,
    curvature: float = 0.5,
) -> tuple[np.ndarray, np.ndarray]:
    """The line search of the single-problem Newton loop, one per problem, evaluated together.

    Each evaluation assembles every problem's trial (those that have accepted a step keep
    it); per problem, the full step is taken on an energy (Armijo) or free-residual
    decrease with the directional derivative at most ``curvature`` of its start, else a
    safeguarded secant search on that derivative brackets the energy minimum, as in
    :func:`warptissue.fem.solvers._line_search`.

    Returns:
        (step lengths (K,), 0 where none was found; whether a step was found (K,)).
    """
    count = segments.count
    low, g_low = np.zeros(count), slopes.copy()
    high, g_high = np.full(count, math.inf), np.full(count, math.nan)
    alpha = np.ones(count)
    accepted = np.where(searching, math.nan, 0.0)
    best, best_energy = np.full(count, math.nan), np.full(count, math.inf)
    for _ in range(LINE_SEARCH_EVALUATIONS):
        pending = searching & np.isnan(accepted)
        if not pending.any():
            break
        trial_alpha = np.where(pending, alpha, np.nan_to_num(accepted))
        trial = u + segments.per_node(trial_alpha) * direction
        check = assembler.assemble(trial, with_tangent=False)
        energy, min_jacobian = check.problem_energies_J, check.problem_min_jacobians
        free_residual = segments.arrays.view(check.residual) * free
        g, squared = segments.sums(free_residual * direction, free_residual * free_residual)
        ok = (min_jacobian > 0.0) & np.isfinite(energy)
        decrease = ok & (
            (energy <= energies + 1e-4 * alpha * slopes) | (np.sqrt(squared) < residual_norms)
        )
        good = decrease & ((np.abs(g) <= curvature * np.abs(slopes)) | ((g < 0.0) & (alpha >= 1.0)))
        accept = pending & good
        accepted[accept] = alpha[accept]
        better = pending & ~good & decrease & (energy < best_energy)
        best[better], best_energy[better] = alpha[better], energy[better]
        lower = pending & ~good & decrease & (g < 0.0)
        upper = pending & ~good & ok & ~lower
        inverted = pending & ~ok
        low[lower], g_low[lower] = alpha[lower], g[lower]
        high[upper], g_high[upper] = alpha[upper], g[upper]
        high[inverted], g_high[inverted] = alpha[inverted], math.nan
        move = pending & ~good
        halve = move & (slopes >= 0.0)
        width = high - low
        with np.errstate(invalid="ignore", divide="ignore"):
            secant = low - g_low * width / (g_high - g_low)
            secant = np.minimum(np.maximum(secant, low + 0.1 * width), high - 0.1 * width)
        use_secant = move & ~halve & np.isfinite(g_high) & (g_high > g_low)
        bisect = move & ~halve & ~use_secant
        alpha = np.where(halve, 0.5 * alpha, alpha)
        alpha = np.where(use_secant, secant, alpha)
        alpha = np.where(bisect, low + 0.5 * width, alpha)
    missing = searching & np.isnan(accepted)
    take_best = missing & np.isfinite(best)
    accepted[take_best] = best[take_best]
    found = searching & np.isfinite(accepted)
    return np.nan_to_num(accepted), found


def _batched_increment(
    assembler: Assembler,
    solver: LinearSolver,
    segments: _Segments,
    u_start: Any,
    prescribed_increment: Any,
    free: Any,
    constrained: Any,
    active: np.ndarray,
    weights: Any,
    *,
    tolerance: float,
    force_floors: np.ndarray,
    max_iterations: int,
) -> _Increment:
    """Newton iterations for one load increment of every active problem at once.

    Problems converge, or fail, one by one: from then on their dofs are treated as
    prescribed with a zero increment, so their state stays as it was.
    """
    arrays = segments.arrays
    xp = arrays.xp
    count = segments.count
    fixed = 1.0 - free
    iterating = active.copy()
    converged = np.zeros(count, dtype=bool)
    iterations = np.zeros(count, dtype=np.int64)
    reactions = np.zeros(count)
    reasons = [""] * count
    u = u_start.copy()
    increment_wp = arrays.warp(prescribed_increment)
    k_times_increment = wp.zeros_like(increment_wp)
    assembly = assembler.assemble(u)
    residual = arrays.view(assembly.residual)
    for iteration in range(1, max_iterations + 1):
        first = iteration == 1
        on = segments.per_node(iterating.astype(np.float64))
        frozen = xp.ascontiguousarray(xp.maximum(constrained, 1.0 - on))  # kept alive
        if first:
            wps.bsr_mv(assembly.matrix, increment_wp, k_times_increment, alpha=1.0, beta=0.0)
            rhs = (-(residual + arrays.view(k_times_increment)) * free + prescribed_increment) * on
        else:
            rhs = -residual * free * on
        assembler.eliminate(arrays.warp(frozen))
        du, _ = solver.solve(assembly.matrix, rhs)
        iterations[iterating] += 1
        (du_squared,) = segments.sums(du * du * on)
        broken = iterating & ~np.isfinite(du_squared)
        for k in np.flatnonzero(broken):
            reasons[k] = "the linear solve gave non-finite values"
        iterating &= ~broken
        on = segments.per_node(iterating.astype(np.float64))
        direction = xp.nan_to_num(du) * free * on
        if first:
            start = u + prescribed_increment * on
            alpha = np.where(iterating, 1.0, 0.0)
            found = np.zeros(count, dtype=bool)
            for _ in range(FIRST_STEP_HALVINGS):
                trial = start + segments.per_node(alpha) * direction
                check = assembler.assemble(trial, with_tangent=False)
                ok = (check.problem_min_jacobians > 0.0) & np.isfinite(check.problem_energies_J)
                found |= iterating & ok
                retry = iterating & ~found
                if not retry.any():
                    break
                alpha[retry] *= 0.5
            alpha = np.where(found, alpha, 0.0)
            u = start + segments.per_node(alpha) * direction
            reason = "an element inverted (J <= 0)"
        else:
            free_residual = residual * free
            slopes, squared = segments.sums(
                free_residual * direction, free_residual * free_residual
            )
            alpha, found = _batched_line_search(
                assembler,
                segments,
                u,
                direction,
                free,
                iterating,
                assembly.problem_energies_J,
                slopes,
                np.sqrt(squared),
            )
            u = u + segments.per_node(alpha) * direction
            reason = "the line search found no decrease"
        for k in np.flatnonzero(iterating & ~found):
            reasons[k] = reason
        iterating &= found
        assembly = assembler.assemble(u)
        residual = arrays.view(assembly.residual)
        step = segments.per_node(alpha) * direction
        moved = u - u_start
        free_squared, reaction_squared, reaction, step_squared, moved_squared = segments.sums(
            residual * free * residual,
            residual * fixed * residual,
            weights * residual,
            step * step,
            moved * moved,
        )
        free_norms = np.sqrt(free_squared)
        reaction_norms = np.sqrt(reaction_squared)
        limits = np.maximum(tolerance * reaction_norms, force_floors)
        # A correction at roundoff relative to the increment: the residual sits at its
        # roundoff floor (as in the single-problem loop).
        at_roundoff = (np.sqrt(step_squared) <= 1e-10 * np.sqrt(moved_squared)) & (
            free_norms <= 1e-6 * reaction_norms
        )
        done = iterating & ((free_norms <= limits) | at_roundoff)
        converged |= done
        reactions[done] = reaction[done]
        for k in np.flatnonzero(done):
            reasons[k] = "converged"
        broken = iterating & ~done & ~np.isfinite(free_norms)
        for k in np.flatnonzero(broken):
            reasons[k] = "the residual became non-finite"
        iterating &= ~done & ~broken
        if not iterating.any():
            break
    for k in np.flatnonzero(iterating):
        reasons[k] = f"no convergence in {max_iterations} iterations"
    keep = segments.per_node(converged.astype(np.float64))
    displacement = keep * u + (1.0 - keep) * u_start
    return _Increment(displacement, converged, iterations, reactions, reasons)


def _batched_sensitivities(
    assembler: Assembler,
    solver: LinearSolver,
    segments: _Segments,
    u: Any,
    names: Sequence[str],
    free: Any,
    constrained: Any,
    weights: Any,
    reached: np.ndarray,
) -> np.ndarray:
    """``dF_k / d theta_k`` of the problems ``reached`` (K,) at their converged states in
    ``u``, for every name: ``(K, len(names))`` (rows of the others are zero).

    As :class:`warptissue.fem.ForceSensitivity` with ``factorization="refactorize"``: the
    tangent at the converged state is factorized once (the other problems' rows made
    identity rows), ``K du = -dR/dtheta`` is solved per name, and
    ``dF/dtheta = w . (dR/dtheta + K du)`` summed per problem. The tangent is block
    diagonal, so the problems do not see each other.
    """
    arrays = segments.arrays
    xp = arrays.xp
    matrix = assembler.assemble(u).matrix
    full_values = wp.clone(matrix.values)
    derivatives = [arrays.asarray(assembler.parameter_residual(u, name)) for name in names]
    on = segments.per_node(reached.astype(np.float64))
    frozen = xp.ascontiguousarray(xp.maximum(constrained, 1.0 - on))  # kept alive
    assembler.eliminate(arrays.warp(frozen))
    steps = []
    for i, derivative in enumerate(derivatives):
        rhs = -derivative * free * on
        du, _ = solver.solve(matrix, rhs) if i == 0 else solver.solve_factorized(matrix, rhs)
        steps.append(xp.ascontiguousarray(du * free * on))
    # K du on the prescribed rows needs the tangent before elimination.
    matrix.values.assign(full_values)
    product = wp.zeros(assembler.node_count, dtype=wp.vec3d, device=assembler.device)
    out = np.zeros((segments.count, len(names)))
    for i, (derivative, du) in enumerate(zip(derivatives, steps, strict=True)):
        wps.bsr_mv(matrix, arrays.warp(du), product, alpha=1.0, beta=0.0)
        (sums,) = segments.sums(weights * (derivative + arrays.view(product)) * on)
        out[:, i] = sums
    return out


@dataclass
class _Path:
    """One problem's place on its load path, and what it has converged so far."""

    loads: np.ndarray
    load: float = 0.0
    index: int = 0
    fraction: float = 0.0
    step_fraction: float = 1.0
    halvings: int = 0
    cutbacks: int = 0
    step_iterations: int = 0
    finished: bool = False
    completed: bool = True
    message: str = ""
    reached: list[float] = field(default_factory=list)
    states: list[np.ndarray] = field(default_factory=list)
    reactions: list[float] = field(default_factory=list)
    iterations: list[int] = field(default_factory=list)
    history: list[dict] = field(default_factory=list)
    sensitivities: list[np.ndarray] = field(default_factory=list)

    def next_load(self) -> tuple[float, float]:
        """(the load the next increment goes to, its fraction of the current step)."""
        fraction = self.fraction + self.step_fraction
        if fraction >= 1.0 - 1e-12:
            fraction = 1.0
        start = self.loads[self.index - 1] if self.index else 0.0
        target = self.loads[self.index]
        load = target if fraction == 1.0 else start + fraction * (target - start)
        return float(load), fraction


def solve_quasistatic_batch(
    assembler: Assembler,
    packed: PackedMeshes,
    conditions: Sequence[DirichletConditions],
    loads: Sequence[np.ndarray],
    *,
    reaction_weights: Sequence[np.ndarray],
    options: NewtonOptions | None = None,
    load_name: str = "load",
    sensitivities: Sequence[str] = (),
) -> list[QuasistaticResult]:
    """Follow K displacement-controlled load paths together, one per packed problem.

    Each problem has its own prescribed dofs, loads and reaction weights, in its own node
    numbering; each Newton iteration assembles and factorizes all problems still iterating
    at once. Per problem as in :func:`warptissue.fem.solve_quasistatic`: the linearized
    predictor, the line search, the convergence test
    ``|f_int free| <= options.tolerance * |f_int prescribed|`` (or a roundoff floor), and
    cutbacks (a failed increment is halved, up to ``options.max_cutbacks`` times per
    requested load, and the path stops there keeping what converged). The nonlinear
    elimination, damping and factorization reuse of the single-problem loop are not used:
    they change the path to the solution, not the converged state.

    Args:
        assembler: An assembler of ``packed.mesh`` with one material per problem
            (``element_problem=packed.element_problem``).
        packed: The packed meshes.
        conditions: Each problem's prescribed dofs, (K,).
        loads: Each problem's load factors, (K,) arrays of shape (S_k,).
        reaction_weights: Each problem's weights (N_k, 3) of the internal forces summed into
            its ``reaction``.
        options: The Newton settings (tolerance, iterations, cutbacks, linear solver).
        load_name: What the load is called in messages (e.g. ``"depth (m)"``).
        sensitivities: Material parameters to differentiate each reaction by, exactly, at
            each requested load (each problem by its own parameters of these names; see
            :mod:`warptissue.fem.sensitivity`): one factorization of the converged tangents
            of the problems that reached a requested load in the same increment, and one
            solve per name, for all of them.

    Returns:
        One :class:`warptissue.fem.QuasistaticResult` per problem.

    Raises:
        InputError: Lists of another length than K, or an assembler of another mesh.
    """
    options = _checked_options(options)
    count = packed.problem_count
    names = check_sensitivity_names(sensitivities)
    for k, material in enumerate(assembler.materials):
        for name in names:
            if material.device_params_derivative(name)[1] >= 0:
                raise InputError(
                    f"problem {k}: a batch differentiates by moduli, not by Ogden exponents",
                    key="sensitivities",
                    value=name,
                )
    for name, values in (
        ("conditions", conditions),
        ("loads", loads),
        ("reaction_weights", reaction_weights),
    ):
        if len(values) != count:
            raise InputError(f"one entry per packed problem ({count})", key=name, value=len(values))
    _check_assembler(assembler, packed)
    n = packed.mesh.node_count
    offsets = packed.node_offsets
    paths = []
    for k, values in enumerate(loads):
        path_loads = np.atleast_1d(np.asarray(values, dtype=np.float64))
        if path_loads.ndim != 1 or path_loads.size == 0 or not np.all(np.isfinite(path_loads)):
            raise InputError(f"problem {k}: loads must be a finite 1-D sequence", key="loads")
        paths.append(_Path(loads=path_loads))
    constrained = np.zeros((n, 3))
    weights = np.zeros((n, 3))
    for k, (condition, weight) in enumerate(zip(conditions, reaction_weights, strict=True)):
        constrained[packed.nodes(k)] = condition.mask(int(offsets[k + 1] - offsets[k]))
        weights[packed.nodes(k)] = np.asarray(weight, dtype=np.float64)
    free = 1.0 - constrained
    solver = LinearSolver(method=options.linear_solver, device=assembler.device)
    arrays = solver.arrays
    floors = np.empty(count)
    volumes = np.bincount(packed.element_problem, weights=assembler.tet_volumes, minlength=count)
    for k, material in enumerate(assembler.materials):
        floors[k] = 1e-13 * material.initial_shear_modulus_Pa * volumes[k] ** (2.0 / 3.0)
    with arrays.context():
        segments = _Segments(arrays, offsets)
        u = arrays.asarray(np.zeros((n, 3)))
        free_x, weights_x = arrays.asarray(free), arrays.asarray(weights)
        constrained_x = arrays.asarray(constrained)
        while not all(path.finished for path in paths):
            active = np.array([not path.finished for path in paths])
            increment = np.zeros((n, 3))
            targets = {}
            for k in np.flatnonzero(active):
                path = paths[k]
                load, fraction = path.next_load()
                size = int(offsets[k + 1] - offsets[k])
                increment[packed.nodes(k)] = conditions[k].values(load, size) - conditions[
                    k
                ].values(path.load, size)
                targets[k] = (load, fraction)
            step = _batched_increment(
                assembler,
                solver,
                segments,
                u,
                arrays.asarray(increment),
                free_x,
                constrained_x,
                active,
                weights_x,
                tolerance=options.tolerance,
                force_floors=floors,
                max_iterations=options.max_newton_iterations,
            )
            u = step.displacement
            host = None
            reached = (
                active
                & step.converged
                & np.array([targets[k][1] == 1.0 if k in targets else False for k in range(count)])
            )
            if names and reached.any():
                derivatives_now = _batched_sensitivities(
                    assembler, solver, segments, u, names, free_x, constrained_x, weights_x, reached
                )
            for k in np.flatnonzero(active):
                path = paths[k]
                load, fraction = targets[k]
                path.step_iterations += int(step.iterations[k])
                path.history.append(
                    {
                        "load": load,
                        "converged": bool(step.converged[k]),
                        "iterations": int(step.iterations[k]),
                        "local_iterations": 0,
                        "reason": step.reasons[k],
                    }
                )
                if step.converged[k]:
                    path.load, path.fraction = load, fraction
                    if fraction < 1.0:
                        path.step_fraction = min(2.0 * path.step_fraction, 1.0 - fraction)
                        continue
                    if host is None:
                        host = arrays.host(u)
                    path.reached.append(float(path.loads[path.index]))
                    path.states.append(host[packed.nodes(k)].copy())
                    path.reactions.append(float(step.reactions[k]))
                    if names:
                        path.sensitivities.append(derivatives_now[k])
                    path.iterations.append(path.step_iterations)
                    path.index += 1
                    path.fraction, path.step_fraction = 0.0, 1.0
                    path.halvings, path.step_iterations = 0, 0
                    if path.index == len(path.loads):
                        path.finished = True
                        path.message = (
                            f"converged at all {len(path.loads)} requested values of {load_name}"
                        )
                    continue
                path.halvings += 1
                path.cutbacks += 1
                if path.halvings > options.max_cutbacks:
                    path.finished, path.completed = True, False
                    path.message = (
                        f"stopped at {load_name} {path.load:.6g} on the way to "
                        f"{path.loads[path.index]:.6g}: Newton failed ({step.reasons[k]}) after "
                        f"{options.max_cutbacks} cutbacks; the {len(path.reached)} converged "
                        "steps are kept"
                    )
                    continue
                path.step_fraction *= 0.5
    results = []
    for k, path in enumerate(paths):
        steps = len(path.reached)
        nodes = int(offsets[k + 1] - offsets[k])
        results.append(
            QuasistaticResult(
                loads=np.array(path.reached),
                displacement_m=np.array(path.states).reshape(steps, nodes, 3),
                reaction=np.array(path.reactions),
                newton_iterations=np.array(path.iterations, dtype=np.int64),
                linear_iterations=np.array(path.iterations, dtype=np.int64),
                local_iterations=np.zeros(steps, dtype=np.int64),
                completed=path.completed,
                message=path.message,
                cutbacks=path.cutbacks,
                linear_solver=solver.method,
                history=path.history,
                reaction_sensitivity=np.array(path.sensitivities).reshape(steps, len(names)),
                times_s=np.arange(1.0, steps + 1.0),
                linear_solver_statistics=solver.statistics(),
            )
        )
    return results


def simulate_indentation_batch(
    problems: Sequence[IndentationProblem],
    depths_m: Sequence[np.ndarray],
    *,
    device: str | None = None,
    options: NewtonOptions | None = None,
    sensitivities: Sequence[str] = (),
    assembler: Assembler | None = None,
) -> list[IndentationResult]:
    """K flat-punch indentations solved together on one device.

    Args:
        problems: Bonded or frictionless flat-punch problems with elastic materials, all of
            one element type and formulation (meshes and materials may differ).
        depths_m: Each problem's depths, positive and strictly increasing, m.
        device: Warp device; None for Warp's default.
        options: The Newton settings (:func:`solve_quasistatic_batch` says which apply).
        sensitivities: Material parameters (``C10_Pa``, ``bulk_modulus_Pa``, ...; moduli,
            not Ogden exponents) to differentiate each problem's force by, exactly, at each
            depth: ``result.force_sensitivity_N_per_unit``.
        assembler: An assembler of these problems' meshes, in this order, from
            :func:`batch_assembler`, to reuse across calls that change only the materials
            (a batched fit's trial points); it takes the problems' materials, and the run
            uses its device. None builds one on ``device``.

    Returns:
        One :class:`warptissue.fem.IndentationResult` per problem, as
        :func:`warptissue.fem.simulate_indentation` gives it (equal forces to the Newton
        tolerance).

    Raises:
        InputError: No problem, a problem this batch cannot take (rigid contact, a
            viscoelastic material, another element type or formulation), bad depths, or an
            assembler of other meshes or another formulation.
    """
    problems = list(problems)
    if not problems:
        raise InputError("at least one problem is needed", key="problems", value=0)
    if len(depths_m) != len(problems):
        raise InputError(
            f"one depth sequence per problem ({len(problems)})", key="depths_m", value=len(depths_m)
        )
    formulation = problems[0].formulation
    for k, problem in enumerate(problems):
        if problem.is_contact:
            raise InputError(
                f"problem {k}: a batch takes flat punches (rigid contact runs one problem per "
                "assembler)",
                key="indenter",
                value=problem.indenter.kind,
            )
        if isinstance(problem.material, Viscoelastic):
            raise InputError(
                f"problem {k}: a batch takes elastic materials",
                key="material",
                value=type(problem.material).__name__,
            )
        if problem.formulation != formulation:
            raise InputError(
                f"problem {k}: every problem of a batch has one formulation ({formulation!r})",
                key="formulation",
                value=problem.formulation,
            )
    depths = []
    for k, values in enumerate(depths_m):
        path = np.atleast_1d(np.asarray(values, dtype=np.float64))
        if path.ndim != 1 or path.size == 0 or np.any(path <= 0) or np.any(np.diff(path) <= 0):
            raise InputError(
                f"problem {k}: depths_m must be positive and strictly increasing",
                key="depths_m",
                value=path.tolist(),
            )
        depths.append(path)
    packed = pack_meshes([problem.mesh for problem in problems])
    if assembler is None:
        assembler = _packed_assembler(problems, packed, device)
    else:
        _check_assembler(assembler, packed, formulation)
        assembler.set_material([problem.material for problem in problems])
    paths = solve_quasistatic_batch(
        assembler,
        packed,
        [problem.dirichlet_conditions() for problem in problems],
        depths,
        reaction_weights=[problem.reaction_weights() for problem in problems],
        options=options,
        load_name="depth (m)",
        sensitivities=sensitivities,
    )
    # Every problem's stress at its last converged state, in one launch over the union.
    last = np.zeros((packed.mesh.node_count, 3))
    for k, path in enumerate(paths):
        if len(path.loads):
            last[packed.nodes(k)] = path.displacement_m[-1]
    stress = assembler.cauchy_stress(last)
    results = []
    for k, (problem, path) in enumerate(zip(problems, paths, strict=True)):
        tets = slice(int(packed.tet_offsets[k]), int(packed.tet_offsets[k + 1]))
        results.append(
            _indentation_result(problem, None, path, tuple(sensitivities), stress_Pa=stress[tets])
        )
    return results


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


def _check_assembler(
    assembler: Assembler, packed: PackedMeshes, formulation: str | None = None
) -> None:
    """Refuse an assembler of other packed meshes (or of another ``formulation``)."""
    expected = formulation if formulation is not None else assembler.formulation
    if (
        assembler.problem_count != packed.problem_count
        or assembler.node_count != packed.mesh.node_count
        or assembler.tet_count != packed.mesh.tet_count
        or assembler.formulation != expected
    ):
        raise InputError(
            f"the assembler was built for other meshes or another formulation "
            f"({packed.problem_count} problems, {packed.mesh.node_count} nodes, "
            f"{packed.mesh.tet_count} tets, {expected!r} expected)",
            key="assembler",
            value=(
                assembler.problem_count,
                assembler.node_count,
                assembler.tet_count,
                assembler.formulation,
            ),
        )


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
