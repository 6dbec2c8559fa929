"""What an inverse-FE fit reports beside its record curves: the data statistics of its
result (also of an interrupted one), the Durbin-Watson statistic, the drift warnings of a
record, and the fitted study.

The public face is :mod:`warptissue.fit.indentation` (:func:`fit_indentation`); its module
docstring says what is warned about.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.fit._model import Evaluation, ForwardModel
from warptissue.lsq.engine import covariance_from_jacobian
from warptissue.lsq.metrics import r_squared, rmse
from warptissue.lsq.result import FitResult, IterationRecord
from warptissue.materials import Viscoelastic
from warptissue.study import DataRecord, Protocol, Study

__all__ = [
    "DRIFT_SHARE",
    "fitted_study",
    "record_drift_warnings",
    "result_from",
]

DRIFT_SHARE = 0.02
"""A force change of more than this share of the record's peak force where none is expected
(rising in a hold, left after unloading, a baseline drift) is reported."""


def result_from(
    engine_result: FitResult | None,
    best: Evaluation,
    model: ForwardModel,
    names: tuple[str, ...],
    units: tuple[str, ...],
    method: str,
    lower: np.ndarray,
    upper: np.ndarray,
    history: list[IterationRecord],
) -> FitResult:
    """The engine's result with the data statistics (R^2, RMSE in N, fitted force); for an
    interrupted fit, a result built from the best evaluation."""
    measured = np.concatenate(model.measured)
    fitted = np.concatenate(best.predicted)
    if engine_result is None:
        covariance, errors, correlation = covariance_from_jacobian(best.jacobian, best.cost)
        result = FitResult(
            x=best.x.copy(),
            parameter_names=names,
            parameter_units=units,
            cost=best.cost,
            residuals=best.residuals,
            jacobian=best.jacobian,
            success=False,
            status=-1,
            message="Interrupted (Ctrl-C): the best point evaluated so far.",
            iterations=len(history),
            nfev=model.evaluations,
            njev=1 + sum(1 for record in history if record.accepted),
            covariance=covariance,
            standard_errors=errors,
            correlation=correlation,
            r_squared=None,
            rmse=0.0,
            history=list(history),
            method=method,
            lower_bounds=lower,
            upper_bounds=upper,
        )
    else:
        result = engine_result
    result.fitted = fitted
    result.objective = model.study.fit.objective
    result.rmse = rmse(measured, fitted)
    try:
        result.r_squared = r_squared(measured, fitted)
    except InputError:
        result.r_squared = None
    return result


def fitted_study(study: Study, material: Any) -> Study:
    """The study with the fitted material; a viscoelastic one whose study has a quasi-static
    protocol replays the first record's history instead (``warptissue simulate`` needs time
    steps for it)."""

    fitted = dataclasses.replace(study, material=material)
    if isinstance(material, Viscoelastic) and not study.protocol.timed:
        steps = study.fit.time_steps if study.fit is not None else 40
        protocol = Protocol.from_record(study.data[0], steps=steps)
        fitted = dataclasses.replace(fitted, protocol=protocol)
    return fitted


def record_drift_warnings(record: DataRecord) -> list[str]:
    """A force that rises in a hold, stays after unloading, or a baseline drift removed."""
    t, d, f = record.time_s, record.displacement_m, record.force_N
    peak = float(np.max(np.abs(f))) if f.size else 0.0
    if peak == 0.0 or f.size < 10:
        return []
    messages = []
    name = record.file
    drift = record.conditioning.get("force_drift_N_per_s")
    if drift:
        change = abs(float(drift)) * float(t[-1] - t[0])
        if change > DRIFT_SHARE * peak:
            messages.append(
                f"{name}: the conditioning removed a force baseline drift of {float(drift):.4g} "
                f"N/s ({100 * change / peak:.0f} % of the peak force over the record): a "
                "drifting transducer offset; check the record's zero"
            )
    deepest = int(np.argmax(d))
    span = float(d[deepest])
    if span > 0.0:
        hold = np.flatnonzero(np.abs(d - span) <= 0.005 * span)
        hold = hold[hold >= deepest]
        breaks = np.flatnonzero(np.diff(hold) > 1)
        contiguous = hold[: int(breaks[0]) + 1] if breaks.size else hold  # the first hold
        if contiguous.size >= 10:
            # Running means over a tenth of the hold: the last one against the lowest, beyond
            # both DRIFT_SHARE of the peak and 4 noise levels of such a mean.
            forces = f[contiguous]
            window = max(3, contiguous.size // 10)
            means = np.convolve(forces, np.full(window, 1.0 / window), mode="valid")
            rise = float(means[-1] - np.min(means))
            noise = 1.4826 * float(np.median(np.abs(np.diff(forces)))) / math.sqrt(2.0)
            if rise > max(DRIFT_SHARE * peak, 4.0 * noise / math.sqrt(window)):
                messages.append(
                    f"{name}: the force rises by {rise:.4g} N ({100 * rise / peak:.0f} % of "
                    "its peak) during the hold at the deepest point, where a tissue relaxes: "
                    "a drifting offset or a moving specimen"
                )
        after = np.flatnonzero((np.arange(d.size) > deepest) & (d <= 0.005 * span))
        if after.size >= 5:
            left = float(np.mean(f[after]))
            if abs(left) > DRIFT_SHARE * peak:
                messages.append(
                    f"{name}: the force is {left:.4g} N ({100 * abs(left) / peak:.0f} % of its "
                    "peak) after unloading, where it should return to zero: a drifting "
                    "offset or a probe that lost contact late"
                )
    return messages
