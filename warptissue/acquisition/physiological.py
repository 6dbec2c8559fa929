"""Respiration and heartbeat in an in vivo record: their rates estimated from a stretch of
the force, and zero-phase notch filters at the rates and their harmonics, applied to the
displacement and the force alike (why that keeps a linear viscoelastic fit unbiased:
:mod:`warptissue.acquisition.conditioning`, step 4, which runs them).
"""

from __future__ import annotations

import numpy as np

from warptissue.errors import InputError

__all__ = ["check_samples", "estimate_rate_Hz", "periodic_basis", "suppress_physiological"]


def check_samples(time_s: np.ndarray, *arrays: np.ndarray) -> None:
    """Refuse fewer than 4 samples, columns of other lengths, a non-finite value and a time
    that does not strictly increase."""
    t = np.asarray(time_s)
    if t.ndim != 1 or t.size < 4:
        raise InputError("a record needs at least 4 samples", value=t.size)
    for array in arrays:
        if np.asarray(array).shape != t.shape:
            raise InputError("columns differ in length", value=(t.shape, np.shape(array)))
    for name, array in (("time_s", t), *((None, a) for a in arrays)):
        bad = np.flatnonzero(~np.isfinite(np.asarray(array, dtype=np.float64)))
        if bad.size:
            raise InputError(
                f"not a finite number at sample {int(bad[0])}",
                column=name,
                value=float(np.asarray(array)[bad[0]]),
            )
    if not np.all(np.diff(t) > 0):
        raise InputError("time_s must strictly increase")


def estimate_rate_Hz(
    time_s: np.ndarray,
    signal: np.ndarray,
    band_Hz: tuple[float, float],
    *,
    harmonics: int = 2,
    trend_order: int = 3,
) -> float:
    """Rate (Hz) of the strongest periodic component of ``signal`` within ``band_Hz``.

    Scans candidate rates (a coarse grid of half the record's frequency resolution across
    the band, then a grid 20 times finer around the best) and keeps the one whose sine and
    cosine at the rate and its first ``harmonics`` multiples, beside a polynomial trend of
    ``trend_order``, explain the most of the signal (linear least squares at each
    candidate). Use a stretch where the specimen's response is
    slow: the rest before the ramp, or the hold. :func:`prepare_record` uses the rest before
    the ramp when it lasts 8 s or more (two breaths), else the hold.
    """
    check_samples(time_s, signal)
    t = np.asarray(time_s, dtype=np.float64)
    y = np.asarray(signal, dtype=np.float64)
    low, high = band_Hz
    # Block-average to about 10 samples per period of the highest harmonic (speed only).
    block = max(1, int(1.0 / (10.0 * harmonics * high * float(np.median(np.diff(t))))))
    if block > 1:
        count = len(t) // block
        t = t[: count * block].reshape(count, block).mean(axis=1)
        y = y[: count * block].reshape(count, block).mean(axis=1)
    if not 0 < low < high:
        raise InputError("the band must be 0 < low < high", value=band_Hz)
    span = float(t[-1] - t[0])
    if span * high < 2.0:
        raise InputError("the stretch is shorter than two periods of the band", value=span)
    centred = (t - t[0]) / span - 0.5
    trend = np.vander(centred, trend_order + 1)
    base, *_ = np.linalg.lstsq(trend, y, rcond=None)
    base_energy = float(np.sum((y - trend @ base) ** 2))

    def explained(rate: float) -> float:
        phase = 2 * np.pi * rate * (t - t[0])
        waves = [g(k * phase) for k in range(1, harmonics + 1) for g in (np.sin, np.cos)]
        basis = np.column_stack([*waves, trend])
        coefficients, *_ = np.linalg.lstsq(basis, y, rcond=None)
        return base_energy - float(np.sum((y - basis @ coefficients) ** 2))

    coarse_step = 1.0 / (2.0 * span)
    candidates = np.arange(low, high + coarse_step, coarse_step)
    best = float(candidates[int(np.argmax([explained(r) for r in candidates]))])
    candidates = np.arange(best - coarse_step, best + coarse_step, coarse_step / 20.0)
    candidates = candidates[(candidates >= low) & (candidates <= high)]
    return float(candidates[int(np.argmax([explained(r) for r in candidates]))])


def periodic_basis(elapsed: np.ndarray, rates_Hz: tuple[float, ...], harmonics: int):
    columns = []
    for rate in rates_Hz:
        for multiple in range(1, harmonics + 1):
            phase = 2 * np.pi * multiple * rate * elapsed
            columns += [np.sin(phase), np.cos(phase)]
    return columns


def _extend(
    t: np.ndarray, y: np.ndarray, rates_Hz: tuple[float, ...], harmonics: int, count: int
) -> np.ndarray:
    """``y`` with ``count`` samples of forecast added at each end.

    Each end is continued by a least-squares fit, over the last (first) two periods of the
    slowest rate, of a quadratic trend plus the periodic components: the relaxation goes
    on smoothly and the breathing keeps its phase, so that the zero-phase filter's start-up
    transients fall outside the record.
    """
    step = float(np.mean(np.diff(t)))
    window = min(len(t), int(2.0 / (min(rates_Hz) * step)))
    pieces = []
    for side in ("start", "end"):
        part = slice(0, window) if side == "start" else slice(len(t) - window, len(t))
        anchor = t[0] if side == "start" else t[-1]
        elapsed = t[part] - anchor
        scale = max(float(np.ptp(elapsed)), step)
        trend = [np.ones_like(elapsed), elapsed / scale, (elapsed / scale) ** 2]
        basis = np.column_stack(trend + periodic_basis(elapsed, rates_Hz, harmonics))
        coefficients, *_ = np.linalg.lstsq(basis, y[part], rcond=None)
        offsets = np.arange(1, count + 1) * step
        future = -offsets[::-1] if side == "start" else offsets
        trend_f = [np.ones_like(future), future / scale, (future / scale) ** 2]
        pieces.append(np.column_stack(trend_f + periodic_basis(future, rates_Hz, harmonics)))
        pieces[-1] = pieces[-1] @ coefficients
    return np.concatenate([pieces[0], y, pieces[1]])


def suppress_physiological(
    time_s: np.ndarray,
    displacement_m: np.ndarray,
    force_N: np.ndarray,
    *,
    rates_Hz: tuple[float, ...],
    harmonics: int = 3,
    quality: float = 4.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Band-stop the respiration and heartbeat rates (and harmonics) out of a record.

    Zero-phase (forward-backward) IIR notches from ``scipy.signal.iirnotch`` at each rate
    and its first ``harmonics`` multiples below 0.45 times the sample rate, applied to the
    displacement and the force alike (see the module docstring for why both). Both ends are
    first extended by a forecast (a quadratic trend plus the periodic components, fitted to
    the two slowest periods at that end), long enough for the notches' transients to die
    out before they reach the record.

    Args:
        time_s: Uniform sample times (s), shape (n,).
        displacement_m: Displacement (m), shape (n,).
        force_N: Force (N), shape (n,).
        rates_Hz: Fundamental rates to remove (Hz), e.g. (0.25, 1.4).
        harmonics: Multiples of each rate to notch (1: the fundamental only).
        quality: Quality factor (centre frequency / -3 dB width) of the fundamentals'
            notches; harmonics get ``quality * multiple`` (the same width in hertz).

    Returns:
        Filtered displacement and force, shape (n,) each.
    """
    from scipy.signal import filtfilt, iirnotch

    check_samples(time_s, displacement_m, force_N)
    t = np.asarray(time_s, dtype=np.float64)
    steps = np.diff(t)
    if np.ptp(steps) > 0.01 * np.mean(steps):
        raise InputError("notch filtering needs uniform sampling (gaps found)")
    rates = tuple(float(r) for r in rates_Hz)
    if not rates or not all(r > 0 for r in rates):
        raise InputError("rates must be positive", value=rates_Hz)
    sample_rate = 1.0 / float(np.mean(steps))
    if max(rates) >= 0.45 * sample_rate:
        raise InputError(
            f"a rate to notch must lie below 0.45 times the sample rate "
            f"({0.45 * sample_rate:.6g} Hz)",
            value=max(rates),
        )
    # A notch of width w = rate / quality decays as exp(-pi w t): pad 8 time constants.
    pad = int(8.0 * quality / (np.pi * min(rates)) * sample_rate)
    filtered = []
    for signal in (displacement_m, force_N):
        y = _extend(t, np.asarray(signal, dtype=np.float64), rates, harmonics, pad)
        for rate in rates:
            for multiple in range(1, harmonics + 1):
                centre = multiple * rate
                if centre >= 0.45 * sample_rate:
                    break
                b, a = iirnotch(centre, quality * multiple, fs=sample_rate)
                y = filtfilt(b, a, y, padtype=None)
        filtered.append(y[pad : pad + len(t)])
    return filtered[0], filtered[1]
