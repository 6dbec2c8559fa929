"""Force-sensor calibration readings: ``sample,force_N,signal_V`` files, the readings grouped
by sample, a split by sample, Tong et al.'s error measures, and a simulated calibration
session of a load cell. :mod:`warptissue.acquisition.calibration` fits on them.

Calibration data (CSV, one row per sensor reading)::

    sample,force_N,signal_V

``sample`` groups the readings of one applied force (every sample needs the same number);
it is optional (each row its own sample, one reading each). The train/test split is by
sample.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warptissue.errors import InputError
from warptissue.io import csv_number, read_csv_rows

__all__ = [
    "GRAM_FORCE_N",
    "CalibrationData",
    "calibration_metrics",
    "read_calibration_csv",
    "sample_readings",
    "split_samples",
    "synthetic_sensor",
]


@dataclass(frozen=True)
class CalibrationData:
    """Calibration readings.

    Attributes:
        sample: Sample label of each reading, shape (n,) (readings of one applied force).
        force_N: Actual force (reference scale), shape (n,), newtons.
        signal_V: Sensor signal, shape (n,), volts.
    """

    sample: np.ndarray
    force_N: np.ndarray
    signal_V: np.ndarray

    def subset(self, mask: np.ndarray) -> CalibrationData:
        """The readings selected by a boolean mask."""
        return CalibrationData(self.sample[mask], self.force_N[mask], self.signal_V[mask])


def read_calibration_csv(path: str | Path) -> CalibrationData:
    """Read ``sample,force_N,signal_V`` (``sample`` optional).

    Raises:
        InputError: Missing columns, non-numeric or non-finite values (file, line, column),
            fewer than 10 readings, or samples with unequal numbers of readings or two
            forces (file, sample).
    """
    path = Path(path)
    samples, forces, signals = [], [], []
    for line, row in read_csv_rows(path, required=("force_N", "signal_V")):
        forces.append(csv_number(path, line, row, "force_N"))
        signals.append(csv_number(path, line, row, "signal_V"))
        samples.append((row.get("sample") or str(line)).strip())
    if len(forces) < 10:
        raise InputError(f"need at least 10 readings, got {len(forces)}", path=path)
    for column, values in (("signal_V", signals), ("force_N", forces)):
        if np.ptp(values) == 0:
            raise InputError(
                f"{column} is {values[0]:g} in every reading: nothing to calibrate",
                path=path,
                column=column,
            )
    data = CalibrationData(np.array(samples), np.array(forces), np.array(signals))
    try:
        sample_readings(data)
    except InputError as exc:
        raise InputError(exc.message, path=path, column=exc.column, value=exc.value) from None
    return data


def split_samples(
    data: CalibrationData, *, test_samples: int = 6, seed: int = 0
) -> tuple[CalibrationData, CalibrationData]:
    """Split by sample: ``test_samples`` random samples held out (the paper: 70 / 6)."""
    labels = np.unique(data.sample)
    if not 0 < test_samples < len(labels):
        raise InputError(
            f"test_samples must be between 1 and {len(labels) - 1}", value=test_samples
        )
    held = np.random.default_rng(seed).choice(labels, test_samples, replace=False)
    mask = np.isin(data.sample, held)
    return data.subset(~mask), data.subset(mask)


def sample_readings(data: CalibrationData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The readings grouped by sample, in order of first appearance.

    Returns:
        Sample labels (n,), actual force (n,) in N, and readings (n, k) in V, k the readings
        per sample.

    Raises:
        InputError: Samples with different numbers of readings, or one sample with two
            different actual forces.
    """
    labels, first, inverse = np.unique(data.sample, return_index=True, return_inverse=True)
    counts = np.bincount(inverse)
    if np.any(counts != counts[0]):
        odd = str(labels[np.argmax(counts != counts[0])])
        raise InputError(
            f"every sample needs the same number of readings ({counts[0]})",
            column="sample",
            value=odd,
        )
    order = np.argsort(first)
    force = data.force_N[first]
    if np.any(data.force_N != force[inverse]):
        odd = str(data.sample[np.argmax(data.force_N != force[inverse])])
        raise InputError("one sample has two different force_N values", column="sample", value=odd)
    positions = np.argsort(inverse, kind="stable").reshape(len(labels), counts[0])
    return labels[order], force[order], data.signal_V[positions][order]


def calibration_metrics(actual_N: np.ndarray, corrected_N: np.ndarray) -> dict[str, float]:
    """Tong et al.'s error measures of corrected against actual forces.

    e_MAE = 1/n sum |x - x^|; e_MSE = 1/n sqrt(sum (x - x^)^2) (as the paper defines it: not
    the usual mean square, which is also returned as ``mean_square_N2``); e_MAPE = 1/n sum
    |(x^ - x) / x| * 100 (zero actual forces are skipped).
    """
    actual = np.asarray(actual_N, dtype=np.float64)
    corrected = np.asarray(corrected_N, dtype=np.float64)
    count = len(actual)
    error = corrected - actual
    nonzero = actual != 0
    return {
        "mae_N": float(np.abs(error).mean()),
        "mse_paper_N": float(np.sqrt(np.sum(error**2)) / count),
        "mape_percent": float(np.mean(np.abs(error[nonzero] / actual[nonzero])) * 100.0),
        "mean_square_N2": float(np.mean(error**2)),
        "max_abs_error_N": float(np.abs(error).max()),
    }


GRAM_FORCE_N = 9.80665e-3
"""One gram-force in newtons."""


def synthetic_sensor(
    *,
    samples: int = 76,
    readings: int = 5,
    seed: int = 2017,
    noise_V: float = 1e-3,
    emi_probability: float = 0.05,
    emi_V: float = 0.02,
    temperature_coefficient_per_K: float = 5e-4,
) -> CalibrationData:
    """A synthetic calibration session of a 3 kg load cell (Tong et al.'s set-up, simulated).

    ``samples`` weights, uniform on 2-100 % of 3000 g, are applied one after another in
    random order, 60 s each; the sensor is read ``readings`` times, 1 s apart, from 10 s after
    the load is applied. The actual force is the reference scale's reading, the true force
    rounded to its 2 g resolution. Each reading (volts) is

        V = V0 + S F_FS g(x) c(t) (1 + b dT) + a V_FS dT + n + e,    x = F / F_FS,

    quantized by a 12-bit ADC over 0-5 V, with

    - V0 = 0.5 V zero output, S F_FS = V_FS = 4 V span at F_FS = 3000 g;
    - gain nonlinearity g(x) = x - 0.06 x^2 + 0.02 x^3 (sensitivity 6 % lower at full scale,
      full-scale output 4 % below the initial tangent; a cheap load cell);
    - creep c(t) = 1 + 0.002 ln(1 + t / 2 s) with t the time under load;
    - temperature (not recorded): dT(t) = 2 K (1 - exp(-t / 20 min)) (warm-up of the
      electronics after power-on) + 1 K sin(2 pi t / 90 min + phase) (room), t the session
      time; zero coefficient a and span coefficient b, each
      ``temperature_coefficient_per_K`` (0.05 %/K: 2 mV/K of zero, about 0.015 N/K);
    - n: white noise, ``noise_V`` rms per reading (amplifier and ADC);
    - e: electromagnetic interference, a spike of ``emi_V`` rms (Gaussian) on each reading
      with probability ``emi_probability``.

    The parameters are typical data-sheet values of a low-cost load cell with an
    instrumentation amplifier, chosen before any model was fitted.

    Returns:
        Readings with labels S000, S001, ... (the session order).
    """
    rng = np.random.default_rng(seed)
    full_scale_g = 3000.0
    grams = rng.uniform(0.02, 1.0, samples) * full_scale_g
    actual_N = np.round(grams / 2.0) * 2.0 * GRAM_FORCE_N
    time_under_load_s = 10.0 + np.arange(readings, dtype=np.float64)
    session_s = 60.0 * np.arange(samples)[:, None] + time_under_load_s[None, :]
    delta_K = 2.0 * (1.0 - np.exp(-session_s / 1200.0)) + np.sin(
        2.0 * np.pi * session_s / 5400.0 + rng.uniform(0.0, 2.0 * np.pi)
    )
    x = (grams / full_scale_g)[:, None]
    span_V = 4.0
    load_V = (
        span_V * (x - 0.06 * x**2 + 0.02 * x**3) * (1.0 + 0.002 * np.log1p(time_under_load_s / 2.0))
    )
    signal = (
        0.5
        + load_V * (1.0 + temperature_coefficient_per_K * delta_K)
        + temperature_coefficient_per_K * span_V * delta_K
        + rng.normal(0.0, noise_V, (samples, readings))
        + (rng.random((samples, readings)) < emi_probability)
        * rng.normal(0.0, emi_V, (samples, readings))
    )
    lsb_V = 5.0 / 4096
    signal = np.round(signal / lsb_V) * lsb_V
    labels = np.repeat([f"S{k:03d}" for k in range(samples)], readings)
    return CalibrationData(labels, np.repeat(actual_N, readings), signal.ravel())
