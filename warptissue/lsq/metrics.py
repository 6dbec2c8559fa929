"""Goodness-of-fit measures shared by every fit."""

from __future__ import annotations

import numpy as np

from warptissue.errors import InputError

__all__ = [
    "DURBIN_WATSON_LIMIT",
    "MIN_WINDOW_SAMPLES",
    "durbin_watson",
    "r_squared",
    "rmse",
    "windowed_durbin_watson",
]

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


MIN_WINDOW_SAMPLES = 20
"""The fewest residuals a window of :func:`windowed_durbin_watson` holds (a shorter window is
merged into the next): the statistic of 20 independent residuals falls below
:data:`DURBIN_WATSON_LIMIT` with a chance of about 1e-3."""


def windowed_durbin_watson(
    time_s: np.ndarray, residuals: np.ndarray, *, first_end_s: float
) -> list[tuple[float, float, int, float | None]]:
    """The Durbin-Watson statistic of the residuals in windows of the record that double in
    length: the first from the first sample to ``first_end_s`` (the loading, e.g. the time
    of the peak force), each next one twice as long as the one before.

    A relaxation is structured in log time: a model that misses the fast relaxation leaves
    systematic residuals in the first second of a hold, and a long, well fitted tail dilutes
    them in the statistic of the whole record (a Prony series of two terms fitted to a QLV
    record: 0.03 in the loading window, 0.6 to 1.2 over the whole record). Windows that
    double in length keep a misfit of any time scale in a window of its own size.

    Args:
        time_s: Sample times (s), increasing, shape (m,).
        residuals: Residuals in the same order, shape (m,).
        first_end_s: End of the first window (s); one before the first sample or not past
            it gives a first window of :data:`MIN_WINDOW_SAMPLES` samples.

    Returns:
        Per window: start and end time (s, of its first and last sample), its number of
        samples and its statistic (:func:`durbin_watson`; None for a perfect fit there).
    """
    time = np.asarray(time_s, dtype=np.float64).reshape(-1)
    residuals = np.asarray(residuals, dtype=np.float64).reshape(-1)
    if time.shape != residuals.shape:
        raise InputError("times and residuals differ in length", value=(time.size, residuals.size))
    if time.size == 0:
        return []
    first = int(np.searchsorted(time, first_end_s, side="right"))
    first = min(max(first, MIN_WINDOW_SAMPLES), time.size)
    length = max(float(time[first - 1] - time[0]), float(np.min(np.diff(time), initial=1.0)))
    cuts, end = [0, first], float(time[first - 1])
    while cuts[-1] < time.size:
        length *= 2.0
        end += length
        cut = int(np.searchsorted(time, end, side="right"))
        if cut - cuts[-1] >= MIN_WINDOW_SAMPLES or cut == time.size:
            cuts.append(max(cut, cuts[-1] + 1))
    if len(cuts) > 2 and cuts[-1] - cuts[-2] < MIN_WINDOW_SAMPLES:
        del cuts[-2]  # a short tail joins the window before it
    return [
        (float(time[a]), float(time[b - 1]), b - a, durbin_watson(residuals[a:b]))
        for a, b in zip(cuts[:-1], cuts[1:], strict=True)
    ]
