"""Newton's iterations for one load increment of K problems at once.

Each iteration assembles the problems still iterating in one launch, solves their tangent in
one linear solve (block diagonal: the problems share no node), searches each problem's step
(:mod:`~warptissue.fem.newton.search`), damps each problem's tangent after a cut step, relaxes
each problem's residual peak (:mod:`~warptissue.fem.newton.elimination`) and tests each
problem's convergence. A problem that has converged, or failed, is frozen: its dofs are
treated as prescribed with a zero increment (identity rows, zero right-hand side), so its state
stays as it was while the others iterate. One problem (K = 1) is the single run.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import warp as wp
import warp.sparse as wps

from warptissue.fem.assembly import Assembler
from warptissue.fem.linear import LinearSolver
from warptissue.fem.newton.elimination import nonlinear_elimination
from warptissue.fem.newton.problems import Problems
from warptissue.fem.newton.search import search_steps
from warptissue.fem.newton.steering import ReuseTracker, forcing_term, next_damping
from warptissue.fem.timing import PhaseTimer

__all__ = [
    "CONTACT_PENALTY_RAMP",
    "CONTACT_RAMP_TOLERANCE",
    "Increment",
    "newton_increment",
    "penalty_ramped_increment",
]


@dataclass
class Increment:
    """Outcome of one load increment's Newton iterations, per problem (K,).

    Attributes:
        converged: Whether each problem converged.
        displacement: The state (N, 3), an array of the loop's library: each converged
            problem's new state, the others' start state.
        iterations: Newton iterations each problem took.
        linear_iterations: Its linear-solver iterations.
        local_iterations: Its local iterations of the nonlinear elimination.
        reasons: Why each problem stopped ("converged" or the failure).
        from_guess: Whether it started from the extrapolated guess.
        residual: The internal force at ``displacement`` (N, 3), valid for the converged
            problems' nodes: a view of the assembler's residual on the CPU, valid until the
            next assembly (the reaction is summed from it at once).
        last_iterate: The state the iterations ended at, failed problems' last iterates
            included (N, 3).
    """

    converged: np.ndarray
    displacement: Any
    iterations: np.ndarray
    linear_iterations: np.ndarray
    local_iterations: np.ndarray
    reasons: list[str] = field(default_factory=list)
    from_guess: np.ndarray | None = None
    residual: Any = None
    last_iterate: Any = None


def newton_increment(
    assembler: Assembler,
    solver: LinearSolver,
    problems: Problems,
    u_start: Any,
    prescribed_increment: Any,
    free: Any,
    constrained: Any,
    *,
    active: np.ndarray,
    tolerance: float,
    force_floors: np.ndarray,
    max_iterations: int,
    nonlinear_elimination_on: bool,
    free_guess: Any = None,
    guessed: np.ndarray | None = None,
    damping: bool = False,
    reuse_factorization: bool = False,
    reuse: ReuseTracker | None = None,
    timer: PhaseTimer | None = None,
) -> Increment:
    """Newton iterations for one load increment of the ``active`` problems.

    ``u_start``, ``prescribed_increment``, ``free``, ``constrained`` (N, 3): arrays of the
    solver's :class:`warptissue.fem.arrays.DeviceArrays` (CuPy on a CUDA device), which the
    iterations work in: on a GPU the state, residual, directions and trial states stay on
    the device, and each iteration reads only per-problem scalars (norms, slopes, energies).

    Args:
        assembler: The discretized body of all K problems.
        solver: The linear solver (one factorization for all problems).
        problems: The problems' node ranges and reductions.
        u_start: The converged state the increment starts from.
        prescribed_increment: The prescribed dofs' increment (0 on free dofs), m.
        free: 1 on free dofs, 0 on prescribed ones.
        constrained: ``1 - free``.
        active: The problems that take this increment, (K,); the others stay frozen.
        tolerance: Converged when a problem's free residual norm is at most ``tolerance``
            times its reaction norm.
        force_floors: Each problem's absolute floor of that limit, (K,), N.
        max_iterations: Newton iterations before the increment fails.
        nonlinear_elimination_on: Relax each problem's residual peak after its global step.
        free_guess: A predicted change of the free dofs over the increment (N, 3), m, for
            the problems ``guessed`` (K,). Where the state it gives (with the prescribed
            increment applied) inverts no element of a problem, that problem starts there;
            otherwise, and without a guess, from the linearized predictor.
        guessed: The problems that have a guess (None: all, where ``free_guess`` is given).
        damping: Adaptive Levenberg-Marquardt damping of each problem's tangent diagonal
            (:func:`~warptissue.fem.newton.steering.next_damping`).
        reuse_factorization: Solve with the last factorization by GMRES where that is
            cheaper (:meth:`LinearSolver.solve_newton`) and ``reuse`` finds every
            iterating problem close to its factorized state.
        reuse: The :class:`~warptissue.fem.newton.steering.ReuseTracker` kept over the load
            paths (None: a new one).
        timer: The phase timer the phases are charged to (None: not timed).

    Returns:
        An :class:`Increment`.
    """
    arrays = problems.arrays
    count = problems.count
    if reuse is None:
        reuse = ReuseTracker()
    if timer is None:
        timer = PhaseTimer(enabled=False)
    single = count == 1
    iterating = np.array(active, dtype=bool)
    converged = np.zeros(count, dtype=bool)
    iterations = np.zeros(count, dtype=np.int64)
    linear = np.zeros(count, dtype=np.int64)
    local = np.zeros(count, dtype=np.int64)
    reasons = [""] * count
    fixed = constrained
    u, assembly, linearized = _start(
        assembler,
        problems,
        u_start,
        prescribed_increment,
        free,
        free_guess,
        iterating if guessed is None else iterating & guessed,
        timer,
    )
    residual = arrays.view(assembly.residual)
    (reaction_squared,) = problems.read(problems.squared(residual * fixed))
    limits = np.maximum(tolerance * np.sqrt(reaction_squared), force_floors)
    norms = _ResidualNorms(problems, free, fixed, tolerance, force_floors)
    increment_wp = arrays.warp(prescribed_increment)
    k_times_increment = wp.zeros_like(increment_wp)
    constrained_wp = arrays.warp(constrained)
    frozen_wp = constrained_wp
    frozen = None
    on: Any = None
    factor = np.zeros(count)
    for iteration in range(1, max_iterations + 1):
        first = iterating & linearized if iteration == 1 else np.zeros(count, dtype=bool)
        if not single:
            on = problems.per_node(iterating.astype(np.float64))
            frozen = arrays.xp.ascontiguousarray(arrays.xp.maximum(constrained, 1.0 - on))
            frozen_wp = arrays.warp(frozen)  # ``frozen`` is kept alive while Warp uses it
        rhs = _newton_rhs(
            problems,
            assembly.matrix,
            residual,
            free,
            prescribed_increment,
            first,
            on,
            scratch=(increment_wp, k_times_increment),
        )
        with timer.phase("assembly"):
            assembler.eliminate(frozen_wp, damping=factor)
        try_old, rhs_squared = (
            reuse.promising(u, factor, problems, iterating, problems.squared(rhs))
            if reuse_factorization
            else (False, [])
        )
        # The forcing term matters only to a solve with the old factors.
        rtol = forcing_term(limits, np.sqrt(rhs_squared[0]), iterating) if try_old else 1.0
        factorizations = solver.factorizations
        du, linear_iterations = solver.solve_newton(assembly.matrix, rhs, rtol=rtol, reuse=try_old)
        if solver.factorizations > factorizations:
            reuse.factorized(u, factor)
        iterations[iterating] += 1
        linear[iterating] += linear_iterations
        free_du = du * free if on is None else du * free * on
        free_residual = residual * free
        du_squared, old_squared, slopes, free_du_squared, *scalars = problems.read(
            problems.squared(du if on is None else du * on),
            problems.squared(free_residual),
            problems.dot(free_residual, du),
            problems.squared(free_du),
            scalars=None if assembly.scalars is None else arrays.view(assembly.scalars),
        )
        if scalars:  # the tangent's energies, read with the step's reductions
            assembly = assembly.with_scalars(scalars[0])
        broken = iterating & ~np.isfinite(du_squared)
        for k in np.flatnonzero(broken):
            reasons[k] = "the linear solve gave non-finite values"
        iterating &= ~broken
        if not iterating.any():
            break
        if broken.any():  # their rows of the direction are not numbers
            free_du = free_du * problems.per_node(iterating.astype(np.float64))
            free_du = arrays.xp.nan_to_num(free_du)
        reuse.first_step(first, np.sqrt(free_du_squared))
        with timer.phase("line_search"):
            search = search_steps(
                assembler,
                problems,
                u,
                free_du,
                free,
                searching=iterating,
                first=first & iterating,
                prescribed_increment=prescribed_increment,
                energies_J=np.asarray(assembly.problem_energies_J, dtype=np.float64),
                slopes=slopes,
                residual_norms=np.sqrt(old_squared),
            )
        failed = iterating & ~search.found
        for k in np.flatnonzero(failed):
            reasons[k] = search.reasons[k]
        iterating &= search.found
        if not iterating.any():
            break
        u, alpha = search.state, search.alpha
        if damping:
            stepped = iterating & ~first
            factor = np.where(stepped, next_damping(factor, alpha), factor)
        if search.current:
            # The line search's residual at u; the tangent only where another iteration
            # (or the elimination) needs it, not at the converged state.
            assembly = search.assembly
        else:
            with timer.phase("assembly"):
                assembly = assembler.assemble(u)
        residual = arrays.view(assembly.residual)
        moves = _moves(problems, alpha, free_du, u, u_start)
        free_norms, reaction_norms, limits, *moved = norms(residual, *moves)
        relax = iterating & (free_norms > limits) if nonlinear_elimination_on else None
        if relax is not None and relax.any():
            u, assembly, steps = _relax(
                assembler, problems, assembly, u, free, limits, relax, timer
            )
            local += steps
            residual = arrays.view(assembly.residual)
            if steps.any():
                moves = _moves(problems, alpha, free_du, u, u_start)
                free_norms, reaction_norms, limits, *moved = norms(residual, *moves)
        at_roundoff = _at_roundoff(*moved, free_norms, reaction_norms)
        done = iterating & ((free_norms <= limits) | at_roundoff)
        converged |= done
        for k in np.flatnonzero(done):
            reasons[k] = "converged"
        broken = iterating & ~done & ~np.isfinite(free_norms)
        for k in np.flatnonzero(broken):
            reasons[k] = "the residual became non-finite"
        iterating &= ~done & ~broken
        if not iterating.any():
            break
        if assembly.matrix is None:  # the next iteration's tangent (its energies read later)
            with timer.phase("assembly"):
                assembly = assembler.assemble(u, read_scalars=False)
            residual = arrays.view(assembly.residual)
    for k in np.flatnonzero(iterating):
        reasons[k] = f"no convergence in {max_iterations} iterations"
    displacement = u if converged.all() else problems.where(converged, u, u_start)
    return Increment(
        converged=converged,
        displacement=displacement,
        iterations=iterations,
        linear_iterations=linear,
        local_iterations=local,
        reasons=reasons,
        from_guess=~linearized,
        residual=residual if converged.any() else None,
        last_iterate=u,
    )


class _ResidualNorms:
    """Each problem's free residual norm, reaction norm and convergence limit
    ``max(tolerance * reaction norm, floor)``, N, of a residual (N, 3)."""

    def __init__(
        self, problems: Problems, free: Any, fixed: Any, tolerance: float, floors: np.ndarray
    ) -> None:
        self.problems, self.free, self.fixed = problems, free, fixed
        self.tolerance, self.floors = tolerance, floors

    def __call__(self, residual: Any, *also: Any) -> list[np.ndarray]:
        """(free norms, reaction norms, limits, then the values of the reductions ``also``
        read in the same copy), each (K,)."""
        problems = self.problems
        free_squared, reaction_squared, *values = problems.read(
            problems.squared(residual * self.free), problems.squared(residual * self.fixed), *also
        )
        free_norms, reaction_norms = np.sqrt(free_squared), np.sqrt(reaction_squared)
        limits = np.maximum(self.tolerance * reaction_norms, self.floors)
        return [free_norms, reaction_norms, limits, *values]


def _newton_rhs(
    problems: Problems,
    matrix: Any,
    residual: Any,
    free: Any,
    prescribed_increment: Any,
    first: np.ndarray,
    on: Any,
    *,
    scratch: tuple[wp.array, wp.array],
) -> Any:
    """The Newton system's right-hand side (N, 3): ``-r`` on the free dofs; for the problems
    taking their ``first`` (linearized) step ``-(r + K du_p)`` there and the prescribed
    increment ``du_p`` on the prescribed dofs; zero on the nodes of problems not iterating
    (``on``, None where all iterate). ``scratch``: ``du_p`` and a buffer for ``K du_p``."""
    arrays = problems.arrays
    rhs = -residual * free
    if first.any():
        increment_wp, k_times_increment = scratch
        wps.bsr_mv(matrix, increment_wp, k_times_increment, alpha=1.0, beta=0.0)
        rhs_first = -(residual + arrays.view(k_times_increment)) * free + prescribed_increment
        rhs = problems.where(first, rhs_first, rhs)
    return rhs if on is None else rhs * on


def _moves(problems: Problems, alpha: np.ndarray, free_du: Any, u: Any, u_start: Any) -> list:
    """The reductions of :func:`_at_roundoff`: each problem's squared last correction
    ``alpha du`` and squared displacement over the increment, to :meth:`Problems.read`."""
    return [
        problems.squared(problems.per_node(alpha) * free_du),
        problems.squared(u - u_start),
    ]


def _at_roundoff(
    step_squared: np.ndarray,
    moved_squared: np.ndarray,
    free_norms: np.ndarray,
    reaction_norms: np.ndarray,
) -> np.ndarray:
    """The problems whose last correction ``alpha du`` is at roundoff (1e-10) relative to
    the increment's displacement (the values of :func:`_moves`, (K,)) and whose residual is
    small anyway (1e-6 of the reaction): the residual sits at its roundoff floor (large bulk
    moduli raise it), (K,) bool."""
    return (np.sqrt(step_squared) <= 1e-10 * np.sqrt(moved_squared)) & (
        free_norms <= 1e-6 * reaction_norms
    )


CONTACT_PENALTY_RAMP = 0.1
"""Under rigid contact (a sphere, a wedge or a rounded punch; not a plate, whose contact
covers the whole surface) each load increment is first solved with the penalty stiffness
times this factor (to :data:`CONTACT_RAMP_TOLERANCE`), then with the full stiffness from there
(:func:`penalty_ramped_increment`); 1 solves with the full stiffness at once."""
CONTACT_RAMP_TOLERANCE = 1.0e-3
"""Relative tolerance of the softened first stage of a contact increment."""


def penalty_ramped_increment(
    assembler: Assembler,
    solver: LinearSolver,
    problems: Problems,
    u_start: Any,
    prescribed_increment: Any,
    free: Any,
    constrained: Any,
    *,
    tolerance: float,
    **options: Any,
) -> Increment:
    """One load increment under rigid contact: a softened penalty first, then the full one.

    The increment is solved by :func:`newton_increment` with every problem's contact penalty
    stiffness k times :data:`CONTACT_PENALTY_RAMP` to the loose :data:`CONTACT_RAMP_TOLERANCE`,
    then with k from that state (no prescribed increment left) to ``tolerance``. Of K
    problems, the stiff stage takes those that converged in the soft one (a problem that
    failed it has failed the increment and keeps its start state), each from its own soft
    state; problems without a rigid contact (a sharp flat punch, in a batch with contact
    problems) take both stages as well. The converged state is that of k alone, as the
    stiff stage's convergence test decides; the iterations of both stages are counted.

    Notes:
        With ``k = beta mu0 h`` and beta = 1000, a node that a Newton step carries into the
        indenter meets a wall a thousand times stiffer than the tissue: the line search cuts
        the step where the first such node enters and the damping keeps the next steps
        short, so each ring of nodes that the contact edge passes costs iterations (a rounded
        punch on a 3 360-tet block: 10, 22, 61 at depths 0.02, 0.05, 0.1 a). With k / 10 the
        nodes enter gently; from the converged soft state the full penalty only moves the
        contact nodes by their penetration (a tenth of the soft one), which takes about three
        iterations. Measured in docs/design-notes/contact-newton.md. This is a continuation
        in the penalty parameter (Wriggers, Computational Contact Mechanics, 2006, ch. 6:
        a penalty increased during the solution).
    """
    contacts = [each for each in assembler.contacts if each is not None]
    stiffnesses = [each.stiffness_N_per_m for each in contacts]
    for each, stiffness in zip(contacts, stiffnesses, strict=True):
        each.stiffness_N_per_m = stiffness * CONTACT_PENALTY_RAMP
    try:
        soft = newton_increment(
            assembler,
            solver,
            problems,
            u_start,
            prescribed_increment,
            free,
            constrained,
            tolerance=max(tolerance, CONTACT_RAMP_TOLERANCE),
            **options,
        )
    finally:
        for each, stiffness in zip(contacts, stiffnesses, strict=True):
            each.stiffness_N_per_m = stiffness
    if not soft.converged.any():
        return soft
    stiff = newton_increment(
        assembler,
        solver,
        problems,
        soft.displacement,
        0.0 * soft.displacement,
        free,
        constrained,
        tolerance=tolerance,
        **(options | {"active": soft.converged, "free_guess": None, "guessed": None}),
    )
    stiff.iterations += soft.iterations
    stiff.linear_iterations += soft.linear_iterations
    stiff.local_iterations += soft.local_iterations
    stiff.from_guess = soft.from_guess
    stiff.reasons = [
        mine if tried else theirs
        for mine, theirs, tried in zip(stiff.reasons, soft.reasons, soft.converged, strict=True)
    ]
    # A problem that failed either stage keeps its start state (not its soft state).
    stiff.displacement = problems.where(stiff.converged, stiff.displacement, u_start)
    stiff.last_iterate = problems.where(soft.converged, stiff.last_iterate, soft.last_iterate)
    return stiff


def _start(
    assembler: Assembler,
    problems: Problems,
    u_start: Any,
    prescribed_increment: Any,
    free: Any,
    free_guess: Any,
    guessed: np.ndarray,
    timer: PhaseTimer,
) -> tuple[Any, Any, np.ndarray]:
    """Where an increment's iterations start: each ``guessed`` problem at its extrapolated
    state where that inverts none of its elements, the others at ``u_start`` (the
    linearized predictor follows in the first iteration).

    Returns:
        (the start state, its assembly with tangent, which problems start linearized (K,)).
    """
    u = u_start.copy()
    if free_guess is None:
        with timer.phase("assembly"):
            return u, assembler.assemble(u), np.ones(problems.count, dtype=bool)
    guess = u_start + prescribed_increment + free_guess * free
    with timer.phase("assembly"):
        assembly = assembler.assemble(guess)
    ok = (
        guessed
        & (np.asarray(assembly.problem_min_jacobians) > 0.0)
        & np.isfinite(assembly.problem_energies_J)
    )
    if ok.any():
        u = problems.where(ok, guess, u)
    if not ok.all():
        with timer.phase("assembly"):
            assembly = assembler.assemble(u)
    return u, assembly, ~ok


def _relax(
    assembler: Assembler,
    problems: Problems,
    assembly: Any,
    u: Any,
    free: Any,
    limits: np.ndarray,
    relax: np.ndarray,
    timer: PhaseTimer,
) -> tuple[Any, Any, np.ndarray]:
    """The nonlinear elimination of each problem ``relax`` (K,) on its own patch, from
    ``u`` and its assembly (the tangent assembled first where it is not).

    Returns:
        (the state, its assembly, each problem's local iterations (K,)).
    """
    if assembly.matrix is None:
        with timer.phase("assembly"):
            assembly = assembler.assemble(u)
    steps = np.zeros(problems.count, dtype=np.int64)
    with timer.phase("elimination"):
        for k in np.flatnonzero(relax):
            u, assembly, steps[k] = nonlinear_elimination(
                assembler,
                assembly,
                u,
                free,
                float(limits[k]),
                problem=int(k),
                nodes=problems.nodes(int(k)),
                arrays=problems.arrays,
            )
    return u, assembly, steps
