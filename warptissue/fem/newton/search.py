"""The step length along each problem's Newton direction, all problems' trials assembled
together.

A load increment's first iteration (the prescribed increment applied whole) starts from a
state that is no reference for a descent test: its free step is only halved while an element
inverts. Every later iteration runs a line search on the energy and its directional
derivative. For K problems solved together each evaluation assembles every problem's trial
in one launch; each problem keeps its own bracket, accepts on its own test and, once
accepted, is evaluated at its accepted step while the others go on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warptissue.fem.assembly import Assembler, Assembly
from warptissue.fem.newton.problems import Problems

__all__ = ["FIRST_STEP_HALVINGS", "LINE_SEARCH_EVALUATIONS", "StepSearch", "search_steps"]

LINE_SEARCH_EVALUATIONS = 10
"""Residual assemblies of one line search."""
FIRST_STEP_HALVINGS = 8
"""Assemblies of a first iteration's step, halved each time an element inverts."""
CURVATURE = 0.5
"""The strong-Wolfe factor on ``|g|``."""
ARMIJO = 1.0e-4
"""The sufficient-decrease factor of the energy."""
INVERTED = "an element inverted (J <= 0)"
NO_DECREASE = "the line search found no decrease"


@dataclass
class StepSearch:
    """Outcome of one step search over K problems.

    Attributes:
        alpha: Each problem's accepted step length, (K,) (0 where none).
        found: Whether a step was found, (K,) (False for problems not searching).
        state: The new displacement (N, 3): each found problem's start plus its step, the
            others as they were.
        assembly: The last residual assembly (no tangent), or None.
        current: ``assembly`` is the assembly of ``state`` for every found problem, so its
            residual needs no new assembly.
        reasons: Why each problem that searched found no step ("" elsewhere).
    """

    alpha: np.ndarray
    found: np.ndarray
    state: Any
    assembly: Assembly | None
    current: bool
    reasons: list[str] = field(default_factory=list)


def search_steps(
    assembler: Assembler,
    problems: Problems,
    u: Any,
    direction: Any,
    free: Any,
    *,
    searching: np.ndarray,
    first: np.ndarray,
    prescribed_increment: Any,
    energies_J: np.ndarray,
    slopes: np.ndarray,
    residual_norms: np.ndarray,
) -> StepSearch:
    """Step lengths along Newton directions of the free dofs, one per problem.

    A ``first`` problem starts from ``u`` plus its prescribed increment and takes the whole
    step unless an element inverts, halving it up to :data:`FIRST_STEP_HALVINGS` times.
    Every other problem takes the full step when it decreases the energy (Armijo) or the
    free residual and the directional derivative of the energy has dropped to
    :data:`CURVATURE` times its start value (or is still negative). Otherwise a safeguarded
    secant search on that derivative, ``g(alpha) = r(u + alpha d) . d`` (free dofs),
    brackets the energy minimum along the direction; states with an inverted element shrink
    the bracket. Where no trial passes both tests within :data:`LINE_SEARCH_EVALUATIONS`,
    the one of lowest energy that passed the decrease test is taken. A residual-only
    assembly is far cheaper than the factorization of a Newton iteration, so a few of them
    that save an iteration pay for themselves.

    Args:
        assembler: The discretized body (all K problems).
        problems: The problems' node ranges and reductions.
        u: Current displacement (N, 3), m, an array of the loop's library.
        direction: Newton direction, zero on prescribed and frozen dofs (N, 3), m.
        free: 1 on free dofs, 0 on prescribed ones (N, 3).
        searching: The problems that take a step, (K,); the others stay at ``u``.
        first: The searching problems at their increment's first iteration, (K,).
        prescribed_increment: The increment of the prescribed dofs (N, 3), m (used by
            ``first`` problems).
        energies_J: Each problem's energy at ``u``, (K,), J.
        slopes: ``g(0)`` per problem, (K,), J.
        residual_norms: Each problem's free residual norm at ``u``, (K,), N.

    Returns:
        A :class:`StepSearch`.
    """
    count = problems.count
    line = searching & ~first
    if first.any():
        base = u + prescribed_increment * problems.per_node(first.astype(np.float64))
    else:
        base = u
    limits = np.where(first, FIRST_STEP_HALVINGS, LINE_SEARCH_EVALUATIONS)
    evaluations = np.zeros(count, dtype=np.int64)
    low, g_low = np.zeros(count), np.asarray(slopes, dtype=np.float64).copy()
    high, g_high = np.full(count, math.inf), np.full(count, math.nan)
    alpha = np.ones(count)
    accepted = np.where(searching, math.nan, 0.0)
    best, best_energy = np.full(count, math.nan), np.full(count, math.inf)
    inverted = first.copy()
    check: Assembly | None = None
    trial = None
    while True:
        pending = searching & np.isnan(accepted) & (evaluations < limits)
        if not pending.any():
            break
        evaluations[pending] += 1
        trial_alpha = np.where(pending, alpha, np.nan_to_num(accepted))
        trial = base + problems.per_node(trial_alpha) * direction
        check = assembler.assemble(trial, with_tangent=False, read_scalars=False)
        scalars = problems.arrays.view(check.scalars)
        searched = pending & line
        if searched.any():  # the energies with the slopes, in one read
            free_residual = problems.arrays.view(check.residual) * free
            g, squared, values = problems.read(
                problems.dot(free_residual, direction),
                problems.squared(free_residual),
                scalars=scalars,
            )
        else:
            g, squared = np.full(count, math.nan), np.full(count, math.nan)
            (values,) = problems.read(scalars=scalars)
        check = check.with_scalars(values)
        energy = np.asarray(check.problem_energies_J, dtype=np.float64)
        ok = (np.asarray(check.problem_min_jacobians) > 0.0) & np.isfinite(energy)
        accept = pending & first & ok
        with np.errstate(invalid="ignore"):
            decrease = ok & (
                (energy <= energies_J + ARMIJO * alpha * slopes)
                | (np.sqrt(squared) < residual_norms)
            )
            good = decrease & (
                (np.abs(g) <= CURVATURE * np.abs(slopes)) | ((g < 0.0) & (alpha >= 1.0))
            )
        accept |= searched & good
        accepted[accept] = alpha[accept]
        move = searched & ~good
        better = move & decrease & (energy < best_energy)
        best[better], best_energy[better] = alpha[better], energy[better]
        lower = move & decrease & (g < 0.0)
        upper = move & ok & ~lower
        broken = move & ~ok
        inverted |= broken
        low[lower], g_low[lower] = alpha[lower], g[lower]
        high[upper], g_high[upper] = alpha[upper], g[upper]
        high[broken], g_high[broken] = alpha[broken], math.nan
        halve = (move & (slopes >= 0.0)) | (pending & first & ~ok)
        alpha = _next_alpha(alpha, (low, g_low), (high, g_high), move=move, halve=halve)
    took_best = searching & line & np.isnan(accepted) & np.isfinite(best)
    accepted[took_best] = best[took_best]
    found = searching & np.isfinite(accepted)
    steps = np.where(found, accepted, 0.0)
    reasons = [""] * count
    for k in np.flatnonzero(searching & ~found):
        reasons[k] = INVERTED if inverted[k] else NO_DECREASE
    current = check is not None and found.any() and not took_best.any()
    if current and found.all() or (current and count == 1):
        state = trial  # the last trial: every problem at its accepted step
    else:
        state = problems.where(found, base + problems.per_node(steps) * direction, u)
    return StepSearch(steps, found, state, check, bool(current), reasons)


def _next_alpha(
    alpha: np.ndarray,
    lower: tuple[np.ndarray, np.ndarray],
    upper: tuple[np.ndarray, np.ndarray],
    *,
    move: np.ndarray,
    halve: np.ndarray,
) -> np.ndarray:
    """The next trial step of each problem that moves (K,): half of it where ``halve``; else
    the secant of the slopes at the bracket's ends ``lower`` and ``upper`` (each (alpha,
    g)), kept a tenth of the bracket inside it, where the upper slope is known and larger;
    else the bracket's middle."""
    low, g_low = lower
    high, g_high = upper
    width = high - low
    with np.errstate(invalid="ignore", divide="ignore"):
        secant = low - g_low * width / (g_high - g_low)
        secant = np.minimum(np.maximum(secant, low + 0.1 * width), high - 0.1 * width)
    use_secant = move & ~halve & np.isfinite(g_high) & (g_high > g_low)
    bisect = move & ~halve & ~use_secant
    alpha = np.where(halve, 0.5 * alpha, alpha)
    alpha = np.where(use_secant, secant, alpha)
    return np.where(bisect, low + 0.5 * width, alpha)
