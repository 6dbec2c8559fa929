"""The Newton loop over K load paths, in named steps: each pass predicts every unfinished
path's increment, sets its load, advances Newton
(:mod:`~warptissue.fem.newton.increment`), reads the reactions and derivatives where a
requested load is reached, commits the viscous histories, and lets each path take its
outcome (a cutback, the next increment, or the end). :func:`follow_paths` is the engine of
:func:`warptissue.fem.newton.solve_quasistatic` and
:func:`warptissue.fem.newton.solve_quasistatic_batch` (:mod:`~warptissue.fem.newton.path`)."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from time import perf_counter
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from warptissue.fem.assembly import Assembler
from warptissue.fem.linear import LinearSolver
from warptissue.fem.newton import increment
from warptissue.fem.newton.options import NewtonOptions
from warptissue.fem.newton.problems import DirichletConditions, Problems
from warptissue.fem.newton.result import QuasistaticResult, SolveInterrupted
from warptissue.fem.newton.sensitivity import ForceSensitivity
from warptissue.fem.newton.steering import ReuseTracker
from warptissue.fem.timing import PhaseTimer


@dataclass
class LoadPath:
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
    warm: np.ndarray | None = None
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

    def warm_state(self, step: tuple[float, float, float]) -> np.ndarray | None:
        """The state (N_k, 3) an earlier run converged to at the requested load that the
        increment to ``step`` reaches (the warm start), or None: none given for that load, the
        increment stops short of it, or it failed from there and runs again linearized. Read
        before :meth:`extrapolation`, which clears the retry."""
        if (
            self.warm is None
            or self.retry_linearized
            or step[0] != 1.0
            or self.index >= len(self.warm)
        ):
            return None
        return self.warm[self.index]

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


@dataclass
class NewtonLoop:
    """What the Newton loop over K load paths holds from its start to its end: the solver,
    the problems' arrays (on a GPU: on the device), the fixed masks and weights, and the
    decisions taken once (the contact penalty ramp, nonlinear elimination)."""

    assembler: Assembler
    paths: list[LoadPath]
    options: NewtonOptions
    sensitivity: ForceSensitivity | None
    load_name: str
    profile: bool
    started: float
    solver: Any
    arrays: Any
    problems: Any
    timer: PhaseTimer
    reuse: ReuseTracker
    free_x: Any
    constrained_x: Any
    weights_x: Any
    springs_x: Any
    ramped: bool
    eliminating: bool
    reusing: bool
    force_floors: np.ndarray

    @property
    def count(self) -> int:
        return len(self.paths)

    def predict(self, u: Any) -> tuple[np.ndarray, np.ndarray, Any, np.ndarray, np.ndarray, dict]:
        """Each unfinished path's next increment: (active, prescribed dof increments (n, 3),
        the guessed change of the free dofs or None, which paths guessed, which of them from
        a warm start, the steps). A path guesses from its warm start
        (:meth:`LoadPath.warm_state`) where it has one for the load the increment reaches,
        else by the extrapolated predictor where that is chosen."""
        count, paths = self.count, self.paths
        active = np.array([not path.finished for path in paths])
        prescribed = np.zeros((self.assembler.node_count, 3))
        guess = None
        guessed = np.zeros(count, dtype=bool)
        warmed = np.zeros(count, dtype=bool)
        steps = {}
        for k in np.flatnonzero(active):
            path = paths[k]
            steps[k] = path.next_step()
            prescribed[path.nodes] = path.prescribed_increment(steps[k][1])
            warm = path.warm_state(steps[k])
            ratio = path.extrapolation(steps[k], self.options.predictor)
            if warm is None and ratio is None:
                continue
            if warm is not None:
                change = self.arrays.asarray(warm) - u[path.nodes]
                warmed[k] = True
            else:
                change = (u[path.nodes] - path.previous[1][path.nodes]) * ratio
            guessed[k] = True
            if count == 1:
                guess = change
                continue
            if guess is None:
                guess = self.arrays.xp.zeros_like(u)
            guess[path.nodes] = change
        return active, prescribed, guess, guessed, warmed, steps

    def load(self, steps: dict) -> None:
        """Each problem's viscous step and rigid indenter depth for this increment (a
        finished problem keeps its load; its rows stay frozen)."""
        count, paths, viscous = self.count, self.paths, self.assembler.viscous
        next_loads = np.array([path.load for path in paths])
        time_steps = np.ones(count)
        for k, (_, next_load, next_time) in steps.items():
            next_loads[k] = next_load
            if paths[k].times is not None:  # an elastic problem ignores time
                time_steps[k] = next_time - paths[k].time
        if viscous is not None:
            viscous.begin_step(time_steps if count > 1 else float(time_steps[0]))
        self.assembler.set_load(next_loads if count > 1 else float(next_loads[0]))

    def advance(
        self,
        u: Any,
        prescribed: np.ndarray,
        active: np.ndarray,
        guess: Any,
        guessed: np.ndarray,
        warmed: np.ndarray,
    ) -> Any:
        """One Newton increment of every active problem
        (:func:`~warptissue.fem.newton.increment.newton_increment`, or under the contact
        penalty ramp its ramped form; not where every active problem starts warm: a state
        converged under the full penalty needs no soft stage to reach its contact)."""
        options = self.options
        ramped = self.ramped and not warmed[active].all()
        advance = increment.penalty_ramped_increment if ramped else increment.newton_increment
        step = advance(
            self.assembler,
            self.solver,
            self.problems,
            u,
            self.arrays.asarray(prescribed),
            self.free_x,
            self.constrained_x,
            active=active,
            tolerance=options.tolerance,
            force_floors=self.force_floors,
            max_iterations=options.max_newton_iterations,
            nonlinear_elimination_on=self.eliminating,
            free_guess=guess,
            guessed=guessed if guess is not None else None,
            damping=options.damping,
            reuse_factorization=self.reusing,
            reuse=self.reuse,
            timer=self.timer,
        )
        self.timer.count_iterations(int(step.iterations.max()))
        return step

    def reactions(self, step: Any, at_target: np.ndarray) -> np.ndarray | None:
        """The reaction of each problem that reached its requested load: the internal force
        of the converged states (with the step's frozen history), as Newton's last assembly
        left it, summed with the weights (and the support springs' share); None: none did."""
        if not at_target.any():
            return None
        problems = self.problems
        reductions = [problems.dot(self.weights_x, step.residual)]
        if self.springs_x is not None:
            reductions.append(problems.dot(self.springs_x, step.displacement))
        return np.sum(problems.read(*reductions), axis=0)

    def derivatives(self, step: Any, active: np.ndarray, at_target: np.ndarray) -> Any:
        """The reaction's derivatives at the converged states that need them (a viscous
        history needs them advanced at every substep), or None."""
        if self.sensitivity is None:
            return None
        viscous = self.assembler.viscous
        wanted = at_target if viscous is None else active & step.converged
        if not wanted.any():
            return None
        with self.timer.phase("sensitivity"):
            return self.sensitivity.at_converged_state(
                self.solver,
                self.arrays.host(step.displacement),
                reached=None if self.count == 1 else wanted,
            )

    def commit(self, step: Any) -> None:
        """Advance the viscous histories of the problems whose increment converged."""
        viscous = self.assembler.viscous
        if viscous is not None and step.converged.any():
            viscous.commit(
                self.assembler,
                self.assembler.device_displacement(step.displacement),
                problems=None if self.count == 1 else step.converged,
            )

    def finish(
        self,
        u: Any,
        step: Any,
        steps: dict,
        active: np.ndarray,
        at_target: np.ndarray,
        reactions: np.ndarray | None,
        derivatives: Any,
        bar: Any,
    ) -> None:
        """Each active path takes its increment's outcome (:meth:`LoadPath.finish_increment`);
        the converged states come to the host once, where a requested load is reached."""
        states = functools.cache(functools.partial(self.arrays.host, step.displacement))
        for k in np.flatnonzero(active):
            path = self.paths[k]
            derivative = None
            if derivatives is not None:
                derivative = derivatives if self.count == 1 else derivatives[k]
            reached = path.finish_increment(
                steps[k],
                converged=bool(step.converged[k]),
                counts=(step.iterations[k], step.linear_iterations[k], step.local_iterations[k]),
                reason=step.reasons[k],
                from_guess=bool(step.from_guess[k]),
                state=u,
                at_target=bool(at_target[k]),
                reaction=float(reactions[k]) if at_target[k] else 0.0,
                derivative=derivative,
                states=states,
                max_cutbacks=self.options.max_cutbacks,
                load_name=self.load_name,
            )
            if reached and bar is not None:
                bar.set_postfix(newton_iterations=int(path.counts[-1][0]), refresh=False)
                bar.update(1)

    def results(self, interrupted: bool = False) -> list[QuasistaticResult]:
        """Each path's result so far (``interrupted``: none of them completed)."""
        solver, timer = self.solver, self.timer
        timings = None
        if self.profile:
            timings = timer.timings(
                total_s=perf_counter() - self.started, factorizations=solver.factorizations
            )
        common = {
            "linear_solver": solver.method,
            "timings": timings,
            "linear_solver_statistics": solver.statistics(),
        }
        sensitivity_count = 0 if self.sensitivity is None else len(self.sensitivity.names)
        return [
            path.result(
                path.completed and not interrupted,
                "interrupted" if interrupted else path.message,
                len(path.counts),
                sensitivity_count,
                **common,
            )
            for path in self.paths
        ]

    def interrupted(self) -> SolveInterrupted:
        """The exception for Ctrl-C in the loop, carrying the converged steps."""
        partial = self.results(interrupted=True)
        first = self.paths[0]
        done = len(first.counts)
        message = (
            f"interrupted on the way to {self.load_name} "
            f"{first.loads[min(done, len(first.loads) - 1)]:.6g}; the {done} converged steps "
            "are kept"
            if self.count == 1
            else "interrupted; the converged steps of every problem are kept"
        )
        return SolveInterrupted(message, partial_result=partial[0] if self.count == 1 else partial)


def start_loop(
    assembler: Assembler,
    paths: list[LoadPath],
    weights: np.ndarray,
    u: np.ndarray,
    *,
    options: NewtonOptions,
    force_floors: np.ndarray,
    sensitivity: ForceSensitivity | None,
    load_name: str,
    profile: bool,
) -> tuple[NewtonLoop, Any]:
    """Set the Newton loop up: its solver and arrays, the constrained dofs' mask, the
    weights (and support springs) of the reaction, and the decisions taken once. Returns the
    loop and the start state ``u`` in its arrays."""
    started = perf_counter()
    n = assembler.node_count
    solver = LinearSolver(method=options.linear_solver, device=assembler.device, owner=assembler)
    arrays = solver.arrays
    timer = PhaseTimer(enabled=profile, device=assembler.device)
    solver.timer = timer
    offsets = np.array([path.nodes.start for path in paths] + [n], dtype=np.int64)
    constrained = np.zeros((n, 3))
    for path in paths:
        constrained[path.nodes] = path.conditions.mask(path.node_count)
    free = 1.0 - constrained
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
    loop = NewtonLoop(
        assembler=assembler,
        paths=paths,
        options=options,
        sensitivity=sensitivity,
        load_name=load_name,
        profile=profile,
        started=started,
        solver=solver,
        arrays=arrays,
        problems=problems,
        timer=timer,
        reuse=ReuseTracker(),
        free_x=free_x,
        constrained_x=constrained_x,
        weights_x=weights_x,
        springs_x=springs_x,
        ramped=ramped,
        eliminating=eliminating,
        reusing=options.reuses(is_cuda=assembler.device.is_cuda, tet_count=assembler.tet_count),
        force_floors=force_floors,
    )
    return loop, u


def follow_paths(
    assembler: Assembler,
    paths: list[LoadPath],
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
    and :func:`solve_quasistatic_batch`. Each pass: predict every unfinished path's
    increment, set its load, advance Newton, read the reactions and derivatives where a
    requested load is reached, commit the viscous histories, and let each path take its
    outcome (:class:`NewtonLoop`)."""
    n = assembler.node_count
    u = np.zeros((n, 3)) if initial_displacement_m is None else np.array(initial_displacement_m)
    loop, u = start_loop(
        assembler,
        paths,
        weights,
        u,
        options=options,
        force_floors=force_floors,
        sensitivity=sensitivity,
        load_name=load_name,
        profile=profile,
    )
    bar = None
    if progress:
        bar = tqdm(
            total=sum(len(path.loads) for path in paths),
            desc=progress_label,
            unit="step",
            leave=False,
        )
    try:
        with loop.arrays.context():
            while not all(path.finished for path in paths):
                active, prescribed, guess, guessed, warmed, steps = loop.predict(u)
                loop.load(steps)
                step = loop.advance(u, prescribed, active, guess, guessed, warmed)
                at_target = np.zeros(loop.count, dtype=bool)
                for k in np.flatnonzero(active & step.converged):
                    at_target[k] = steps[k][0] == 1.0
                reactions = loop.reactions(step, at_target)
                derivatives = loop.derivatives(step, active, at_target)
                loop.commit(step)
                loop.finish(u, step, steps, active, at_target, reactions, derivatives, bar)
                u = step.displacement
    except KeyboardInterrupt as exc:
        raise loop.interrupted() from exc
    finally:
        if bar is not None:
            bar.close()
    return loop.results()
