"""Goodness-of-fit measures shared by every fit."""

from __future__ import annotations

import numpy as np

from warptissue.errors import InputError

__all__ = ["DURBIN_WATSON_LIMIT", "durbin_watson", "r_squared", "rmse"]

DURBIN_WATSON_LIMIT = 0.5
"""Residuals in the order of the data whose Durbin-Watson statistic is below this are
systematic: the model misses the curve's shape (independent noise gives about 2)."""


def _paired(y: np.ndarray, y_fit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    measured = np.asarray(y, dtype=np.float64).reshape(-1)
    fitted = np.asarray(y_fit, dtype=np.float64).reshape(-1)
    if measured.shape != fitted.shape:
        raise InputError(
            "measured and fitted values differ in length",
            value=(measured.size, fitted.size),
        )
    if measured.size == 0:
        raise InputError("no values to compare")
    if not (np.all(np.isfinite(measured)) and np.all(np.isfinite(fitted))):
        raise InputError("measured and fitted values must be finite")
    return measured, fitted


def r_squared(y: np.ndarray, y_fit: np.ndarray) -> float:
    """Coefficient of determination, 1 - SS_res / SS_tot.

    Args:
        y: Measured values, shape (m,).
        y_fit: Fitted values, shape (m,).

    Returns:
        R² (1 for a perfect fit; negative when the fit is worse than the mean).

    Raises:
        InputError: Different lengths, no values, non-finite values, or constant ``y``
            (SS_tot = 0, where R² is undefined).
    """
    measured, fitted = _paired(y, y_fit)
    total = float(np.sum((measured - measured.mean()) ** 2))
    if total == 0.0:
        raise InputError("R^2 is undefined for constant data", value=float(measured[0]))
    return 1.0 - float(np.sum((measured - fitted) ** 2)) / total


def rmse(y: np.ndarray, y_fit: np.ndarray) -> float:
    """Root mean square error, sqrt(mean((y - y_fit)**2)), in the units of ``y``.

    Raises:
        InputError: Different lengths, no values or non-finite values.
    """
    measured, fitted = _paired(y, y_fit)
    return float(np.sqrt(np.mean((measured - fitted) ** 2)))


def durbin_watson(residuals: np.ndarray) -> float | None:
    """sum(diff(r)^2) / sum(r^2): about 2 for independent residuals, near 0 for a trend.

    Args:
        residuals: Residuals in the order of the data, shape (m,).

    Returns:
        The statistic, or None for fewer than 3 residuals or a perfect fit.
    """
    residuals = np.asarray(residuals, dtype=np.float64).reshape(-1)
    total = float(residuals @ residuals)
    if residuals.size < 3 or total == 0.0:
        return None
    return float(np.sum(np.diff(residuals) ** 2) / total)
