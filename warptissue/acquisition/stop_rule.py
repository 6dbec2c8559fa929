"""When a live fit has learnt enough: the stop rule of ``warptissue acquire --stop-when``.

A small standard error says that the data pin the model down, not that the model is right: a
Prony series of two terms fitted to a QLV tissue reaches standard errors below 2 % while its
parameters lie 5 to 33 standard errors from the tissue's. So the rule asks for both: every
free parameter's relative standard error below the limit, and a model that fits, judged by
the rule the fits already report (:data:`warptissue.lsq.metrics.DURBIN_WATSON_LIMIT`) in
each window of :func:`warptissue.lsq.metrics.windowed_durbin_watson` (the loading, then
windows that double in length). :meth:`StopRule.unmet` says which condition is still unmet;
the live display prints it.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from warptissue.errors import InputError
from warptissue.lsq import FitResult
from warptissue.lsq.metrics import DURBIN_WATSON_LIMIT, windowed_durbin_watson

if TYPE_CHECKING:
    from warptissue.acquisition.live import LiveCurve

__all__ = ["StopRule", "systematic_residuals"]

_STOP_RULE = re.compile(r"^\s*se\s*<\s*([0-9.eE+-]+)\s*(%?)\s*$")


def systematic_residuals(curve: LiveCurve) -> list[str]:
    """The windows of a fitted record whose residuals are systematic.

    Args:
        curve: The fitted record: time (s), measured and model force (N), shape (m,) each.

    Returns:
        One phrase per window whose Durbin-Watson statistic is below
        :data:`~warptissue.lsq.metrics.DURBIN_WATSON_LIMIT` (``"systematic residuals at
        0.52-1.03 s (Durbin-Watson 0.03)"``); empty when the model fits everywhere.
    """
    time = np.asarray(curve.time_s, dtype=np.float64)
    measured = np.asarray(curve.measured_force_N, dtype=np.float64)
    if time.size == 0:
        return []
    peak_s = float(time[int(np.argmax(np.abs(measured)))])
    windows = windowed_durbin_watson(
        time, np.asarray(curve.model_force_N) - measured, first_end_s=peak_s
    )
    return [
        f"systematic residuals at {start:.3g}-{end:.3g} s (Durbin-Watson {dw:.2g} < "
        f"{DURBIN_WATSON_LIMIT:g})"
        for start, end, _, dw in windows
        if dw is not None and dw < DURBIN_WATSON_LIMIT
    ]


@dataclass(frozen=True)
class StopRule:
    """Stop once every free parameter's relative standard error is below
    ``relative_standard_error``, the fit is identified, and the model fits.

    Attributes:
        relative_standard_error: The largest standard error / |value| allowed (0.02 for
            ``se<2%``).
    """

    relative_standard_error: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.relative_standard_error) and self.relative_standard_error > 0):
            raise InputError(
                "the stop rule's relative standard error must be positive",
                value=self.relative_standard_error,
            )

    @classmethod
    def parse(cls, text: str) -> StopRule:
        """``se<2%`` or ``se<0.02``.

        Raises:
            InputError: Any other text (the value named).
        """
        match = _STOP_RULE.match(text)
        if match is None:
            raise InputError("--stop-when takes se<LIMIT, e.g. se<2%", value=text)
        try:
            value = float(match.group(1))
        except ValueError:
            raise InputError("--stop-when takes se<LIMIT, e.g. se<2%", value=text) from None
        return cls(value / 100.0 if match.group(2) else value)

    def relative_errors(self, result: FitResult) -> np.ndarray | None:
        """Standard error / |value| per parameter, shape (n,), or None without a covariance."""
        if result.standard_errors is None:
            return None
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.abs(result.standard_errors) / np.abs(result.x)

    def unmet(self, result: FitResult, curve: LiveCurve | None = None) -> list[str]:
        """The conditions that do not hold yet, in words; empty when the rule holds.

        Args:
            result: The fit.
            curve: What it fitted (:class:`~warptissue.acquisition.live.LiveCurve`), for the
                test of systematic residuals; None skips that test.
        """
        if not result.success:
            return ["a converged fit"]
        missing = [] if result.identified else ["an identified fit"]
        relative = self.relative_errors(result)
        if relative is None:
            missing.append("standard errors")
        else:
            worst = int(np.nanargmax(np.where(np.isfinite(relative), relative, np.inf)))
            if not relative[worst] < self.relative_standard_error:
                missing.append(
                    f"the se of {result.parameter_names[worst]} below "
                    f"{self.relative_standard_error * 100:g}% (now {relative[worst] * 100:.3g}%)"
                )
        if curve is not None:
            missing += systematic_residuals(curve)
        return missing

    def met(self, result: FitResult, curve: LiveCurve | None = None) -> bool:
        """Converged, identified, every relative standard error below the limit, and (with
        ``curve``) no systematic residuals."""
        return not self.unmet(result, curve)

    def __str__(self) -> str:
        return f"se<{self.relative_standard_error * 100:g}%"
