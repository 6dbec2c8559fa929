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

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from time import perf_counter
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from warptissue.errors import InputError
from warptissue.fem.assembly import Assembler
from warptissue.fem.linear import LinearSolver
from warptissue.fem.newton import increment
from warptissue.fem.newton.options import NewtonOptions, checked_options
from warptissue.fem.newton.problems import DirichletConditions, Problems
from warptissue.fem.newton.sensitivity import ForceSensitivity
from warptissue.fem.newton.steering import ReuseTracker
from warptissue.fem.packing import PackedMeshes
from warptissue.fem.timing import NewtonTimings, PhaseTimer
from warptissue.materials import Viscoelastic

__all__ = [
    "QuasistaticResult",
    "SolveInterrupted",
    "solve_quasistatic",
    "solve_quasistatic_batch",
]


@dataclass
class QuasistaticResult:
    """Converged states of a displacement-controlled load path.

    Attributes:
        loads: Load factors reached, shape (S,) (a prefix of the requested ones).
        displacement_m: Nodal displacements at each, shape (S, N, 3).
        reaction: ``sum(reaction_weights * f_int)`` at each, shape (S,) (``f_int``: the
            internal and contact forces, without support springs' forces).
        newton_iterations: Newton iterations per requested load (all substeps), shape (S,).
        linear_iterations: Linear-solver iterations per requested load, shape (S,).
        local_iterations: Local Newton iterations of the nonlinear elimination per requested
            load, shape (S,).
        completed: Whether every requested load converged.
        message: What happened, in one sentence.
        cutbacks: Increment halvings used.
        linear_solver: The linear solver used.
        history: One record per attempted increment (load, converged, iterations,
            local_iterations, reason).
        reaction_sensitivity: ``d reaction / d theta`` at each converged load, shape (S, n),
            for the n parameters of the ``sensitivity`` passed in (n = 0 without one).
        times_s: The time of each converged load of a timed path, s; else the load-step
            number 1..S, shape (S,).
        timings: Where the wall time went, per phase (:class:`warptissue.fem.NewtonTimings`),
            when the path was profiled (``profile=True``); else None.
        linear_solver_statistics: The linear solver's counts over the path:
            ``factorizations``, ``reused_solves`` (Newton solves by GMRES with earlier
            factors, :meth:`LinearSolver.solve_newton`), ``krylov_iterations`` and
            ``failed_reuses`` (GMRES attempts that gave up for a factorization).
    """

    loads: np.ndarray
    displacement_m: np.ndarray
    reaction: np.ndarray
    newton_iterations: np.ndarray
    linear_iterations: np.ndarray
    local_iterations: np.ndarray
    completed: bool
    message: str
    cutbacks: int = 0
    linear_solver: str = ""
    history: list[dict] = field(default_factory=list)
    reaction_sensitivity: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    times_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    timings: NewtonTimings | None = None
    linear_solver_statistics: dict[str, int] = field(default_factory=dict)


class SolveInterrupted(KeyboardInterrupt):
    """Ctrl-C during a solve, carrying the load steps that converged before it.

    A :class:`KeyboardInterrupt`, so that code that does not look for it stops as usual.

    Args:
        message: What was interrupted, and how many steps are kept.
        partial_result: The result of the converged steps (``completed=False``): a
            :class:`QuasistaticResult` from :func:`solve_quasistatic`, an
            :class:`warptissue.fem.IndentationResult` from
            :func:`warptissue.fem.simulate_indentation`.
    """

    def __init__(self, message: str, *, partial_result: Any) -> None:
        super().__init__(message)
        self.message = message
        self.partial_result = partial_result


@dataclass
class _Path:
    """One problem's place on its load path, and what it has converged so far."""

    loads: np.ndarray
    times: np.ndarray | None
    conditions: DirichletConditions
    nodes: slice
    load: float = 0.0
    time: float = 0.0
    index: int = 0
    start_load: float = 0.0
    start_time: float = 0.0
    fraction: float = 0.0
    step_fraction: float = 1.0
    halvings: int = 0
    cutbacks: int = 0
    retry_linearized: bool = False
    previous: tuple[float, Any] | None = None
    step_counts: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.int64))
    step_sensitivity: np.ndarray | None = None
    finished: bool = False
    completed: bool = True
    message: str = ""
    reached: list[float] = field(default_factory=list)
    states: list[np.ndarray] = field(default_factory=list)
    reactions: list[float] = field(default_factory=list)
    counts: list[np.ndarray] = field(default_factory=list)
    history: list[dict] = field(default_factory=list)
    sensitivities: list[np.ndarray] = field(default_factory=list)

    @property
    def node_count(self) -> int:
        return self.nodes.stop - self.nodes.start

    def next_step(self) -> tuple[float, float, float]:
        """(fraction of the way to the next requested load, its load, its time)."""
        fraction = self.fraction + self.step_fraction
        if fraction >= 1.0 - 1e-12:
            fraction = 1.0
        target = float(self.loads[self.index])
        target_time = self.time if self.times is None else float(self.times[self.index])
        if fraction == 1.0:
            return fraction, target, target_time
        load = self.start_load + fraction * (target - self.start_load)
        time = self.start_time + fraction * (target_time - self.start_time)
        return fraction, load, time

    def prescribed_increment(self, load: float) -> np.ndarray:
        """The prescribed dofs' increment from the current load to ``load``, (N_k, 3), m."""
        size = self.node_count
        return self.conditions.values(load, size) - self.conditions.values(self.load, size)

    def extrapolation(self, step: tuple[float, float, float], predictor: str) -> float | None:
        """The factor of the last converged change that predicts the free dofs of the
        increment to ``step`` (the extrapolated predictor), or None: none to make."""
        _, load, time = step
        here, there = (self.load, load) if self.times is None else (self.time, time)
        guess = (
            predictor == "extrapolated"
            and self.previous is not None
            and not self.retry_linearized
            and here != self.previous[0]
        )
        self.retry_linearized = False
        return (there - here) / (here - self.previous[0]) if guess else None

    def finish_increment(
        self,
        step: tuple[float, float, float],
        *,
        converged: bool,
        counts: tuple[int, int, int],
        reason: str,
        from_guess: bool,
        state: Any,
        at_target: bool,
        reaction: float,
        derivative: np.ndarray | None,
        states: Any,
        max_cutbacks: int,
        load_name: str,
    ) -> bool:
        """Take an increment's outcome: its history, and on success the new place on the
        path (and the requested load reached, with its state from ``states()``, reaction
        and derivatives); on failure a retry from the linearized predictor, a cutback, or
        the end of the path. ``state``: the converged state the increment started from.

        Returns:
            Whether a requested load was reached.
        """
        fraction, load, time = step
        self.step_counts += counts
        self.history.append(
            {
                "load": load,
                **({} if self.times is None else {"time_s": time}),
                "converged": converged,
                "iterations": int(counts[0]),
                "local_iterations": int(counts[2]),
                "reason": reason,
            }
        )
        if converged:
            here, there = (self.load, load) if self.times is None else (self.time, time)
            if there != here:
                self.previous = (here, state)
            self.load, self.time, self.fraction = load, time, fraction
            if derivative is not None:
                self.step_sensitivity = derivative
            if not at_target:
                self.step_fraction = min(2.0 * self.step_fraction, 1.0 - fraction)
                return False
            self.reached.append(float(self.loads[self.index]))
            self.states.append(states()[self.nodes].copy())
            self.reactions.append(reaction)
            if self.step_sensitivity is not None:
                self.sensitivities.append(self.step_sensitivity)
            self.counts.append(self.step_counts.copy())
            self.step_counts[:] = 0
            self.index += 1
            self.start_load, self.start_time = self.load, self.time
            self.fraction, self.step_fraction, self.halvings = 0.0, 1.0, 0
            self.finished = self.index == len(self.loads)
            return True
        if from_guess:  # retry the increment from the linearized predictor before cutting back
            self.retry_linearized = True
            return False
        self.halvings += 1
        self.cutbacks += 1
        if self.halvings <= max_cutbacks:
            self.step_fraction *= 0.5
            return False
        self.finished, self.completed = True, False
        target = float(self.loads[self.index])
        timed = "" if self.times is None else f" (t = {self.time:.6g} s)"
        span = ""
        if self.times is not None:
            duration = self.step_fraction * (float(self.times[self.index]) - self.start_time)
            span = f" over {duration:.3g} s"
        self.message = (
            f"stopped at {load_name} {self.load:.6g} on the way to {target:.6g}{timed}: Newton "
            f"failed ({reason}) after {max_cutbacks} cutbacks (last increment "
            f"{self.step_fraction * (target - self.start_load):.3g}{span}); the "
            f"{len(self.reached)} converged steps are kept"
        )
        return False

    def result(
        self, completed: bool, message: str, count: int, sensitivity_count: int, **common: Any
    ) -> QuasistaticResult:
        counts = np.array(self.counts[:count], dtype=np.int64).reshape(count, 3)
        return QuasistaticResult(
            loads=np.array(self.reached[:count]),
            displacement_m=np.array(self.states[:count]).reshape(count, self.node_count, 3),
            reaction=np.array(self.reactions[:count]),
            newton_iterations=counts[:, 0].copy(),
            linear_iterations=counts[:, 1].copy(),
            local_iterations=counts[:, 2].copy(),
            completed=completed,
            message=message,
            cutbacks=self.cutbacks,
            history=self.history,
            reaction_sensitivity=np.array(self.sensitivities[:count]).reshape(
                count, sensitivity_count
            ),
            times_s=(
                np.arange(1.0, count + 1.0) if self.times is None else np.array(self.times[:count])
            ),
            **common,
        )


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


def _follow_paths(
    assembler: Assembler,
    paths: list[_Path],
    weights: np.ndarray,
    *,
    options: NewtonOptions,
    force_floors: np.ndarray,
    sensitivity: ForceSensitivity | None,
    initial_displacement_m: np.ndarray | None,
    progress: bool,
    progress_label: str,
    load_name: str,
    profile: bool,
) -> list[QuasistaticResult]:
    """The Newton loop over K load paths: the engine of :func:`solve_quasistatic` (K = 1)
    and :func:`solve_quasistatic_batch`."""
    started = perf_counter()
    count = len(paths)
    n = assembler.node_count
    viscous = assembler.viscous
    solver = LinearSolver(method=options.linear_solver, device=assembler.device, owner=assembler)
    arrays = solver.arrays
    reuse = ReuseTracker()
    timer = PhaseTimer(enabled=profile, device=assembler.device)
    solver.timer = timer
    offsets = np.array([path.nodes.start for path in paths] + [n], dtype=np.int64)
    constrained = np.zeros((n, 3))
    for path in paths:
        constrained[path.nodes] = path.conditions.mask(path.node_count)
    free = 1.0 - constrained
    u = np.zeros((n, 3)) if initial_displacement_m is None else np.array(initial_displacement_m)
    # The state stays in the Newton loop's arrays (on a GPU: on the device) along the paths;
    # the converged states come to the host once per requested load.
    with arrays.context():
        problems = Problems(arrays, offsets)
        u, free_x, weights_x = arrays.asarray(u), arrays.asarray(free), arrays.asarray(weights)
        constrained_x = arrays.asarray(constrained)
        # Support springs (an elastic foundation): the reaction sums w . (R - S u), the
        # internal and contact forces alone (warptissue.fem.support).
        springs_x = None
        if assembler.has_springs:
            springs_x = arrays.asarray(-assembler.spring_product(weights))
    sensitivity_count = 0 if sensitivity is None else len(sensitivity.names)
    # A plate touches the whole surface: no contact edge crosses nodes, and the ramp would
    # only repeat its iterations (4 -> 8-13 per step measured). Of K problems, all take the
    # ramp where one has another rigid indenter (the stiff stage's test decides for all).
    ramped = increment.CONTACT_PENALTY_RAMP < 1.0 and any(
        each is not None and each.indenter.kind != "plate" for each in assembler.contacts
    )
    eliminating = options.eliminates(
        is_cuda=assembler.device.is_cuda,
        tets_per_problem=assembler.tet_count // assembler.problem_count,
        problem_count=assembler.problem_count,
    )
    for path in paths:
        path.finished = path.loads.size == 0
        path.message = f"converged at all {len(path.loads)} requested values of {load_name}"
    bar = None

    def results(interrupted: bool = False) -> list[QuasistaticResult]:
        common = {
            "linear_solver": solver.method,
            "timings": (
                timer.timings(
                    total_s=perf_counter() - started, factorizations=solver.factorizations
                )
                if profile
                else None
            ),
            "linear_solver_statistics": solver.statistics(),
        }
        return [
            path.result(
                path.completed and not interrupted,
                "interrupted" if interrupted else path.message,
                len(path.counts),
                sensitivity_count,
                **common,
            )
            for path in paths
        ]

    if progress:
        bar = tqdm(
            total=sum(len(path.loads) for path in paths),
            desc=progress_label,
            unit="step",
            leave=False,
        )
    try:
        with arrays.context():
            while not all(path.finished for path in paths):
                active = np.array([not path.finished for path in paths])
                prescribed = np.zeros((n, 3))
                guess = None
                guessed = np.zeros(count, dtype=bool)
                steps = {}
                for k in np.flatnonzero(active):
                    path = paths[k]
                    steps[k] = path.next_step()
                    prescribed[path.nodes] = path.prescribed_increment(steps[k][1])
                    ratio = path.extrapolation(steps[k], options.predictor)
                    if ratio is not None:
                        change = (u - path.previous[1]) * ratio
                        if count == 1:
                            guess = change
                        else:
                            if guess is None:
                                guess = arrays.xp.zeros_like(u)
                            guess[path.nodes] = change[path.nodes]
                        guessed[k] = True
                # Each problem's viscous step and rigid indenter depth for this increment
                # (a finished problem keeps its load; its rows stay frozen).
                next_loads = np.array([path.load for path in paths])
                time_steps = np.ones(count)
                for k, (_, next_load, next_time) in steps.items():
                    next_loads[k] = next_load
                    if paths[k].times is not None:  # an elastic problem ignores time
                        time_steps[k] = next_time - paths[k].time
                if viscous is not None:
                    viscous.begin_step(time_steps if count > 1 else float(time_steps[0]))
                assembler.set_load(next_loads if count > 1 else float(next_loads[0]))
                advance = (
                    increment.penalty_ramped_increment if ramped else increment.newton_increment
                )
                step = advance(
                    assembler,
                    solver,
                    problems,
                    u,
                    arrays.asarray(prescribed),
                    free_x,
                    constrained_x,
                    active=active,
                    tolerance=options.tolerance,
                    force_floors=force_floors,
                    max_iterations=options.max_newton_iterations,
                    nonlinear_elimination_on=eliminating,
                    free_guess=guess,
                    guessed=guessed if guess is not None else None,
                    damping=options.damping,
                    reuse_factorization=options.reuse_factorization,
                    reuse=reuse,
                    timer=timer,
                )
                timer.count_iterations(int(step.iterations.max()))
                at_target = np.zeros(count, dtype=bool)
                for k in np.flatnonzero(active & step.converged):
                    at_target[k] = steps[k][0] == 1.0
                if at_target.any():
                    # The internal force of the converged states (with the step's frozen
                    # history), as Newton's last assembly left it.
                    reductions = [problems.dot(weights_x, step.residual)]
                    if springs_x is not None:
                        reductions.append(problems.dot(springs_x, step.displacement))
                    reactions = np.sum(problems.read(*reductions), axis=0)
                derivatives = None
                if sensitivity is not None:
                    wanted = at_target if viscous is None else active & step.converged
                    if wanted.any():
                        # A viscous history needs its derivatives advanced at every substep.
                        with timer.phase("sensitivity"):
                            derivatives = sensitivity.at_converged_state(
                                solver,
                                arrays.host(step.displacement),
                                reached=None if count == 1 else wanted,
                            )
                if viscous is not None and step.converged.any():
                    viscous.commit(
                        assembler,
                        assembler.device_displacement(step.displacement),
                        problems=None if count == 1 else step.converged,
                    )
                # The converged states on the host, read once where a requested load is reached.
                states = functools.cache(functools.partial(arrays.host, step.displacement))
                for k in np.flatnonzero(active):
                    path = paths[k]
                    derivative = None
                    if derivatives is not None:
                        derivative = derivatives if count == 1 else derivatives[k]
                    reached = path.finish_increment(
                        steps[k],
                        converged=bool(step.converged[k]),
                        counts=(
                            step.iterations[k],
                            step.linear_iterations[k],
                            step.local_iterations[k],
                        ),
                        reason=step.reasons[k],
                        from_guess=bool(step.from_guess[k]),
                        state=u,
                        at_target=bool(at_target[k]),
                        reaction=float(reactions[k]) if at_target[k] else 0.0,
                        derivative=derivative,
                        states=states,
                        max_cutbacks=options.max_cutbacks,
                        load_name=load_name,
                    )
                    if reached and bar is not None:
                        bar.set_postfix(newton_iterations=int(path.counts[-1][0]), refresh=False)
                        bar.update(1)
                u = step.displacement
    except KeyboardInterrupt as exc:
        partial = results(interrupted=True)
        first = paths[0]
        done = len(first.counts)
        message = (
            f"interrupted on the way to {load_name} "
            f"{first.loads[min(done, len(first.loads) - 1)]:.6g}; the {done} converged steps "
            "are kept"
            if count == 1
            else "interrupted; the converged steps of every problem are kept"
        )
        raise SolveInterrupted(
            message, partial_result=partial[0] if count == 1 else partial
        ) from exc
    finally:
        if bar is not None:
            bar.close()
    return results()


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
    path = _Path(loads=loads, times=times, conditions=conditions, nodes=slice(0, n))
    (result,) = _follow_paths(
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
    for name, values in (
        ("conditions", conditions),
        ("loads", loads),
        ("reaction_weights", reaction_weights),
        ("times_s", times_list),
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
        paths.append(_Path(loads=path_loads, times=times, conditions=conditions[k], nodes=nodes))
        weight = np.asarray(reaction_weights[k], dtype=np.float64)
        size = nodes.stop - nodes.start
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
    return _follow_paths(
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
