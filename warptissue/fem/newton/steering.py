"""What steers Newton's path without changing where it ends: Levenberg-Marquardt damping of
the tangent, the decision to solve with old factors, and the accuracy asked of such a solve.

Each is kept per problem ((K,) arrays) for K problems solved together
(:mod:`warptissue.fem.newton.problems`); the convergence test is never touched, so the
converged states are those of the plain Newton method.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from warptissue.fem.newton.problems import Problems

__all__ = [
    "DAMPING_CUT",
    "DAMPING_START",
    "FORCING_MAX",
    "FORCING_MIN",
    "REUSE_STATE_CHANGE",
    "ReuseTracker",
    "forcing_term",
    "next_damping",
]

DAMPING_START = 1.0
"""Levenberg-Marquardt factor lambda set when the line search first cuts a step below
:data:`DAMPING_CUT` (each free diagonal entry K_ii of the tangent becomes K_ii + lambda |K_ii|);
multiplied by 4 at each further cut, divided by 4 after each full step and dropped to 0 below
``DAMPING_START / 8``."""
DAMPING_CUT = 0.25


def next_damping(factor: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Each problem's damping factor for its next Newton iteration, after steps ``alpha``.

    Args:
        factor: The factors of the iteration just taken, (K,).
        alpha: The step lengths the line search accepted, (K,).

    Returns:
        The next factors, (K,).

    Notes:
        Levenberg (1944), Marquardt (1963), with Marquardt's scaling by the diagonal; the
        update follows the line search instead of a trust-region ratio. At a finely meshed
        punch edge a large load increment leaves the tangent of the predictor state a poor
        model: undamped, the line search cut many Newton steps there to 0.002-0.05 of their
        length. Damped, the steps shorten and turn toward the scaled steepest descent, and
        are taken whole; with the factor dropped again after full steps, the quadratic
        convergence near the solution is kept. The converged state is the same.
    """
    factor = np.asarray(factor, dtype=np.float64)
    alpha = np.asarray(alpha, dtype=np.float64)
    cut = np.maximum(4.0 * factor, DAMPING_START)
    relaxed = np.where(factor > DAMPING_START / 8.0, factor / 4.0, 0.0)
    return np.where(alpha < DAMPING_CUT, cut, np.where(alpha >= 1.0, relaxed, factor))


REUSE_STATE_CHANGE = 0.5
"""A Newton solve tries the last factorization only where every problem's state has moved less
than this fraction of its last load increment's first Newton step since the factorized
tangent was assembled (:class:`ReuseTracker`)."""


@dataclass
class ReuseTracker:
    """Where the factorized tangent was assembled, for
    :meth:`warptissue.fem.LinearSolver.solve_newton`.

    Measured on the flat-punch benchmark (2 471 tets, 3 Newton iterations per load step):
    the first iteration of a step (its tangent at the last converged state, the factors of
    the step before's second iteration) and the third (a small correction since the second)
    were solved by GMRES in 2-4 iterations, while the second, after the first iteration's
    long step, failed in every step. So a solve tries the old factors only where each
    iterating problem's state has moved by less than :data:`REUSE_STATE_CHANGE` times its
    last first-iteration step (``step_scale``) since the factorization, with the same
    damping; the time budget of ``solve_newton`` still decides the rest. K problems share
    one factorization, so the decision is one for all of them.

    Attributes:
        state: The displacement (N, 3) whose tangent was factorized last (an array of the
            Newton loop's :class:`warptissue.fem.arrays.DeviceArrays`), or None.
        damping: Each problem's Levenberg-Marquardt factor of that factorization, (K,).
        step_scale: Each problem's norm of the free part of its last first Newton step of an
            increment, (K,), m (infinite until each has taken one).
    """

    state: Any = None
    damping: np.ndarray | None = None
    step_scale: np.ndarray | None = None

    def promising(
        self, u: Any, damping: np.ndarray, problems: Problems, iterating: np.ndarray, *also: Any
    ) -> tuple[bool, list[np.ndarray]]:
        """Whether a solve at ``u`` with ``damping`` (K,) should try the old factors: for
        every ``iterating`` problem the damping is that of the factorization and the state
        is close to it.

        ``also``: reductions of :class:`Problems` that the caller needs only where the old
        factors are tried, read in the same copy as the state's change.

        Returns:
            (whether to try, the values of ``also`` where read, else an empty list).
        """
        if self.state is None or self.damping is None:
            return False, []
        if np.any(damping[iterating] != self.damping[iterating]):
            return False, []
        moved, *values = problems.read(problems.squared(u - self.state), *also)
        scale = np.full(problems.count, math.inf) if self.step_scale is None else self.step_scale
        close = np.sqrt(moved) <= REUSE_STATE_CHANGE * scale
        return bool(np.all(close[iterating])), values

    def factorized(self, u: Any, damping: np.ndarray) -> None:
        """The tangent at ``u`` with ``damping`` (K,) was just factorized."""
        self.state, self.damping = u, np.array(damping, dtype=np.float64)

    def first_step(self, first: np.ndarray, free_step_norms: np.ndarray) -> None:
        """The problems ``first`` (K,) took the first step of an increment, of free norms
        ``free_step_norms`` (K,), m."""
        if self.step_scale is None:
            self.step_scale = np.full(len(first), math.inf)
        self.step_scale[first] = free_step_norms[first]


FORCING_MAX = 1.0e-3
"""Loosest relative residual of a Newton step solved by GMRES with old factors."""
FORCING_MIN = 1.0e-10
"""Tightest relative residual asked of such a solve (a direct solve's roundoff)."""


def forcing_term(limits: np.ndarray, rhs_norms: np.ndarray, iterating: np.ndarray) -> float:
    """Relative residual of a Newton step solved with old factors (GMRES), for all problems.

    Per problem, a tenth of its convergence limit on the free residual, relative to its
    right-hand side, within [:data:`FORCING_MIN`, :data:`FORCING_MAX`]: far from the
    solution the step needs only to point the right way, near it the linear residual must
    not keep the nonlinear one above the limit (Eisenstat and Walker 1996, SIAM J. Sci.
    Comput. 17, "choosing the forcing terms"; here tied to the final tolerance rather than
    to the last residual reduction). K problems share one GMRES solve, whose residual is
    measured over all of them: it is asked for the smallest absolute residual any iterating
    problem needs, relative to the whole right-hand side.

    Args:
        limits: Each problem's convergence limit on its free residual norm, (K,), N.
        rhs_norms: Each problem's right-hand side norm, (K,), N.
        iterating: The problems still iterating, (K,).

    Returns:
        The relative residual of the shared solve.
    """
    terms = np.full(len(limits), FORCING_MAX)
    usable = iterating & np.isfinite(rhs_norms) & (rhs_norms > 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        terms[usable] = np.minimum(
            FORCING_MAX, np.maximum(0.1 * limits[usable] / rhs_norms[usable], FORCING_MIN)
        )
    if len(limits) == 1:
        return float(terms[0])
    if not usable.any():
        return FORCING_MAX
    total = math.sqrt(float(np.sum(rhs_norms[usable] ** 2)))
    needed = float(np.min(terms[usable] * rhs_norms[usable]))
    return min(FORCING_MAX, max(needed / total, FORCING_MIN))
