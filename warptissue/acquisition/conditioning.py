"""Prepare a recorded indentation for fitting, keeping the raw data beside the result.

Steps (each also usable on its own), in the order :func:`prepare_record` runs them:

1. :func:`detect_contact`: the first sample where the force leaves the pre-contact baseline
   by more than ``threshold_sigma`` noise standard deviations, refined by extrapolating a
   straight line through the early loading back to the baseline. In vivo, where breathing
   moves the baseline, give the contact instead (the probe rests on the organ).
2. :func:`remove_offset_and_drift`: subtract the baseline force (a constant from the
   pre-contact window, or a straight line when an unloaded window after the test exists too;
   with physiological rates, fitted together with their sines and cosines).
3. Displacement from the contact point: ``position - contact``.
4. :func:`suppress_physiological` (in vivo records): remove respiration and heartbeat with
   zero-phase notch filters at their rates and harmonics (scipy.signal), or keep only a
   breath-hold window with :func:`select_window`. The same filter is applied to the
   displacement and to the force. For a linear viscoelastic specimen (SLS, Prony/QLV at
   small strain), the force is a linear time-invariant functional of the displacement
   history, and any LTI filter commutes with it: the filtered force is exactly the specimen's
   response to the filtered displacement. Fitting the filtered pair is therefore unbiased;
   filtering the force alone would distort the ramp and bias the fit. For nonlinear models
   it is an approximation that holds while the filter leaves the ramp's spectrum alone.
   :func:`estimate_rate_Hz` finds the rates when they are not known (both in
   :mod:`warptissue.acquisition.physiological`, still importable from here).
5. A detected contact (approach through air) clips the depth at zero.
6. :func:`trim_ramp` (ramp fits, Takacs et al.): keep the loading ramp up to a depth, cutting the
   probe's deceleration (Takacs et al. keep the first 3.6 mm of a 4 mm ramp).

:func:`prepare_record` returns a :class:`ConditionedRecord` with the raw columns beside the
result. The steps 1, 2 and 6 and the window live in
:mod:`warptissue.acquisition.conditioning_steps`, step 4 in
:mod:`warptissue.acquisition.physiological`; every name still imports from here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warptissue.acquisition.conditioning_steps import (
    ContactPoint,
    detect_contact,
    remove_offset_and_drift,
    select_window,
    trim_ramp,
)
from warptissue.acquisition.physiological import check_samples as _check
from warptissue.acquisition.physiological import (
    estimate_rate_Hz,
    suppress_physiological,
)
from warptissue.errors import InputError
from warptissue.io import ExperimentData

__all__ = [
    "CONTACT_MODES",
    "OFFSET_MODES",
    "ConditionedRecord",
    "ContactPoint",
    "FitRecord",
    "condition_for_fit",
    "detect_contact",
    "estimate_rate_Hz",
    "prepare_record",
    "remove_offset_and_drift",
    "select_window",
    "suppress_physiological",
    "trim_ramp",
]

CONTACT_MODES: tuple[str, ...] = ("none", "auto")
"""The contact choices of :func:`condition_for_fit` besides a position (m)."""
OFFSET_MODES: tuple[str, ...] = ("auto", "none")
"""The force-offset choices of :func:`condition_for_fit`."""


def _check_options(
    position_m: np.ndarray,
    *,
    physiological_rates_Hz: tuple[float, ...] | str | None,
    harmonics: int,
    quality: float,
    contact_position_m: float | None,
    threshold_sigma: float,
) -> None:
    """InputError naming the first option of :func:`prepare_record` that cannot work."""
    rates = physiological_rates_Hz
    if isinstance(rates, str) and rates != "auto":
        raise InputError('physiological_rates_Hz must be "auto", rates in Hz or None', value=rates)
    if rates is not None and rates != "auto":
        values = np.atleast_1d(np.asarray(rates, dtype=np.float64))
        if values.size == 0 or not np.all(np.isfinite(values) & (values > 0)):
            raise InputError("physiological_rates_Hz must be positive rates in Hz", value=rates)
    if not (isinstance(harmonics, int | np.integer) and harmonics >= 1):
        raise InputError("harmonics must be a whole number of 1 or more", value=harmonics)
    if not (math.isfinite(quality) and quality > 0):
        raise InputError("quality must be a positive number", value=quality)
    if not (math.isfinite(threshold_sigma) and threshold_sigma > 0):
        raise InputError("threshold_sigma must be a positive number", value=threshold_sigma)
    if contact_position_m is not None and not (
        math.isfinite(contact_position_m) and contact_position_m < float(np.max(position_m))
    ):
        raise InputError(
            f"contact_position_m is not above the deepest recorded position "
            f"({float(np.max(position_m)):.6g} m): the probe never reaches it",
            value=contact_position_m,
        )


@dataclass(frozen=True)
class ConditionedRecord:
    """A record ready for fitting, with its raw data.

    Attributes:
        time_s: Time (s) of the kept samples, shape (m,).
        displacement_m: Indentation depth below the contact point (m), shape (m,).
        force_N: Force without baseline (and physiological disturbance) (N), shape (m,).
        raw: The record's original columns, full length.
        kept: Boolean mask (n,) of the raw samples kept.
        contact: The contact point.
        force_offset_N: Baseline removed (N).
        force_drift_N_per_s: Drift removed (N/s).
        notch_rates_Hz: Physiological rates removed (Hz), empty ex vivo.
        steps: What was done, in order.
    """

    time_s: np.ndarray
    displacement_m: np.ndarray
    force_N: np.ndarray
    raw: dict[str, np.ndarray]
    kept: np.ndarray
    contact: ContactPoint
    force_offset_N: float
    force_drift_N_per_s: float
    notch_rates_Hz: tuple[float, ...] = ()
    steps: tuple[str, ...] = field(default_factory=tuple)

    def columns(self) -> dict[str, np.ndarray]:
        """Conditioned columns plus the raw ones (prefixed ``raw_``), full length; removed
        samples have NaN in the conditioned columns."""
        n = len(self.kept)
        out: dict[str, np.ndarray] = {}
        for name, values in (
            ("time_s", self.time_s),
            ("displacement_m", self.displacement_m),
            ("force_N", self.force_N),
        ):
            full = np.full(n, np.nan)
            full[self.kept] = values
            out[name] = full
        for name, values in self.raw.items():
            out[f"raw_{name}"] = values
        return out

    def summary(self) -> dict[str, Any]:
        """JSON-ready description of the conditioning."""
        return {
            "contact": {
                "index": self.contact.index,
                "time_s": self.contact.time_s,
                "position_m": self.contact.position_m,
                "noise_N": self.contact.noise_N,
                "threshold_N": self.contact.threshold_N,
            },
            "force_offset_N": self.force_offset_N,
            "force_drift_N_per_s": self.force_drift_N_per_s,
            "notch_rates_Hz": list(self.notch_rates_Hz),
            "samples_kept": int(self.kept.sum()),
            "samples_raw": len(self.kept),
            "steps": list(self.steps),
        }


def prepare_record(
    record: ExperimentData | dict[str, np.ndarray],
    *,
    physiological_rates_Hz: tuple[float, ...] | str | None = None,
    harmonics: int = 3,
    quality: float = 4.0,
    contact_position_m: float | None = None,
    keep_depth_m: float | None = None,
    window_s: tuple[float, float] | None = None,
    threshold_sigma: float = 6.0,
) -> ConditionedRecord:
    """Condition an indentation record for fitting (see the module docstring).

    Args:
        record: An experiment record with ``time_s``, ``displacement_m`` (axis position
            relative to the start, as the recorder writes it) and ``force_N``.
        physiological_rates_Hz: Respiration/heartbeat rates to notch out; ``"auto"``
            estimates one rate in 0.1-0.7 Hz (respiration) and one in 0.7-3 Hz (heartbeat)
            from the record; None: ex vivo, no filtering.
        harmonics: Harmonics notched per rate.
        contact_position_m: Known contact position (m) (skips detection; e.g. in vivo,
            where the probe rests on the organ before the ramp). The depth is then
            ``position - contact`` unclipped, so that a notch filter's ringing stays linear;
            a detected contact (probe approaching through air) clips the depth at zero.
        keep_depth_m: Keep only the loading ramp to this depth (Takacs et al.: 3.6 mm);
            None keeps the whole record (ramp and hold) for relaxation fits.
        window_s: Keep only ``(start, stop)`` (a breath-hold window), applied last.
        threshold_sigma: Contact threshold in baseline noise standard deviations.

    Returns:
        The conditioned record with the raw columns.
    """
    raw = _raw_columns(record)
    t, x, f = raw["time_s"], raw["displacement_m"], raw["force_N"]
    _check(t, x, f)
    _check_options(
        x,
        physiological_rates_Hz=physiological_rates_Hz,
        harmonics=harmonics,
        quality=quality,
        contact_position_m=contact_position_m,
        threshold_sigma=threshold_sigma,
    )
    steps: list[str] = []
    rates = _physiological_rates(t, x, f, physiological_rates_Hz, steps)
    contact = _contact_point(t, x, f, contact_position_m, threshold_sigma, steps)
    f, offset, drift = _without_offset(t, x, f, contact, rates, harmonics, steps)
    depth = x - contact.position_m
    if rates:
        depth, f = suppress_physiological(
            t, depth, f, rates_Hz=rates, harmonics=harmonics, quality=quality
        )
        steps.append(f"notched {rates} Hz and {harmonics} harmonics (displacement and force)")
    if contact_position_m is None:
        depth = np.clip(depth, 0.0, None)
    kept = _kept_samples(t, x, contact, keep_depth_m, window_s, steps)
    return ConditionedRecord(
        time_s=t[kept],
        displacement_m=depth[kept],
        force_N=f[kept],
        raw=raw,
        kept=kept,
        contact=contact,
        force_offset_N=offset,
        force_drift_N_per_s=drift,
        notch_rates_Hz=rates,
        steps=tuple(steps),
    )


def _raw_columns(record: ExperimentData | dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The record's columns as float64, with ``time_s``, ``displacement_m`` and a finite
    ``force_N`` and displacement (InputError naming the column and sample)."""
    columns = record.columns if isinstance(record, ExperimentData) else dict(record)
    for name in ("time_s", "displacement_m", "force_N"):
        if name not in columns:
            raise InputError("missing column", column=name)
    raw = {name: np.asarray(values, dtype=np.float64) for name, values in columns.items()}
    for name in ("displacement_m", "force_N"):
        bad = np.flatnonzero(~np.isfinite(raw[name]))
        if bad.size:
            raise InputError(
                f"not a finite number at sample {int(bad[0])}",
                column=name,
                value=float(raw[name][bad[0]]),
            )
    return raw


def _physiological_rates(
    t: np.ndarray,
    x: np.ndarray,
    f: np.ndarray,
    physiological_rates_Hz: tuple[float, ...] | str | None,
    steps: list[str],
) -> tuple[float, ...]:
    """The rates to notch, Hz: given, or estimated (``"auto"``) from the record's rest
    before the ramp (or after it where that is too short)."""
    rates: tuple[float, ...] = ()
    if physiological_rates_Hz == "auto":
        moving = np.flatnonzero(np.abs(x - x[0]) > 1e-6)
        rest = slice(0, max(int(moving[0]) if moving.size else len(t), 1))
        if t[max(rest.stop - 1, 0)] - t[0] < 8.0:
            settled = np.flatnonzero(np.abs(x - x[-1]) > 1e-6)
            rest = slice(int(settled[-1]) + 1 if settled.size else 0, None)
        rates = tuple(estimate_rate_Hz(t[rest], f[rest], band) for band in ((0.1, 0.7), (0.7, 3.0)))
        steps.append(f"estimated physiological rates {rates} Hz")
    elif physiological_rates_Hz is not None:
        rates = tuple(float(r) for r in physiological_rates_Hz)
    return rates


def _contact_point(
    t: np.ndarray,
    x: np.ndarray,
    f: np.ndarray,
    contact_position_m: float | None,
    threshold_sigma: float,
    steps: list[str],
) -> ContactPoint:
    """The contact point: detected, or at the given position (the baseline before the
    probe moves)."""
    if contact_position_m is None:
        contact = detect_contact(t, x, f, threshold_sigma=threshold_sigma)
        steps.append(f"contact detected at {contact.position_m:.6g} m, {contact.time_s:.6g} s")
    else:
        index = int(np.searchsorted(np.maximum.accumulate(x), contact_position_m))
        moving = np.flatnonzero(np.abs(x - x[0]) > 1e-6)
        stop = int(moving[0]) if moving.size else len(t)
        baseline = f[: max(stop, 2)]
        contact = ContactPoint(
            index=index,
            time_s=float(t[min(index, len(t) - 1)]),
            position_m=float(contact_position_m),
            baseline_force_N=float(np.mean(baseline)),
            noise_N=float(np.std(baseline)),
            threshold_N=0.0,
        )
        steps.append(f"contact given at {contact_position_m:.6g} m")
    return contact


def _without_offset(
    t: np.ndarray,
    x: np.ndarray,
    f: np.ndarray,
    contact: ContactPoint,
    rates: tuple[float, ...],
    harmonics: int,
    steps: list[str],
) -> tuple[np.ndarray, float, float]:
    """The force without its offset and drift, fitted on the unloaded samples, with them
    (N, N/s; zero where fewer than two samples are unloaded)."""
    # Unloaded: before the position first passes the contact, and after it comes back
    # above it (a retraction).
    loaded = np.flatnonzero(x > contact.position_m + 1e-6)
    first_loaded = int(loaded[0]) if loaded.size else len(t)
    unloaded = np.zeros(len(t), dtype=bool)
    unloaded[:first_loaded] = True
    unloaded[first_loaded:] = x[first_loaded:] < contact.position_m - 1e-6
    if unloaded.sum() >= 2:
        f, offset, drift = remove_offset_and_drift(
            t, f, unloaded=unloaded, periodic_rates_Hz=rates, harmonics=harmonics
        )
        steps.append(f"removed offset {offset:.6g} N and drift {drift:.6g} N/s")
    else:
        offset, drift = 0.0, 0.0
    return f, offset, drift


def _kept_samples(
    t: np.ndarray,
    x: np.ndarray,
    contact: ContactPoint,
    keep_depth_m: float | None,
    window_s: tuple[float, float] | None,
    steps: list[str],
) -> np.ndarray:
    """The samples kept, (n,) bool: the ramp to ``keep_depth_m``, within ``window_s``."""
    kept = np.ones(len(t), dtype=bool)
    if keep_depth_m is not None:
        deepest = float(np.max(x)) - contact.position_m
        if keep_depth_m > 1.1 * deepest:  # 10 %: the contact is an estimate
            raise InputError(
                f"keep_depth_m lies well below the deepest point of the record ({deepest:.6g} "
                "m below the contact): nothing to trim (a length in mm given in m?)",
                value=keep_depth_m,
            )
        kept &= trim_ramp(x, contact_position_m=contact.position_m, keep_depth_m=keep_depth_m)
        steps.append(f"kept the ramp to {keep_depth_m:.6g} m below contact")
    if window_s is not None:
        kept &= select_window(t, start_s=window_s[0], stop_s=window_s[1])
        steps.append(f"kept the window {window_s} s")
    if not kept.any():
        raise InputError(
            f"no sample left: the record spans {t[0]:.6g} to {t[-1]:.6g} s"
            + ("" if keep_depth_m is None else ", and keep_depth_m keeps the loading ramp only"),
            value=window_s,
        )
    return kept


@dataclass(frozen=True)
class FitRecord:
    """A record as a fit uses it, and what :func:`condition_for_fit` did to it.

    Attributes:
        time_s: Time of the kept samples (s), shape (m,); the sample index where the record
            has no time column.
        displacement_m: Indentation depth (m), shape (m,).
        force_N: Force (N), shape (m,).
        conditioned: True where a contact point was given or detected (depths measured from
            it, force offset removed unless ``offset="none"``).
        summary: JSON-ready description of the conditioning.
    """

    time_s: np.ndarray
    displacement_m: np.ndarray
    force_N: np.ndarray
    conditioned: bool
    summary: dict[str, Any]


_OPTION_NAMES = {
    "contact": "contact",
    "offset": "offset",
    "keep_depth_m": "keep_depth_m",
    "window_s": "window_s",
}


def condition_for_fit(
    columns: ExperimentData | dict[str, np.ndarray],
    *,
    contact: str | float = "none",
    offset: str = "auto",
    keep_depth_m: float | None = None,
    window_s: tuple[float, float] | None = None,
    option_names: dict[str, str] | None = None,
) -> FitRecord:
    """Condition one record with a fit's four choices (the one owner of those choices).

    ``warptissue fit relaxation`` and ``punch-modulus`` (``--contact``, ``--offset``,
    ``--keep-depth``, ``--window``) and the ``[[data]]`` records of a study file
    (:mod:`warptissue.study`) both come here.

    Args:
        columns: ``displacement_m`` and ``force_N`` (shape (n,) each) and, optionally,
            ``time_s``.
        contact: ``"none"`` (``displacement_m`` is already the depth), ``"auto"`` (detect
            where the force leaves the pre-contact baseline) or the axis position at contact
            (m); with a contact, depths are measured from it and clipped at zero.
        offset: With a contact: ``"auto"`` subtracts the force offset (and drift) measured
            where the probe carries no load; ``"none"`` keeps the force as recorded.
        keep_depth_m: Keep only the loading ramp down to this depth below contact (m).
        window_s: Keep only the samples with ``start <= time_s <= stop`` (s).
        option_names: How messages name the four options (``contact``, ``offset``,
            ``keep_depth_m``, ``window_s``), e.g. ``--contact`` for the command line.

    Returns:
        The kept samples and a summary of the conditioning.

    Raises:
        InputError: An option that cannot work on this record, or no sample left. The
            message names the option; ``column`` is the data column at fault, if any.
    """
    names = {**_OPTION_NAMES, **(option_names or {})}
    if contact not in CONTACT_MODES and (
        isinstance(contact, str | bool) or not math.isfinite(contact)
    ):
        raise InputError(f"{names['contact']} must be none, auto or a position in m", value=contact)
    if offset not in OFFSET_MODES:
        raise InputError(f"{names['offset']} must be auto or none", value=offset)
    source = columns.columns if isinstance(columns, ExperimentData) else columns
    x = np.asarray(source["displacement_m"], dtype=np.float64)
    f = np.asarray(source["force_N"], dtype=np.float64)
    has_time = "time_s" in source
    t = (
        np.asarray(source["time_s"], dtype=np.float64)
        if has_time
        else np.arange(x.size, dtype=np.float64)
    )
    if window_s is not None and not has_time:
        raise InputError(f"{names['window_s']} needs a time_s column")
    if contact == "none":
        kept = np.ones(x.size, dtype=bool)
        if keep_depth_m is not None:
            kept &= trim_ramp(x, contact_position_m=0.0, keep_depth_m=keep_depth_m)
        if window_s is not None:
            kept &= select_window(t, start_s=window_s[0], stop_s=window_s[1])
        summary = {"contact": "none"} if kept.all() else {"samples_kept": int(kept.sum())}
        if not kept.any():
            raise InputError(f"no sample left after {names['keep_depth_m']}/{names['window_s']}")
        return FitRecord(t[kept], x[kept], f[kept], False, summary)
    if contact != "auto" and not float(np.min(x)) <= contact < float(np.max(x)):
        raise InputError(
            f"{names['contact']} {contact:g} m lies outside the recorded positions "
            f"[{float(np.min(x)):g}, {float(np.max(x)):g}] m",
            column="displacement_m",
        )
    try:
        prepared = prepare_record(
            {"time_s": t, "displacement_m": x, "force_N": f},
            contact_position_m=None if contact == "auto" else float(contact),
            keep_depth_m=keep_depth_m,
            window_s=window_s,
        )
    except InputError as exc:
        if contact == "auto" and "baseline" in exc.message:
            raise InputError(
                f"{names['contact']} auto: {exc.message}; it needs the probe at rest, off the "
                "specimen, for at least 10 samples before it moves: give the contact "
                f"position or use {names['contact']} none",
                value=exc.value,
            ) from None
        raise
    force = prepared.force_N if offset == "auto" else f[prepared.kept]
    summary = prepared.summary()
    summary["offset"] = offset
    if offset == "none":
        summary["force_offset_N"] = summary["force_drift_N_per_s"] = 0.0
    if not prepared.kept.any():
        raise InputError("no sample left after the conditioning")
    return FitRecord(
        prepared.time_s, np.clip(prepared.displacement_m, 0.0, None), force, True, summary
    )
