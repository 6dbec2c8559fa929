"""The steps of conditioning a record, each usable alone: the contact point
(:func:`detect_contact`, :class:`ContactPoint`), the force's offset and drift
(:func:`remove_offset_and_drift`), the loading ramp to a depth (:func:`trim_ramp`) and a
breath-hold window (:func:`select_window`). :func:`warptissue.acquisition.conditioning.
prepare_record` runs them in order, with the physiological filters of
:mod:`warptissue.acquisition.physiological`; the module docstring there says how.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from warptissue.acquisition.physiological import check_samples, periodic_basis
from warptissue.errors import InputError

__all__ = [
    "ContactPoint",
    "detect_contact",
    "remove_offset_and_drift",
    "select_window",
    "trim_ramp",
]


@dataclass(frozen=True)
class ContactPoint:
    """Where the probe met the specimen.

    Attributes:
        index: First sample at or after contact.
        time_s: Contact time (s), interpolated.
        position_m: Axis position at contact (m), extrapolated from the early loading.
        baseline_force_N: Mean force before contact (N).
        noise_N: Standard deviation of the baseline force (N).
        threshold_N: Force rise that marked the contact (N).
    """

    index: int
    time_s: float
    position_m: float
    baseline_force_N: float
    noise_N: float
    threshold_N: float


def detect_contact(
    time_s: np.ndarray,
    position_m: np.ndarray,
    force_N: np.ndarray,
    *,
    baseline_s: float | None = None,
    threshold_sigma: float = 6.0,
    min_threshold_N: float = 0.0,
    fit_multiple: float = 8.0,
) -> ContactPoint:
    """Find the contact point of an indentation.

    Args:
        time_s: Sample times (s), shape (n,).
        position_m: Axis position (m, increasing into the specimen), shape (n,).
        force_N: Force (N), shape (n,).
        baseline_s: Length of the pre-contact baseline (s); default: the samples before the
            probe starts moving (position within 1 um of its first value), at least 10.
        threshold_sigma: Contact is where the force exceeds the baseline by this many noise
            standard deviations (the noise from the baseline's sample-to-sample differences).
        min_threshold_N: Lower bound of the threshold (N), e.g. the transducer resolution.
        fit_multiple: The early loading used for the extrapolation runs from a rise of 2
            thresholds to a rise of ``fit_multiple`` thresholds.

    Raises:
        InputError: The force never leaves the baseline, or the baseline is too short.
    """
    check_samples(time_s, position_m, force_N)
    t, x, f = (np.asarray(a, dtype=np.float64) for a in (time_s, position_m, force_N))
    if baseline_s is None:
        moving = np.flatnonzero(np.abs(x - x[0]) > 1e-6)
        stop = int(moving[0]) if moving.size else len(t)
    else:
        stop = int(np.searchsorted(t, t[0] + baseline_s))
    if stop < 10:
        raise InputError("the pre-contact baseline has fewer than 10 samples", value=stop)
    baseline = f[:stop]
    level = float(np.mean(baseline))
    noise = float(np.std(np.diff(baseline)) / math.sqrt(2.0))
    threshold = max(threshold_sigma * noise, min_threshold_N)
    above = np.flatnonzero((f - level > threshold) & (np.arange(len(f)) >= stop))
    if not above.size:
        if np.any(level - f[stop:] > threshold):
            raise InputError(
                "no contact: the force falls below the pre-contact baseline instead of rising; "
                "give the compressive force as positive",
                column="force_N",
                value=float(np.min(f[stop:]) - level),
            )
        raise InputError("no contact: the force never leaves the baseline", value=threshold)
    crossing = int(above[0])
    # Early loading: from the crossing until the rise reaches fit_multiple thresholds, less
    # the first samples (picked because their noise pushed them over the threshold).
    rise = f[crossing:] - level
    high = np.flatnonzero(rise > fit_multiple * threshold)
    end = crossing + (int(high[0]) if high.size else min(20, len(f) - crossing - 1))
    clear = np.flatnonzero(rise > 2.0 * threshold)
    begin = crossing + (int(clear[0]) if clear.size else 0)
    begin = min(begin, max(end - 3, crossing))
    end = max(end, begin + 3)
    slope, intercept = np.polyfit(x[begin : end + 1], f[begin : end + 1] - level, 1)
    if slope > 0:
        contact_position = float(-intercept / slope)
    else:
        contact_position = float(x[crossing])
    contact_position = min(max(contact_position, float(x[stop - 1])), float(x[crossing]))
    index = int(np.searchsorted(np.maximum.accumulate(x), contact_position))
    index = min(max(index, 0), crossing)
    if index > 0 and x[index] != x[index - 1]:
        share = (contact_position - x[index - 1]) / (x[index] - x[index - 1])
        contact_time = float(t[index - 1] + np.clip(share, 0.0, 1.0) * (t[index] - t[index - 1]))
    else:
        contact_time = float(t[index])
    return ContactPoint(
        index=index,
        time_s=contact_time,
        position_m=contact_position,
        baseline_force_N=level,
        noise_N=noise,
        threshold_N=threshold,
    )


def remove_offset_and_drift(
    time_s: np.ndarray,
    force_N: np.ndarray,
    *,
    unloaded: np.ndarray,
    periodic_rates_Hz: tuple[float, ...] = (),
    harmonics: int = 3,
) -> tuple[np.ndarray, float, float]:
    """Subtract the transducer baseline estimated where the probe carries no load.

    With unloaded samples on one side of the test only, the baseline is a constant (an
    offset); with unloaded samples before and after it (a probe retracted at the end), a
    straight line (offset and drift). Both are least-squares fits to the unloaded samples;
    with ``periodic_rates_Hz`` the fit also carries sines and cosines at those rates and
    their harmonics, so that a baseline spanning a fraction of a breath is not biased by it.

    Args:
        time_s: Sample times (s), shape (n,).
        force_N: Force (N), shape (n,).
        unloaded: Boolean mask (n,) of samples without load.
        periodic_rates_Hz: Physiological rates present in the baseline (Hz).
        harmonics: Harmonics per rate in the baseline fit.

    Returns:
        The corrected force (n,), the offset (N, baseline at ``time_s[0]``) and the drift
        (N/s, 0 when it cannot be told from relaxation).
    """
    check_samples(time_s, force_N, unloaded)
    t, f = np.asarray(time_s, dtype=np.float64), np.asarray(force_N, dtype=np.float64)
    mask = np.asarray(unloaded, dtype=bool)
    if mask.sum() < 2:
        raise InputError("need at least 2 unloaded samples", value=int(mask.sum()))
    indices = np.flatnonzero(mask)
    loaded = np.flatnonzero(~mask)
    two_sided = bool(loaded.size and indices[0] < loaded[0] and indices[-1] > loaded[-1])
    elapsed = t[mask] - t[0]
    columns = [np.ones_like(elapsed)] + ([elapsed] if two_sided else [])
    columns += periodic_basis(elapsed, tuple(periodic_rates_Hz), harmonics)
    basis = np.column_stack(columns)
    if basis.shape[0] <= basis.shape[1]:
        raise InputError("too few unloaded samples for the baseline fit", value=basis.shape[0])
    coefficients, *_ = np.linalg.lstsq(basis, f[mask], rcond=None)
    offset_at_zero = float(coefficients[0])
    drift = float(coefficients[1]) if two_sided else 0.0
    corrected = f - (offset_at_zero + drift * (t - t[0]))
    return corrected, float(offset_at_zero), float(drift)


def trim_ramp(
    position_m: np.ndarray, *, contact_position_m: float, keep_depth_m: float
) -> np.ndarray:
    """Mask of the loading ramp from contact to ``keep_depth_m`` below it.

    Takacs et al. keep the first 3.6 mm of a 4 mm ramp, dropping the end where the indenter
    decelerates (and overshoots); the start, where it accelerates, happens in air when the
    probe starts above the specimen.

    Args:
        position_m: Axis position (m), shape (n,).
        contact_position_m: Position of the contact point (m).
        keep_depth_m: Depth to keep (m).

    Returns:
        Boolean mask (n,): samples of the first, monotonic loading between contact and
        ``contact + keep_depth_m``.
    """
    x = np.asarray(position_m, dtype=np.float64)
    if not keep_depth_m > 0:
        raise InputError("keep_depth_m must be positive", value=keep_depth_m)
    depth = x - contact_position_m
    beyond = np.flatnonzero(depth > keep_depth_m)
    end = int(beyond[0]) if beyond.size else len(x)
    mask = np.zeros(len(x), dtype=bool)
    mask[:end] = depth[:end] >= 0.0
    return mask


def select_window(time_s: np.ndarray, *, start_s: float, stop_s: float) -> np.ndarray:
    """Mask of a breath-hold window ``start_s <= t <= stop_s`` (Kim et al. held the breath
    during each indentation)."""
    t = np.asarray(time_s, dtype=np.float64)
    if not stop_s > start_s:
        raise InputError("the window must end after it starts", value=(start_s, stop_s))
    return (t >= start_s) & (t <= stop_s)
