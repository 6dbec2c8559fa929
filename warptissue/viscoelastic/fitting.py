"""Fits of the lumped viscoelastic models, all through :mod:`warptissue.lsq`.

Every least-squares fit here goes through the project's one engine
(:func:`warptissue.lsq.fit_curve` / :func:`warptissue.lsq.least_squares`, Levenberg-Marquardt
or the self-adapting LM). The joint Wiechert fit can also use Nelder-Mead
(``scipy.optimize.minimize``) on Takacs et al.'s cost, the sum of the RMS errors of the
curves.
Models are simulated on the measured displacement history, ramp included, never on an
idealized step.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np

from warptissue.errors import ConvergenceError, InputError
from warptissue.lsq import FitResult, RejectStep, fit_curve
from warptissue.lsq.engine import covariance_from_jacobian
from warptissue.lsq.metrics import r_squared, rmse
from warptissue.lsq.plausibility import (
    MAX_INDENTATION_DEPTH_M,
    check_indentation_record,
    convergence_warnings,
    fit_quality_warnings,
    stiffness_warnings,
)
from warptissue.viscoelastic._hereditary import validate_history
from warptissue.viscoelastic.linear import (
    PronySeries,
    QuasiLinearViscoelastic,
    StandardLinearSolid,
    exponential_spring_force,
)
from warptissue.viscoelastic.wiechert import LinearWiechert, NonlinearWiechert

__all__ = [
    "RELAXATION_MODELS",
    "RelaxationRecord",
    "fit_qlv",
    "fit_relaxation",
    "fit_relaxation_joint",
    "fit_wiechert_joint",
    "model_from_result",
]

RELAXATION_MODELS = ("sls", "prony", "wiechert", "wiechert-nonlinear")
"""Model names accepted by :func:`fit_relaxation`."""

_WIECHERT_NAMES = ("k0_N_per_m", "k1_N_per_m", "k2_N_per_m", "b1_N_s_per_m", "b2_N_s_per_m")
_WIECHERT_UNITS = ("N/m", "N/m", "N/m", "N s/m", "N s/m")
_NONLINEAR_NAMES = (
    "K0_N_per_m",
    "K1_N_per_m",
    "K2_N_per_m",
    "b1_N_s_per_m",
    "b2_N_s_per_m",
    "kappa0_per_m",
    "kappa1_per_m",
    "kappa2_per_m",
)
_NONLINEAR_UNITS = ("N/m", "N/m", "N/m", "N s/m", "N s/m", "1/m", "1/m", "1/m")


@dataclass(frozen=True)
class RelaxationRecord:
    """One measured test: sampled time, displacement and force (SI, shape (n,) each).

    Attributes:
        time_s: Strictly increasing sample times, shape (n,).
        displacement_m: Indentation depth, shape (n,), positive into the specimen.
        force_N: Force, shape (n,), positive when the probe pushes in.
        source: Where the record came from (a file name), named in errors and warnings.
        conditioned: The record went through contact detection and trimming
            (:mod:`warptissue.acquisition.conditioning`); the fits then skip the "probe
            above the surface" warning.
        max_displacement_m: The largest plausible displacement, m (an indentation's 0.1 m by
            default; a specimen's tensile or compressive test allows more).
    """

    time_s: np.ndarray
    displacement_m: np.ndarray
    force_N: np.ndarray
    source: str | None = None
    conditioned: bool = False
    max_displacement_m: float = MAX_INDENTATION_DEPTH_M

    def __post_init__(self) -> None:
        time, displacement = validate_history(
            self.time_s, self.displacement_m, name="displacement_m"
        )
        _, force = validate_history(time, self.force_N, name="force_N")
        if time.size < 3:
            raise InputError("a record needs at least 3 samples", path=self.source, value=time.size)
        object.__setattr__(self, "time_s", time)
        object.__setattr__(self, "displacement_m", displacement)
        object.__setattr__(self, "force_N", force)

    def plausibility_warnings(self) -> list[str]:
        """:func:`warptissue.lsq.plausibility.check_indentation_record` on this record.

        Raises:
            InputError: A record that cannot be an indentation in SI units.
        """
        messages = check_indentation_record(
            self.displacement_m,
            self.force_N,
            path=self.source,
            conditioned=self.conditioned,
            max_displacement_m=self.max_displacement_m,
        )
        return [f"{self.source}: {m}" if self.source else m for m in messages]


def _initial_prony(record: RelaxationRecord, terms: int) -> np.ndarray:
    """Data-based start: (k_inf, k_1..k_N, tau_1..tau_N) from the peak and the tail.

    The record must have passed :meth:`RelaxationRecord.plausibility_warnings` (non-zero
    force and displacement of one sign).
    """
    time, x, force = record.time_s, record.displacement_m, record.force_N
    peak = int(np.argmax(np.abs(force)))
    x_peak = x[peak] if abs(x[peak]) > 0 else np.max(np.abs(x))
    x_end = x[-1] if abs(x[-1]) > 0 else x_peak
    k_end = max(force[-1] / x_end, 1e-12 * abs(force[peak] / x_peak))
    k_peak = max(force[peak] / x_peak, 1.5 * k_end)
    start = time[peak] - time[0]
    duration = time[-1] - time[0]
    shortest = max(start, 5.0 * float(np.min(np.diff(time))), 1e-3 * duration)
    taus = np.geomspace(shortest, duration / 4.0, terms) if terms > 1 else [duration / 10.0]
    branches = np.full(terms, (k_peak - k_end) / terms)
    return np.concatenate([[k_end], branches, taus])


def _prony_from_vector(p: np.ndarray) -> PronySeries:
    terms = (p.size - 1) // 2
    return PronySeries(p[0], tuple(p[1 : 1 + terms]), tuple(p[1 + terms :]))


def _refusing(model: Callable[[np.ndarray], np.ndarray]) -> Callable[[np.ndarray], np.ndarray]:
    """Turn a model's parameter or integration errors into RejectStep for the engine."""

    def guarded(p: np.ndarray) -> np.ndarray:
        try:
            with np.errstate(over="raise", invalid="raise"):
                return model(p)
        except (InputError, ConvergenceError, FloatingPointError) as exc:
            raise RejectStep(str(exc)) from exc

    return guarded


def fit_relaxation(
    time_s: np.ndarray, displacement_m: np.ndarray, force_N: np.ndarray, **options: Any
) -> FitResult:
    """Fit a lumped viscoelastic model to one measured test (ramp-and-hold or any history).

    The model is driven by the measured displacement history (linear between samples), so
    the finite ramp of a real ramp-and-hold test is part of the fit.

    Args:
        time_s, displacement_m, force_N: The record, shape (n,) each.
        **options: The keyword options of :func:`fit_relaxation_joint` (``model``,
            ``terms``, ``p0``, ``method``, ``objective``, ``relative_floor``,
            ``max_iterations``, ``progress``).

    Returns:
        The result of :func:`fit_relaxation_joint` for this one record.
    """
    return fit_relaxation_joint([RelaxationRecord(time_s, displacement_m, force_N)], **options)


def fit_relaxation_joint(
    records: Sequence[RelaxationRecord],
    *,
    model: str = "sls",
    terms: int = 2,
    p0: Sequence[float] | None = None,
    method: str = "lm",
    objective: str = "absolute",
    relative_floor: float | None = None,
    max_iterations: int = 200,
    progress: bool = False,
) -> FitResult:
    """Fit one lumped viscoelastic model to one or several tests at once.

    Takacs et al. fit a near-step relaxation and a constant-rate ramp together, so that the
    fast and the slow time scales are both constrained, and validate on a third rate
    (predict it with ``result.fitted_model.force_N``). Each model is driven by each record's
    measured displacement history. The residuals of record i are weighted by
    1 / sqrt(n_i), so that every test weighs as its mean square error whatever its sampling
    rate and length (one record is fitted unweighted; the parameters and their covariance
    would be the same).

    Args:
        records: The tests (:class:`RelaxationRecord`, or (time_s, displacement_m, force_N)
            tuples).
        model: "sls" (parameters instantaneous_stiffness_N_per_m,
            equilibrium_stiffness_N_per_m, relaxation_time_s), "prony" (``terms`` terms:
            equilibrium_stiffness_N_per_m, k1..kN_N_per_m, tau1..tauN_s), "wiechert"
            (k0, k1, k2, b1, b2) or "wiechert-nonlinear" (K0, K1, K2, b1, b2, kappa0..2).
        terms: Number of Prony terms (model "prony").
        p0: Initial parameters in the order above; default from the longest record (the
            nonlinear Wiechert model starts from its linear fit with kappa = 0). All
            parameters are bounded below by 0 (kappa_j >= 0: progressive springs; a negative
            kappa makes the spring force fall with stretch beyond 1/|kappa|).
        method: "lm" or "salm" (:func:`warptissue.lsq.least_squares`).
        objective: "absolute" or "relative".
        relative_floor: Smallest |force| (N) used as the divisor of the relative objective
            (:func:`warptissue.lsq.fit_curve`); needed for records that start at zero force.
        max_iterations: Iteration limit of the engine.
        progress: Show a progress bar.

    Returns:
        The :class:`warptissue.lsq.FitResult` (``fitted`` and ``r_squared``/``rmse`` over
        all samples, unweighted), with the extra attributes ``fitted_model`` (the model
        object; :func:`model_from_result` builds it again from any result),
        ``record_rmse_N`` and ``record_r_squared`` (one per record). Its ``warnings`` hold
        the plausibility warnings of the data and of the fitted stiffness
        (:mod:`warptissue.lsq.plausibility`).

    Raises:
        InputError: Bad data (implausible for an indentation: zero force, opposite signs,
            depths beyond 0.1 m), model name or initial parameters.
    """
    checked = [r if isinstance(r, RelaxationRecord) else RelaxationRecord(*r) for r in records]
    if not checked:
        raise InputError("at least one record is needed")
    if model not in RELAXATION_MODELS:
        raise InputError(f"model must be one of {RELAXATION_MODELS}", value=model)
    if model == "prony" and int(terms) < 1:
        raise InputError("terms must be >= 1", value=terms)
    data_warnings = [m for r in checked for m in r.plausibility_warnings()]
    names, units, start, build = _model_setup(checked, model, int(terms), p0, method)
    start = np.asarray(start, dtype=np.float64)
    if start.size != len(names):
        raise InputError(f"p0 needs {len(names)} values {names}", value=start.tolist())
    is_kappa = np.array([n.startswith("kappa") for n in names])
    start = np.where((start == 0.0) & ~is_kappa, 1e-300, start)
    weights = (  # one record: unweighted, so that the cost is its plain 0.5 * SSR
        None
        if len(checked) == 1
        else np.concatenate([np.full(r.time_s.size, r.time_s.size**-0.5) for r in checked])
    )

    def predict(p: np.ndarray) -> np.ndarray:
        body = build(p)
        return np.concatenate([body.force_N(r.time_s, r.displacement_m) for r in checked])

    result = fit_curve(
        _refusing(predict),
        start,
        np.concatenate([r.force_N for r in checked]),
        objective=objective,
        weights=weights,
        relative_floor=relative_floor,
        bounds=(0.0, np.inf),
        method=method,
        parameter_names=names,
        parameter_units=units,
        x_scale=_scales(names, start, checked),
        max_iterations=max_iterations,
        progress=progress,
    )
    result.fitted_model = build(result.x)
    _record_statistics(result, checked)
    result.warnings.extend(data_warnings)
    result.warnings.extend(fit_quality_warnings(result))
    result.warnings.extend(stiffness_warnings(result.parameters, result.parameter_units))
    return result


def _record_statistics(result: FitResult, records: Sequence[RelaxationRecord]) -> None:
    """Set ``record_rmse_N`` and ``record_r_squared`` (None for constant data) per record."""
    result.record_rmse_N, result.record_r_squared = [], []
    offset = 0
    for r in records:
        fitted = result.fitted[offset : offset + r.time_s.size]
        offset += r.time_s.size
        result.record_rmse_N.append(rmse(r.force_N, fitted))
        try:
            result.record_r_squared.append(r_squared(r.force_N, fitted))
        except InputError:
            result.record_r_squared.append(None)


def _scales(
    names: Sequence[str], start: np.ndarray, records: Sequence[RelaxationRecord]
) -> np.ndarray:
    depth = max(max(float(np.max(np.abs(r.displacement_m))) for r in records), 1e-12)
    return np.array(
        [
            max(abs(v), 1.0 / depth) if n.startswith("kappa") else max(abs(v), 1e-12)
            for n, v in zip(names, start, strict=True)
        ]
    )


def _model_setup(
    records: Sequence[RelaxationRecord],
    model: str,
    terms: int,
    p0: Sequence[float] | None,
    method: str,
) -> tuple[tuple[str, ...], tuple[str, ...], np.ndarray, Callable[[np.ndarray], object]]:
    """Names, units, initial values and builder of each model of :func:`fit_relaxation_joint`.

    The default initial values come from the longest record (its hold shows the relaxation).
    """
    record = max(records, key=lambda r: r.time_s[-1] - r.time_s[0])
    if model == "sls":
        names = (
            "instantaneous_stiffness_N_per_m",
            "equilibrium_stiffness_N_per_m",
            "relaxation_time_s",
        )
        if p0 is None:
            k_end, k_branch, tau = _initial_prony(record, 1)
            p0 = (k_end + k_branch, k_end, tau)
        return (
            names,
            ("N/m", "N/m", "s"),
            np.asarray(p0),
            lambda p: StandardLinearSolid(*p),
        )
    if model == "prony":
        names = (
            ("equilibrium_stiffness_N_per_m",)
            + tuple(f"k{i + 1}_N_per_m" for i in range(terms))
            + tuple(f"tau{i + 1}_s" for i in range(terms))
        )
        units = ("N/m",) * (terms + 1) + ("s",) * terms
        start = np.asarray(p0 if p0 is not None else _initial_prony(record, terms))
        return names, units, start, _prony_from_vector
    if model == "wiechert":
        if p0 is None:
            k = _initial_prony(record, 2)
            p0 = (k[0], k[1], k[2], k[1] * k[3], k[2] * k[4])
        return _WIECHERT_NAMES, _WIECHERT_UNITS, np.asarray(p0), lambda p: LinearWiechert(*p)
    if p0 is None:
        linear = fit_relaxation_joint(records, model="wiechert", method=method)
        p0 = np.concatenate([linear.x, np.zeros(3)])
    return _NONLINEAR_NAMES, _NONLINEAR_UNITS, np.asarray(p0), NonlinearWiechert.from_vector


def model_from_result(result: FitResult) -> object:
    """Rebuild the fitted model object from a :func:`fit_relaxation` result's names."""
    names, x = result.parameter_names, np.asarray(result.x)
    if names[0] == "instantaneous_stiffness_N_per_m":
        return StandardLinearSolid(*x)
    if names == _WIECHERT_NAMES:
        return LinearWiechert(*x)
    if names == _NONLINEAR_NAMES:
        return NonlinearWiechert.from_vector(x)
    if names[0] == "equilibrium_stiffness_N_per_m":
        return _prony_from_vector(x)
    raise InputError("not a relaxation-model fit", value=names)


def fit_qlv(
    time_s: np.ndarray,
    displacement_m: np.ndarray,
    force_N: np.ndarray,
    *,
    terms: int = 2,
    p0: Sequence[float] | None = None,
    substeps: int = 4,
    method: str = "lm",
    max_iterations: int = 200,
    max_displacement_m: float = MAX_INDENTATION_DEPTH_M,
) -> FitResult:
    """Fit QLV with an exponential elastic response to a real ramp-and-hold record.

    Model: F(t) = integral G(t - s) dF_e(x(s)), G(t) = 1 - sum g_i (1 - exp(-t/tau_i)) (Ahn
    & Kim Eq. 2, sign fixed) and F_e(x) = A (exp(B x) - 1) = (k0 / B) (exp(B x) - 1), both
    fitted at once on the measured history, finite ramp included.

    The elastic response is fitted as (k0, B), k0 = A B its stiffness at zero displacement
    (:func:`~warptissue.viscoelastic.exponential_spring_force`): an indentation's force is
    often nearly linear in depth, and then A grows without bound while B falls to 0 along a
    valley of equal cost; Levenberg-Marquardt crawled along it to its iteration limit (Ahn &
    Kim's experiment 2 made by FE: 200 iterations, g and tau within 0.9 %). In (k0, B) the
    linear response is the ordinary point B = 0, and B may also come out negative (a
    softening response).

    Args:
        time_s, displacement_m, force_N: The record, shape (n,) each.
        terms: Prony terms N.
        p0: (k0_N_per_m, B_per_m, g1..gN, tau1..tauN_s); default from the data.
        substeps: Sub-intervals of the hereditary integral per sample interval.
        method: "lm" or "salm".
        max_iterations: Iteration limit of the engine.
        max_displacement_m: The largest plausible displacement, m (an indentation's 0.1 m by
            default; a specimen's tensile or compressive test allows more), as
            :attr:`RelaxationRecord.max_displacement_m`.

    Returns:
        The FitResult (parameters k0_N_per_m, B_per_m, g1.., tau1.._s; A = k0 / B);
        ``fitted_model`` is the :class:`QuasiLinearViscoelastic`.
    """
    record = RelaxationRecord(
        time_s, displacement_m, force_N, max_displacement_m=max_displacement_m
    )
    data_warnings = record.plausibility_warnings()
    n = int(terms)
    if n < 1:
        raise InputError("terms must be >= 1", value=terms)
    check_hold(record)
    if p0 is None:
        prony = _initial_prony(record, n)
        instantaneous = prony[0] + prony[1 : 1 + n].sum()
        depth = float(np.max(np.abs(record.displacement_m)))
        rate = 1.0 / depth
        scale = instantaneous * depth / math.expm1(rate * depth) if depth > 0 else 1.0
        p0 = np.concatenate(
            [[scale * rate, rate], prony[1 : 1 + n] / instantaneous, prony[1 + n :]]
        )
    start = np.asarray(p0, dtype=np.float64)
    if start.size != 2 + 2 * n:
        raise InputError(f"p0 needs {2 + 2 * n} values", value=start.tolist())
    names = ("k0_N_per_m", "B_per_m") + tuple(f"g{i + 1}" for i in range(n))
    names += tuple(f"tau{i + 1}_s" for i in range(n))
    units = ("N/m", "1/m") + ("",) * n + ("s",) * n

    def build(p: np.ndarray) -> QuasiLinearViscoelastic:
        return QuasiLinearViscoelastic(
            tuple(p[2 : 2 + n]),
            tuple(p[2 + n :]),
            partial(
                exponential_spring_force, stiffness_N_per_m=float(p[0]), rate_per_m=float(p[1])
            ),
        )

    def predict(p: np.ndarray) -> np.ndarray:
        return build(p).force_N(record.time_s, record.displacement_m, substeps=substeps)

    lower = np.concatenate([[1e-300, -np.inf], np.zeros(2 * n)])
    upper = np.concatenate([[np.inf, np.inf], np.ones(n), np.full(n, np.inf)])
    depth = max(float(np.max(np.abs(record.displacement_m))), 1e-12)
    result = fit_curve(
        _refusing(predict),
        start,
        record.force_N,
        bounds=(lower, upper),
        method=method,
        parameter_names=names,
        parameter_units=units,
        x_scale=np.maximum(
            np.abs(start), np.concatenate([[1e-12, 1 / depth], np.full(2 * n, 1e-3)])
        ),
        max_iterations=max_iterations,
    )
    result.fitted_model = build(result.x)
    result.warnings.extend(convergence_warnings(result))
    result.warnings.extend(data_warnings)
    result.warnings.extend(fit_quality_warnings(result))
    return result


MIN_HOLD_FRACTION = 0.1
"""The shortest hold a relaxation fit of a ramp-and-hold record takes, as a fraction of the
ramp's duration (:func:`check_hold`)."""

HOLD_LEVEL = 0.99
"""A sample holds when its displacement is at least this fraction of the peak's."""


def check_hold(record: RelaxationRecord) -> float:
    """Refuse a record without a hold: the relaxation that a Prony series describes shows only
    while the displacement is held.

    The hold runs from the first to the last sample at :data:`HOLD_LEVEL` of the peak
    displacement or more; the ramp from the first sample to the hold.

    Args:
        record: The record.

    Returns:
        The hold's duration, s.

    Raises:
        InputError: The hold is shorter than :data:`MIN_HOLD_FRACTION` of the ramp (a
            ramp-only or loading-unloading record), naming the record and its hold.
    """
    depth = np.abs(record.displacement_m)
    held = np.flatnonzero(depth >= HOLD_LEVEL * float(np.max(depth)))
    time = record.time_s
    ramp_s = float(time[held[0]] - time[0])
    hold_s = float(time[held[-1]] - time[held[0]])
    if hold_s < MIN_HOLD_FRACTION * ramp_s or held.size < 3:
        raise InputError(
            f"the record has no hold (the displacement stays at its peak for {hold_s:.3g} s "
            f"after a {ramp_s:.3g} s ramp; at least {MIN_HOLD_FRACTION:g} of the ramp is "
            "needed): a Prony series is fitted to the relaxation of a ramp-and-hold record",
            path=record.source,
            column="displacement_m",
        )
    return hold_s


def fit_wiechert_joint(
    records: Sequence[RelaxationRecord],
    p0: Sequence[float],
    *,
    model: str = "nonlinear",
    optimizer: str = "lm",
    max_iterations: int = 200,
    progress: bool = False,
) -> FitResult:
    """Fit one Wiechert model to several tests at once (Takacs et al., Section VI).

    Args:
        records: The tests, e.g. a near-step relaxation and a constant-rate ramp.
        p0: Initial parameters: (k0, k1, k2, b1, b2) for "linear", (K0, K1, K2, b1, b2,
            kappa0, kappa1, kappa2) for "nonlinear".
        model: "linear" or "nonlinear".
        optimizer: "lm" (:func:`fit_relaxation_joint`: residuals of each record divided by
            sqrt(its sample count), so that each test weighs as its mean square error) or
            "nelder-mead" (``scipy.optimize.minimize`` on Takacs et al.'s cost, the sum of
            the RMS errors of the records; K_j, b_j in log scale). Every parameter is
            bounded below by 0 (kappa_j >= 0, progressive springs).
        max_iterations: Iteration limit (for Nelder-Mead: 400 per parameter at most).
        progress: Progress bar (LM only).

    Returns:
        A FitResult with the stacked residuals (per-record RMS weighting as above), ``rmse``
        of all samples, and the extra attributes ``fitted_model``, ``record_rmse_N`` and
        ``record_r_squared`` (one per record) and ``sum_of_record_rmse_N`` (Takacs et al.'s
        cost). For Nelder-Mead the covariance comes from the Jacobian of the stacked
        residuals at the optimum (as for LM).
    """
    if model not in ("linear", "nonlinear"):
        raise InputError("model must be 'linear' or 'nonlinear'", value=model)
    if optimizer not in ("lm", "nelder-mead"):
        raise InputError("optimizer must be 'lm' or 'nelder-mead'", value=optimizer)
    checked = [r if isinstance(r, RelaxationRecord) else RelaxationRecord(*r) for r in records]
    if not checked:
        raise InputError("at least one record is needed")
    if optimizer == "lm":
        result = fit_relaxation_joint(
            checked,
            model="wiechert" if model == "linear" else "wiechert-nonlinear",
            p0=p0,
            max_iterations=max_iterations,
            progress=progress,
        )
        result.sum_of_record_rmse_N = float(sum(result.record_rmse_N))
        return result
    names, units, build = (
        (_WIECHERT_NAMES, _WIECHERT_UNITS, lambda p: LinearWiechert(*p))
        if model == "linear"
        else (_NONLINEAR_NAMES, _NONLINEAR_UNITS, NonlinearWiechert.from_vector)
    )
    start = np.asarray(p0, dtype=np.float64)
    if start.size != len(names):
        raise InputError(f"p0 needs {len(names)} values {names}", value=start.tolist())
    data_warnings = [m for r in checked for m in r.plausibility_warnings()]
    positive = np.array([not n.startswith("kappa") for n in names])
    weights = [1.0 / math.sqrt(r.time_s.size) for r in checked]

    def record_errors(p: np.ndarray) -> list[np.ndarray]:
        body = build(p)
        return [body.force_N(r.time_s, r.displacement_m) - r.force_N for r in checked]

    def stacked(p: np.ndarray) -> np.ndarray:
        return np.concatenate([w * e for w, e in zip(weights, record_errors(p), strict=True)])

    depth = max(float(np.max(np.abs(r.displacement_m))) for r in checked)
    scale = np.where(positive, np.abs(start), np.maximum(np.abs(start), 1.0 / depth))
    result = _nelder_mead(
        _refusing(stacked), record_errors, start, positive, scale, names, units, max_iterations
    )
    all_force = np.concatenate([r.force_N for r in checked])
    result.fitted = all_force + np.concatenate(record_errors(result.x))
    result.rmse = rmse(all_force, result.fitted)
    result.r_squared = r_squared(all_force, result.fitted)
    result.fitted_model = build(result.x)
    _record_statistics(result, checked)
    result.sum_of_record_rmse_N = float(sum(result.record_rmse_N))
    result.warnings.extend(data_warnings)
    result.warnings.extend(fit_quality_warnings(result))
    return result


def _nelder_mead(
    residual: Callable[[np.ndarray], np.ndarray],
    record_errors: Callable[[np.ndarray], list[np.ndarray]],
    start: np.ndarray,
    positive: np.ndarray,
    scale: np.ndarray,
    names: tuple[str, ...],
    units: tuple[str, ...],
    max_iterations: int,
) -> FitResult:
    """Nelder-Mead on Takacs et al.'s sum-of-RMSE cost, wrapped as a FitResult."""
    from scipy.optimize import minimize

    def to_parameters(z: np.ndarray) -> np.ndarray:
        return np.where(positive, start * np.exp(z), start + z * scale)

    def cost(z: np.ndarray) -> float:
        try:
            with np.errstate(over="raise", invalid="raise"):
                errors = record_errors(to_parameters(z))
        except (InputError, ConvergenceError, FloatingPointError):
            return math.inf
        return float(sum(np.sqrt(np.mean(e**2)) for e in errors))

    def bounded_cost(z: np.ndarray) -> float:
        return math.inf if np.any(to_parameters(z) < 0.0) else cost(z)

    outcome = minimize(
        bounded_cost,
        np.zeros(start.size),
        method="Nelder-Mead",
        options={"maxiter": int(max_iterations), "xatol": 1e-6, "fatol": 1e-10, "adaptive": True},
    )
    x = to_parameters(outcome.x)
    residuals = residual(x)
    steps = 1e-6 * np.where(positive, np.abs(x), scale)
    jacobian = np.column_stack(
        [(residual(x + h * np.eye(x.size)[j]) - residuals) / h for j, h in enumerate(steps)]
    )
    status = 2 if outcome.success else 0
    final_cost = 0.5 * float(residuals @ residuals)
    covariance, errors, correlation = covariance_from_jacobian(jacobian, final_cost)
    return FitResult(
        x=x,
        parameter_names=names,
        parameter_units=units,
        cost=final_cost,
        residuals=residuals,
        jacobian=jacobian,
        success=status > 0,
        status=status,
        message=f"Nelder-Mead: {outcome.message}",
        iterations=int(outcome.nit),
        nfev=int(outcome.nfev),
        njev=1,
        covariance=covariance,
        standard_errors=errors,
        correlation=correlation,
        r_squared=None,
        rmse=float(np.sqrt(np.mean(residuals**2))),
        method="nelder-mead",
        lower_bounds=np.zeros(x.size),
        upper_bounds=np.full(x.size, np.inf),
    )
