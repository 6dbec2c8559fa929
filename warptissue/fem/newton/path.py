"""Following load paths: the one Newton loop of the project, over one problem or K at once.

Each requested load is reached from the previous converged one in one increment; when Newton
fails (no convergence, no line-search decrease, or an inverted element) the increment is
halved and retried, up to ``max_cutbacks`` halvings, and grows back after successes. When the
halvings run out the path stops there, keeping what converged. K problems packed into one
mesh follow their own paths in the same launches: each has its own loads (and times), its own
increments, cutbacks and Newton decisions (:mod:`~warptissue.fem.newton.increment`), and
waits frozen for the others where it has finished.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.fem.assembly import Assembler
from warptissue.fem.newton.loop import LoadPath, follow_paths
from warptissue.fem.newton.options import NewtonOptions, checked_options
from warptissue.fem.newton.problems import DirichletConditions
from warptissue.fem.newton.result import (  # noqa: F401
    QuasistaticResult,
    SolveInterrupted,
)
from warptissue.fem.newton.sensitivity import ForceSensitivity
from warptissue.fem.packing import PackedMeshes
from warptissue.materials import Viscoelastic

__all__ = [
    "QuasistaticResult",
    "SolveInterrupted",
    "solve_quasistatic",
    "solve_quasistatic_batch",
]


def _checked_loads(values: Any, times_s: Any, what: str) -> tuple[np.ndarray, np.ndarray | None]:
    """A path's loads, and its times (None: quasi-static), checked."""
    loads = np.atleast_1d(np.asarray(values, dtype=np.float64))
    if loads.ndim != 1 or not np.all(np.isfinite(loads)):
        raise InputError(f"{what}loads must be a finite 1-D sequence", key="loads", value=loads)
    if times_s is None:
        return loads, None
    times = np.atleast_1d(np.asarray(times_s, dtype=np.float64))
    if times.shape != loads.shape or not np.all(np.isfinite(times)):
        raise InputError(
            f"{what}times_s must be finite, one per load ({loads.size})",
            key="times_s",
            value=times.shape,
        )
    steps = np.diff(np.concatenate([[0.0], times]))
    if np.any(steps <= 0.0):
        raise InputError(
            f"{what}times_s must be positive and strictly increasing (the path starts at t = 0)",
            key="times_s",
            value=times[: int(np.argmax(steps <= 0.0)) + 1].tolist()[-2:],
        )
    return loads, times


def _checked_warm(states: Any, loads: np.ndarray, node_count: int, what: str) -> np.ndarray | None:
    """A path's warm start (None: none), checked: float64 states (S', N, 3) for at most its
    S loads, finite."""
    if states is None:
        return None
    warm = np.asarray(states, dtype=np.float64)
    if warm.ndim != 3 or warm.shape[1:] != (node_count, 3) or warm.shape[0] > loads.size:
        raise InputError(
            f"{what}warm_states_m must have shape (S', {node_count}, 3) with S' <= "
            f"{loads.size} (one state per requested load, from the first)",
            key="warm_states_m",
            value=warm.shape,
        )
    if not np.all(np.isfinite(warm)):
        raise InputError(f"{what}warm_states_m must be finite", key="warm_states_m")
    return warm


def _force_floors(assembler: Assembler, problem_of_tet: np.ndarray | None) -> np.ndarray:
    """Each problem's absolute floor of the residual norm: a roundoff-level force for its
    body and material, ``1e-13 mu0 L^2`` with L the cube root of its volume, N."""
    if problem_of_tet is None:
        volumes = np.array([float(np.sum(assembler.tet_volumes))])
    else:
        volumes = np.bincount(
            problem_of_tet, weights=assembler.tet_volumes, minlength=assembler.problem_count
        )
    moduli = np.array([material.initial_shear_modulus_Pa for material in assembler.materials])
    lengths = volumes ** (1.0 / 3.0)
    return 1e-13 * moduli * lengths**2


def solve_quasistatic(
    assembler: Assembler,
    conditions: DirichletConditions,
    loads: np.ndarray,
    *,
    reaction_weights: np.ndarray | None = None,
    options: NewtonOptions | None = None,
    progress: bool = False,
    progress_label: str = "load steps",
    load_name: str = "load",
    initial_displacement_m: np.ndarray | None = None,
    sensitivity: ForceSensitivity | None = None,
    times_s: np.ndarray | None = None,
    profile: bool = False,
    warm_states_m: np.ndarray | None = None,
) -> QuasistaticResult:
    """Follow a displacement-controlled load path with Newton's method.

    Each requested load is reached from the previous converged one in one increment; when
    Newton fails (no convergence, no line-search decrease, or an inverted element) the
    increment is halved and retried, up to ``max_cutbacks`` halvings, and grows back after
    successes. When the halvings run out the path stops there, keeping what converged.

    Args:
        assembler: The discretized body. Its ``set_load(load)`` (where it has one) is called
            before each load increment and cutback with the load the increment goes to: a
            rigid contact's depth follows it (:meth:`warptissue.fem.Assembler.set_load`).
        conditions: Prescribed dofs, ``u = load * values_per_load``.
        loads: Increasing (or any) sequence of load factors, shape (S,).
        reaction_weights: Weights (N, 3) of the internal forces summed into ``reaction``
            (None: zeros).
        options: The Newton solver's settings (:class:`NewtonOptions`; None: the defaults).
            Converged when ``|f_int free| <= options.tolerance * |f_int prescribed|`` (or
            below a roundoff floor ``1e-13 mu0 L^2``). ``options.predictor``:
            ``"linearized"`` starts each increment from the converged state plus the
            tangent's response to the prescribed increment; ``"extrapolated"`` (after the
            first increment) from the free dofs extrapolated linearly in the load from the
            last two converged states, and where that state inverts an element, or Newton
            fails from it, the increment runs again from the linearized predictor before any
            cutback. ``options.nonlinear_elimination`` (``"auto"``: the measured rule of
            :func:`warptissue.fem.newton.options.elimination_pays`) relaxes, after each
            global Newton step,
            the nodes that hold most of the residual with the others fixed
            (:func:`warptissue.fem.newton.elimination.nonlinear_elimination`).
            ``options.damping``: where the line search cuts a Newton step below a quarter of
            its length, the next iterations' tangent is damped (Levenberg-Marquardt,
            :func:`warptissue.fem.newton.steering.next_damping`) until steps are taken whole
            again. These three change the path to the solution, not the convergence test.
        progress: Show a tqdm bar over the requested loads.
        progress_label: The bar's label.
        load_name: What the load is called in messages (e.g. ``"depth (m)"``).
        initial_displacement_m: Start state (N, 3); zero by default (load 0).
        sensitivity: A :class:`warptissue.fem.ForceSensitivity` of this
            assembler and these conditions: its ``at_converged_state`` runs at each converged
            requested load, after Newton (with Newton's linear solver), into
            ``reaction_sensitivity`` (with a viscous history: at every converged substep,
            which advances the history's derivatives).
        times_s: The time of each load, shape (S,), s, strictly increasing from t = 0 (the
            unloaded start): a timed path. Between two requested loads the load is linear in
            time, and cutbacks split both. Needed by a viscoelastic material
            (``assembler.viscous``), whose history is advanced after every converged
            (sub)step (:mod:`warptissue.fem.viscous`); an elastic one ignores time. None: a
            quasi-static path.
        profile: Time each phase of the Newton iterations (assembly, factorization, solve,
            line search, nonlinear elimination, sensitivities, host work) into the result's
            ``timings`` (:mod:`warptissue.fem.timing`). On a CUDA device this synchronizes
            the device at every phase boundary; off, nothing is timed.
        warm_states_m: A warm start: the states (S', N, 3), m, that an earlier run of the
            same body and loads (and times) converged to at the first S' <= S requested
            loads, for a nearby material (a fit's previous evaluation). An increment that
            reaches one of these loads starts from its state (with the prescribed dofs of
            the load) instead of the predictor, and under rigid contact without the soft
            penalty stage; where that start inverts an element or Newton fails from it, the
            increment runs again from the linearized predictor. It changes where Newton
            starts, not the convergence test. None: no warm start.

    Returns:
        A :class:`QuasistaticResult`.

    Raises:
        InputError: Non-finite loads, mis-shaped weights, or options that are not a
            :class:`NewtonOptions`.
    """
    loads, times = _checked_loads(loads, times_s, "")
    options = checked_options(options)
    n = assembler.node_count
    if assembler.problem_count != 1:
        raise InputError(
            f"the assembler packs {assembler.problem_count} problems: use solve_quasistatic_batch",
            key="assembler",
            value=assembler.problem_count,
        )
    weights = np.zeros((n, 3)) if reaction_weights is None else np.asarray(reaction_weights)
    if weights.shape != (n, 3):
        raise InputError(f"reaction_weights must have shape ({n}, 3)", value=weights.shape)
    if assembler.viscous is not None and times is None:
        raise InputError(
            "a viscoelastic material needs the time of each load (times_s)", key="times_s"
        )
    path = LoadPath(
        loads=loads,
        times=times,
        conditions=conditions,
        nodes=slice(0, n),
        warm=_checked_warm(warm_states_m, loads, n, ""),
    )
    (result,) = follow_paths(
        assembler,
        [path],
        weights,
        options=options,
        force_floors=_force_floors(assembler, None),
        sensitivity=sensitivity,
        initial_displacement_m=initial_displacement_m,
        progress=progress,
        progress_label=progress_label,
        load_name=load_name,
        profile=profile,
    )
    return result


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
    times_s: Sequence[np.ndarray | None] | None = None,
    progress: bool = False,
    profile: bool = False,
    warm_states_m: Sequence[np.ndarray | None] | None = None,
) -> list[QuasistaticResult]:
    """Follow K displacement-controlled load paths together, one per packed problem.

    The loop of :func:`solve_quasistatic` with K problems: each has its own prescribed dofs,
    loads (and times), reaction weights, increments, cutbacks and every Newton decision
    (predictor, line search, damping, nonlinear elimination, convergence test), in its own
    node numbering; each Newton iteration assembles all problems still iterating in one
    launch and solves their block-diagonal tangent in one linear solve (with the old factors
    where every iterating problem is close to its factorized state,
    ``options.reuse_factorization``). A problem that has finished its increment waits frozen.
    Each problem's converged states are those it reaches alone, to the Newton tolerance.

    Args:
        assembler: An assembler of ``packed.mesh`` with one material per problem
            (``element_problem=packed.element_problem``), and each problem's rigid contact
            where it has one (:meth:`warptissue.fem.Assembler.set_contact`; its depth is the
            problem's load).
        packed: The packed meshes.
        conditions: Each problem's prescribed dofs, (K,).
        loads: Each problem's load factors, (K,) arrays of shape (S_k,).
        reaction_weights: Each problem's weights (N_k, 3) of the internal forces summed into
            its ``reaction``.
        options: The Newton settings (:class:`NewtonOptions`; None: the defaults).
        load_name: What the load is called in messages (e.g. ``"depth (m)"``).
        sensitivities: Material parameters to differentiate each reaction by, exactly, at
            each requested load (each problem by its own parameters of these names; moduli,
            not Ogden exponents; :class:`warptissue.fem.ForceSensitivity`).
        times_s: Each problem's times (None entries, or None: quasi-static paths); an
            elastic material ignores them, as in :func:`solve_quasistatic`.
        progress: Show a tqdm bar over all problems' requested loads.
        profile: Time the Newton phases into each result's ``timings`` (shared by all).
        warm_states_m: Each problem's warm start (None entries, or None: none), each as
            :func:`solve_quasistatic`'s, (S'_k, N_k, 3) in the problem's own nodes.

    Returns:
        One :class:`QuasistaticResult` per problem (the linear solver's statistics and
        timings are those of the shared run).

    Raises:
        InputError: Lists of another length than K, an assembler of another mesh, bad loads
            or times, or a sensitivity the batch cannot take.
        SolveInterrupted: Ctrl-C; its ``partial_result`` is the list of each problem's
            converged steps.
    """
    options = checked_options(options)
    count = packed.problem_count
    times_list = [None] * count if times_s is None else list(times_s)
    warm_list = [None] * count if warm_states_m is None else list(warm_states_m)
    for name, values in (
        ("conditions", conditions),
        ("loads", loads),
        ("reaction_weights", reaction_weights),
        ("times_s", times_list),
        ("warm_states_m", warm_list),
    ):
        if len(values) != count:
            raise InputError(f"one entry per packed problem ({count})", key=name, value=len(values))
    check_packed_assembler(assembler, packed)
    for k, material in enumerate(assembler.materials):
        if isinstance(material, Viscoelastic) and times_list[k] is None:
            raise InputError(
                f"problem {k}: a viscoelastic material needs the time of each load (times_s)",
                key="times_s",
            )
    n = packed.mesh.node_count
    weights = np.zeros((n, 3))
    paths = []
    for k in range(count):
        path_loads, times = _checked_loads(loads[k], times_list[k], f"problem {k}: ")
        if path_loads.size == 0:
            raise InputError(f"problem {k}: loads must not be empty", key="loads")
        nodes = packed.nodes(k)
        size = nodes.stop - nodes.start
        warm = _checked_warm(warm_list[k], path_loads, size, f"problem {k}: ")
        paths.append(
            LoadPath(
                loads=path_loads, times=times, conditions=conditions[k], nodes=nodes, warm=warm
            )
        )
        weight = np.asarray(reaction_weights[k], dtype=np.float64)
        if weight.shape != (size, 3):
            raise InputError(
                f"problem {k}: reaction_weights must have shape ({size}, 3)",
                key="reaction_weights",
                value=weight.shape,
            )
        weights[nodes] = weight
    sensitivity = None
    if len(sensitivities):
        union = DirichletConditions.combine(
            *(
                DirichletConditions(
                    condition.nodes + packed.node_offsets[k],
                    condition.components,
                    condition.values_per_load,
                )
                for k, condition in enumerate(conditions)
            )
        )
        sensitivity = ForceSensitivity(
            assembler, union, tuple(sensitivities), weights, node_offsets=packed.node_offsets
        )
    return follow_paths(
        assembler,
        paths,
        weights,
        options=options,
        force_floors=_force_floors(assembler, packed.element_problem),
        sensitivity=sensitivity,
        initial_displacement_m=None,
        progress=progress,
        progress_label="load steps",
        load_name=load_name,
        profile=profile,
    )


def check_packed_assembler(
    assembler: Assembler, packed: PackedMeshes, formulation: str | None = None
) -> None:
    """Refuse an assembler of other packed meshes (or of another ``formulation``).

    Raises:
        InputError: Naming what the assembler was built for and what was expected.
    """
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
