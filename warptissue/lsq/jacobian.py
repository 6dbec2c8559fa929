"""The least-squares engine's Jacobians (:mod:`warptissue.lsq.engine`): the residual
function counted and its refusals turned into None, the user's Jacobian or forward
differences toward the inside of the bounds, and the covariance of the fitted parameters.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from warptissue.errors import ConvergenceError, InputError
from warptissue.lsq.result import RejectStep

__all__ = ["Evaluator", "Jacobians", "covariance_from_jacobian", "finite_difference_jacobian"]

_EPS = float(np.finfo(np.float64).eps)


class Evaluator:
    """Counts residual evaluations and turns refusals into None."""

    def __init__(self, fun: Callable[[np.ndarray], Any], residual_count: int | None) -> None:
        self.fun = fun
        self.residual_count = residual_count
        self.nfev = 0

    def __call__(self, x: np.ndarray) -> np.ndarray | None:
        self.nfev += 1
        try:
            value = self.fun(x.copy())
        except RejectStep:
            return None
        residuals = np.asarray(value, dtype=np.float64)
        if residuals.ndim != 1 or residuals.size == 0:
            raise InputError(
                "the residual function must return a non-empty 1-D array",
                value=residuals.shape,
            )
        if self.residual_count is not None and residuals.size != self.residual_count:
            raise InputError(
                f"the residual function returned {residuals.size} values, "
                f"expected {self.residual_count}"
            )
        if not np.all(np.isfinite(residuals)):
            return None
        return residuals


def finite_difference_jacobian(
    evaluate: Evaluator,
    x: np.ndarray,
    residuals: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    typical: np.ndarray,
) -> np.ndarray:
    """Forward differences of the residuals at ``x`` (m, n): step
    ``h_j = sqrt(eps) max(|x_j|, typical_j)`` toward the inside of the bounds, retried on the
    other side where the model refuses the point.

    Raises:
        ConvergenceError: The model refused both sides of a parameter, or a parameter has no
            room inside its bounds.
    """
    jacobian = np.empty((residuals.size, x.size))
    for j in range(x.size):
        h = math.sqrt(_EPS) * max(abs(x[j]), typical[j])
        room_up, room_down = upper[j] - x[j], x[j] - lower[j]
        first = h if room_up >= h or room_up >= room_down else -h
        candidates = [first, -first]
        for k, step in enumerate(candidates):
            room = room_up if step > 0 else room_down
            step = math.copysign(min(abs(step), room), step)
            if step == 0.0:
                continue
            probe = x.copy()
            probe[j] += step
            actual = probe[j] - x[j]
            value = evaluate(probe)
            if value is not None:
                jacobian[:, j] = (value - residuals) / actual
                break
            if k == len(candidates) - 1:
                raise ConvergenceError(
                    f"finite differences: the model refused both x{j} +/- {abs(step):.3g} "
                    f"around x = {x.tolist()}"
                )
        else:
            raise ConvergenceError(
                f"finite differences: no room inside the bounds for parameter {j}"
            )
    return jacobian


def covariance_from_jacobian(
    jacobian: np.ndarray, cost: float
) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """(J^T J)^-1 * SSR / (m - n), its standard errors and correlation, or Nones.

    Args:
        jacobian: d residuals / d x, shape (m, n).
        cost: 0.5 * sum(residuals**2).

    Returns:
        (covariance (n, n), standard errors (n,), correlation (n, n)); all None when
        m <= n or J is rank deficient (smallest singular value below m * eps of the
        largest); the correlation alone is None when a standard error is zero.
    """
    m, n = jacobian.shape
    if m <= n:
        return None, None, None
    _, singular, vt = np.linalg.svd(jacobian, full_matrices=False)
    if singular[0] == 0.0 or singular[-1] <= singular[0] * max(m, n) * _EPS:
        return None, None, None
    variance = 2.0 * cost / (m - n)
    covariance = (vt.T / singular**2) @ vt * variance
    errors = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    if np.all(errors > 0.0):
        correlation = covariance / np.outer(errors, errors)
        np.fill_diagonal(correlation, 1.0)
    else:
        correlation = None
    return covariance, errors, correlation


class Jacobians:
    """The Jacobian at a point (``jac``, or finite differences), counting evaluations."""

    def __init__(
        self,
        jac: Callable[[np.ndarray], np.ndarray] | None,
        evaluate: Evaluator,
        *,
        lower: np.ndarray,
        upper: np.ndarray,
        scale_vector: np.ndarray | None,
    ) -> None:
        self.jac = jac
        self.evaluate = evaluate
        self.lower, self.upper = lower, upper
        self.typical = np.ones(lower.size) if scale_vector is None else scale_vector
        self.njev = 0

    def __call__(self, point: np.ndarray, point_residuals: np.ndarray) -> np.ndarray:
        self.njev += 1
        n = point.size
        if self.jac is None:
            return finite_difference_jacobian(
                self.evaluate, point, point_residuals, self.lower, self.upper, self.typical
            )
        try:
            matrix = np.asarray(self.jac(point.copy()), dtype=np.float64)
        except RejectStep as exc:
            raise ConvergenceError(f"the Jacobian was refused at x = {point.tolist()}") from exc
        if matrix.shape != (point_residuals.size, n):
            raise InputError(
                f"jac must return shape ({point_residuals.size}, {n})", value=matrix.shape
            )
        if not np.all(np.isfinite(matrix)):
            raise ConvergenceError(f"the Jacobian is not finite at x = {point.tolist()}")
        return matrix
