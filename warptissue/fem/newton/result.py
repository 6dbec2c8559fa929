"""What following a load path gives back: the converged states (:class:`QuasistaticResult`),
or, on Ctrl-C, the steps converged before it (:class:`SolveInterrupted`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warptissue.fem.timing import NewtonTimings


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
