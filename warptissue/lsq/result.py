"""The result of a least-squares fit, its status table, and the step-refusal signal.

A :class:`FitResult` is what :func:`warptissue.lsq.least_squares` and
:func:`warptissue.lsq.fit_curve` return, in the style of ``scipy.optimize.OptimizeResult``:
the parameters, the final residuals and Jacobian, an integer ``status`` with a message from
:data:`STATUS_MESSAGES`, the iteration history, and the statistics of the fit (covariance,
standard errors, correlation, R², RMSE). It never holds NaN: quantities that are undefined
(R² of a bare residual function, the covariance of a rank-deficient Jacobian) are None.

Every result checks its own identifiability (:attr:`FitResult.identifiability`): a fit can
converge (``success``) and still not determine its parameters. The check is generic, so every
fit of the package (relaxation, punch, hyperelastic, field) reports it the same way, in its
summary (``warning:`` lines), its JSON (``identified``, ``identifiability``, ``warnings``) and
the command line (a ``warning:`` line on stderr; the exit status stays 0).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warptissue.io import software_versions

__all__ = [
    "STANDARD_ERROR_BOUND_FACTOR",
    "STATUS_MESSAGES",
    "FitResult",
    "IterationRecord",
    "RejectStep",
]


STATUS_MESSAGES: Mapping[int, str] = {
    -3: "The Jacobian could not be evaluated at the current point (non-finite, or finite "
    "differences refused); x is the best point reached, without covariance.",
    -2: "No acceptable step: the damping reached its limit without reducing the cost "
    "(a local minimum to rounding precision, or an inaccurate Jacobian).",
    -1: "Stopped by the callback.",
    0: "The maximum number of iterations was reached.",
    1: "`gtol` termination condition is satisfied (projected gradient).",
    2: "`ftol` termination condition is satisfied (relative reduction of the cost).",
    3: "`xtol` termination condition is satisfied (relative step size).",
    4: "Both `ftol` and `xtol` termination conditions are satisfied.",
}
"""Integer status of a fit and its message. ``success`` is ``status > 0``."""


STANDARD_ERROR_BOUND_FACTOR = 1.0
"""A parameter whose standard error exceeds this multiple of its |value| is not identified."""

_BOUND_RTOL = 1e-9
"""Relative distance to a bound below which a parameter counts as pinned at it."""


def _number(value: float) -> str:
    """A plain number for messages (never a NumPy repr)."""
    return f"{float(value):.4g}"


class RejectStep(Exception):  # noqa: N818 (a signal, not an error)
    """Raised by a model to refuse a trial point.

    The fit engine treats the trial point as rejected (as it does a point whose residuals are
    not finite) and tries a more strongly damped, shorter step. Raise it, for example, when an
    FE solve at the trial parameters does not converge, or when the parameters leave the
    model's domain. At the initial point it is an error (``InputError``).
    """


@dataclass(frozen=True)
class IterationRecord:
    """One trial step of the engine.

    Attributes:
        iteration: 1-based count of trial steps so far.
        x: The current parameters after this trial (the trial point when accepted), shape (n,).
        cost: Current cost, 0.5 * sum(residual**2), after this trial.
        trial_cost: Cost at the trial point, or None when the model refused it.
        step_norm: Scaled norm of the (projected) trial step.
        damping: The damping parameter used for this trial (lambda).
        gradient_norm: Norm of the scaled projected gradient at the point the step left from.
        ratio: Actual over predicted reduction of the cost, or None when refused.
        accepted: Whether the trial point was accepted.
    """

    iteration: int
    x: np.ndarray
    cost: float
    trial_cost: float | None
    step_norm: float
    damping: float
    gradient_norm: float
    ratio: float | None
    accepted: bool

    def to_dict(self) -> dict[str, Any]:
        """A JSON-compatible dict of this record."""
        return {
            "iteration": self.iteration,
            "x": self.x.tolist(),
            "cost": self.cost,
            "trial_cost": self.trial_cost,
            "step_norm": self.step_norm,
            "damping": self.damping,
            "gradient_norm": self.gradient_norm,
            "ratio": self.ratio,
            "accepted": self.accepted,
        }


@dataclass
class FitResult:
    """Outcome of a least-squares fit.

    Attributes:
        x: Fitted parameters, shape (n,).
        parameter_names: One name per parameter (units in the name or in parameter_units).
        parameter_units: One SI unit string per parameter ("" for dimensionless).
        cost: 0.5 * sum(residuals**2) at ``x``.
        residuals: The (weighted, possibly relative) residuals at ``x``, shape (m,).
        jacobian: d residuals / d x at ``x``, shape (m, n) (status -3: at the previous
            point, the last one where it could be evaluated).
        success: ``status > 0``.
        status: Key of :data:`STATUS_MESSAGES`.
        message: The status message.
        iterations: Number of trial steps (each costs one residual evaluation).
        nfev: Residual evaluations, finite-difference ones included.
        njev: Jacobian evaluations.
        covariance: (J^T J)^-1 * SSR / (m - n), shape (n, n), or None when J is rank
            deficient or m <= n.
        standard_errors: sqrt(diag(covariance)), shape (n,), or None.
        correlation: covariance normalized by the standard errors, shape (n, n), or None.
        r_squared: Coefficient of determination of the fitted curve against the data (from
            :func:`fit_curve`), or None for a bare residual function.
        rmse: Root mean square error: of the data in data units (from :func:`fit_curve`), or
            of the residuals (from :func:`least_squares`).
        history: One :class:`IterationRecord` per trial step.
        method: "lm" or "salm".
        fitted: Model predictions at ``x``, shape (m,), from :func:`fit_curve`; else None.
        objective: "absolute" or "relative" from :func:`fit_curve`; else None.
        lower_bounds: The lower bounds of the fit, shape (n,) (``-inf`` for none), or None
            when unknown (then no bound check).
        upper_bounds: The upper bounds, shape (n,) (``inf`` for none), or None.
        warnings: Further warnings a caller adds (plausibility of the data or of the
            result: sign, magnitude, units); :attr:`all_warnings` lists them after the
            identifiability warnings.
        standard_error_scales: Per parameter, the size its standard error is judged
            against in :attr:`identifiability` (NaN: its own |value|), shape (n,), or None
            (every parameter against its |value|). For a parameter whose true value may be
            zero, such as a depth offset (judged against the record's depth span).
    """

    x: np.ndarray
    parameter_names: tuple[str, ...]
    parameter_units: tuple[str, ...]
    cost: float
    residuals: np.ndarray
    jacobian: np.ndarray
    success: bool
    status: int
    message: str
    iterations: int
    nfev: int
    njev: int
    covariance: np.ndarray | None
    standard_errors: np.ndarray | None
    correlation: np.ndarray | None
    r_squared: float | None
    rmse: float
    history: list[IterationRecord] = field(default_factory=list)
    method: str = "lm"
    fitted: np.ndarray | None = None
    objective: str | None = None
    lower_bounds: np.ndarray | None = None
    upper_bounds: np.ndarray | None = None
    warnings: list[str] = field(default_factory=list)
    standard_error_scales: np.ndarray | None = None

    @property
    def parameters(self) -> dict[str, float]:
        """Parameter name to fitted value."""
        return {name: float(v) for name, v in zip(self.parameter_names, self.x, strict=True)}

    @property
    def identifiability(self) -> list[str]:
        """Warnings about parameters that the data do not determine; empty when identified.

        One generic check for every fit. A parameter is reported (one line each, naming the
        parameter, its value and unit) when:

        - it is pinned at a finite bound (within a relative 1e-9): the optimum lies outside
          the allowed range, or the data do not move the parameter;
        - its standard error exceeds :data:`STANDARD_ERROR_BOUND_FACTOR` times |value| (or
          times its :attr:`standard_error_scales` entry): the data are consistent with a
          value of zero or of the opposite sign (or with a wide range);
        - it lies within one standard error of a non-zero finite bound.

        For the fit as a whole, a line is added when the covariance is unavailable: no more
        residuals than parameters, or a rank-deficient Jacobian (a singular J^T J: some
        combination of parameters leaves the residuals unchanged).

        Returns:
            The warning messages (without a "warning:" prefix), in parameter order; empty
            for an identified fit.
        """
        messages: list[str] = []
        m, n = self.residuals.size, self.x.size
        errors = self.standard_errors
        if errors is None:
            if m <= n:
                messages.append(
                    f"only {m} residuals for {n} parameters: the covariance is undefined and "
                    "the parameters are not identified"
                )
            else:
                messages.append(
                    "the covariance is singular (rank-deficient Jacobian): some combination "
                    "of the parameters does not change the fit, so they are not identified"
                )
        for j, name in enumerate(self.parameter_names):
            value = float(self.x[j])
            unit = f" {self.parameter_units[j]}" if self.parameter_units[j] else ""
            error = None if errors is None else float(errors[j])
            pinned = None
            for side, bounds in (("lower", self.lower_bounds), ("upper", self.upper_bounds)):
                if bounds is None or not np.isfinite(bounds[j]):
                    continue
                bound = float(bounds[j])
                if abs(value - bound) <= _BOUND_RTOL * max(abs(bound), abs(value)):
                    pinned = f"{name} = {_number(value)}{unit} is pinned at its {side} bound"
                    break
                if error is not None and bound != 0.0 and abs(value - bound) < error:
                    pinned = (
                        f"{name} = {_number(value)}{unit} lies within one standard error "
                        f"({_number(error)}{unit}) of its {side} bound {_number(bound)}"
                    )
            scales = self.standard_error_scales
            scale = None if scales is None or not np.isfinite(scales[j]) else float(scales[j])
            size = abs(value) if scale is None else scale
            if pinned is not None:
                messages.append(pinned + ": it is not identified by the data")
            elif error is not None and error > STANDARD_ERROR_BOUND_FACTOR * size:
                than = "its value" if scale is None else f"{_number(scale)}{unit}"
                messages.append(
                    f"{name} = {_number(value)}{unit} has a standard error of "
                    f"{_number(error)}{unit}, larger than {than}: it is not identified "
                    "by the data"
                )
        return messages

    @property
    def identified(self) -> bool:
        """True when :attr:`identifiability` has nothing to report."""
        return not self.identifiability

    @property
    def all_warnings(self) -> list[str]:
        """The identifiability warnings followed by the caller's :attr:`warnings`."""
        return self.identifiability + list(self.warnings)

    def to_dict(self, *, include_history: bool = False) -> dict[str, Any]:
        """A JSON-compatible summary.

        Args:
            include_history: Also list every iteration record.

        Returns:
            ``{"parameters": {name: {"value", "unit", "standard_error"}}, "r_squared", "rmse",
            "cost", "iterations", "nfev", "njev", "status", "success", "message", "method",
            "objective", "correlation", "identified", "identifiability", "warnings",
            "software"}`` (and ``"history"`` when asked). ``identifiability`` lists the
            messages of :attr:`identifiability`; ``warnings`` lists :attr:`all_warnings`.
        """

        errors = self.standard_errors
        parameters = {
            name: {
                "value": float(self.x[i]),
                "unit": self.parameter_units[i],
                "standard_error": None if errors is None else float(errors[i]),
            }
            for i, name in enumerate(self.parameter_names)
        }
        summary: dict[str, Any] = {
            "parameters": parameters,
            "r_squared": self.r_squared,
            "rmse": self.rmse,
            "cost": self.cost,
            "iterations": self.iterations,
            "nfev": self.nfev,
            "njev": self.njev,
            "status": self.status,
            "success": self.success,
            "message": self.message,
            "method": self.method,
            "objective": self.objective,
            "correlation": None if self.correlation is None else self.correlation.tolist(),
            "identified": self.identified,
            "identifiability": self.identifiability,
            "warnings": self.all_warnings,
            "software": software_versions(),
        }
        if include_history:
            summary["history"] = [record.to_dict() for record in self.history]
        return summary

    def summary(self, *, warnings: bool = True) -> str:
        """A human-readable table of the parameters and the fit statistics.

        Args:
            warnings: End the table with one ``warning: ...`` line per entry of
                :attr:`all_warnings` (the command line prints them on stderr instead).
        """
        errors = self.standard_errors
        width = max(len(name) for name in self.parameter_names)
        lines = [f"{'parameter':<{width}}  {'value':>14}  {'std. error':>12}  unit"]
        for i, name in enumerate(self.parameter_names):
            error = "n/a" if errors is None else f"{errors[i]:.6g}"
            lines.append(
                f"{name:<{width}}  {self.x[i]:>14.6g}  {error:>12}  {self.parameter_units[i]}"
            )
        r2 = "n/a" if self.r_squared is None else f"{self.r_squared:.6f}"
        lines.append(
            f"R^2 = {r2}, RMSE = {self.rmse:.6g}, cost = {self.cost:.6g}, "
            f"iterations = {self.iterations}, status = {self.status}: {self.message}"
        )
        lines.append(
            "parameters identified: "
            + ("yes" if self.identified else f"NO ({len(self.identifiability)} finding(s))")
        )
        if warnings:
            lines.extend(f"warning: {message}" for message in self.all_warnings)
        return "\n".join(lines)
