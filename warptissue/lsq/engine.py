"""The least-squares engine of warptissue: Levenberg-Marquardt and self-adapting LM.

Every fit in the project (analytic stress-strain curves, lumped viscoelastic models, the
heterogeneous field estimator, inverse FE) goes through :func:`least_squares` or its curve
front end :func:`fit_curve`. The front end follows ``scipy.optimize.least_squares``: validate
the input first, then iterate, then return a :class:`~warptissue.lsq.result.FitResult` with an
integer status from :data:`~warptissue.lsq.result.STATUS_MESSAGES`.

Notes:
    Both methods solve the damped Gauss-Newton system for the step d,

        (J^T J + lambda D^2) d = -J^T r,

    through the SVD of the column-scaled Jacobian J D^-1 (as a damped least-squares problem,
    which is better conditioned than forming J^T J). The cost is 0.5 * ||r||^2.

    ``method="lm"``: Levenberg-Marquardt with Marquardt's scaling, D^2 = diag(J^T J) (Ahn &
    Kim, Eq. 8, print the Levenberg form J^T J + lambda I; Marquardt's diagonal makes the
    step invariant to the units of each parameter, which matters for moduli in Pa next to
    dimensionless exponents). D is taken from the current Jacobian at every iteration; a
    zero column (a parameter without effect) gets D = 1, so D^2 stays positive. (MINPACK's
    running maximum of the column norms was tried: on Powell's singular function it needs
    296 steps instead of 130, because the columns shrink near the solution.)
    The damping lambda follows Nielsen's rule (Madsen, Nielsen & Tingleff 2004): with
    rho = actual / predicted cost reduction, an accepted step (rho > 1e-4) multiplies lambda
    by max(1/3, 1 - (2 rho - 1)^3); a rejected step multiplies it by nu (2, 4, 8, ...).
    The ``gtol`` test is MINPACK's: the largest cosine between r and a column of J.

    ``method="salm"``: the self-adapting LM of Tong et al., Eq. 7-12 and
    Algorithm 1, with D = I (or 1/x_scale):

        lambda_k = eta_k (theta m_k / ||Y_k|| + (1 - theta) m_k / ||J_k^T Y_k||),
            m_k = min(||Y_k||^2, ||J_k^T Y_k||^2)                               (Eq. 8)
        tau_k = (||Y_k||^2 - ||Y(x_k + d_k)||^2) / (||Y_k||^2 - ||Y_k + J_k d_k||^2) (Eq. 11)
        x_{k+1} = x_k + d_k if tau_k > p0, else x_k                                 (Eq. 12)
        eta_{k+1} = max(c, eta_k q(tau_k)),  q(tau) = max(0.5, 1 - 2 (2 tau - 1)^3)

    and the loop runs while ||J^T Y||_2 >= epsilon (``gtol``). Two misprints of the paper are
    corrected here. (1) Eq. 9 prints eta_{k+1} = min{c, eta_k q}, but Algorithm 1 asks for
    eta_1 > c, which only makes sense if c is a lower bound: with min, eta could never exceed
    c again and the initial value would be meaningless. It is max{c, .}, as in the
    self-adaptive LM of Fan & Pan (2006) that the method builds on. (2) Eq. 10 prints
    q(tau) = max{0.5, 1 - (2 tau - 1)^2}, which never exceeds 1: the damping could then
    only shrink, also after a rejected step, so a rejected step would be retried with a
    LONGER step, forever. Fan & Pan's q is max{1/4, 1 - 2 (2 tau - 1)^3}, which grows the
    damping (q(0) = 3) after a poor step and shrinks it (q(1) = 1/4) after a good one; we
    use that cubic with the paper's floor of 0.5. Defaults: theta = 0.5, c = 1e-8,
    p0 = 1e-4, eta_1 = 1 (the paper gives no values). The paper has no ``ftol``/``xtol``
    tests; they are added as safeguards, with the same meaning as for "lm".

    Refused trial points (``RejectStep`` raised by the model, or non-finite residuals) are
    rejected steps with extra damping: lambda (lm) or eta (salm) grows by a further factor
    of 10.

    Bounds are kept by projection (Kanzow, Yamashita & Fukushima 2004): parameters at a
    bound whose gradient points outward are held fixed for the step, the step of the others
    is projected onto the box, and the predicted reduction uses the projected step. Iterates
    are therefore always feasible and a model is never evaluated outside the bounds (finite
    differences step inward at a bound).

    Finite differences (``jac=None``): forward differences with step
    h_j = sqrt(eps) * max(|x_j|, s_j), where s_j is ``x_scale`` (default 1), taken toward
    the inside of the bounds; a refused point is retried on the other side.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warptissue.errors import ConvergenceError, InputError
from warptissue.lsq.damping import MarquardtDamping, SelfAdaptingDamping
from warptissue.lsq.jacobian import Evaluator, Jacobians, covariance_from_jacobian
from warptissue.lsq.metrics import r_squared, rmse
from warptissue.lsq.result import STATUS_MESSAGES, FitResult, IterationRecord

__all__ = ["covariance_from_jacobian", "fit_curve", "least_squares"]

METHODS: tuple[str, ...] = ("lm", "salm")
"""The methods of :func:`least_squares`: Levenberg-Marquardt and self-adapting LM."""
RELATIVE_FLOOR_SHARE = 0.01
"""The default floor of a relative objective (``relative_floor`` of :func:`fit_curve`) that
the fits choose for the user: this share of the largest |force| of the records."""
_OPTION_DEFAULTS: Mapping[str, Mapping[str, float]] = {
    "lm": {"initial_damping": 1e-3, "p0": 1e-4},
    "salm": {"theta": 0.5, "c": 1e-8, "p0": 1e-4, "eta0": 1.0},
}
REFUSAL_FACTOR = 10.0
_DAMPING_LIMIT = 1e300


def _as_vector(name: str, value: Any, size: int) -> np.ndarray:
    try:
        array = np.broadcast_to(np.asarray(value, dtype=np.float64), (size,)).copy()
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number or an array of {size}", value=value) from None
    return array


def _validate_names(
    names: Sequence[str] | None, size: int, default_prefix: str, what: str
) -> tuple[str, ...]:
    if names is None:
        return tuple(f"{default_prefix}{i}" for i in range(size))
    result = tuple(str(name) for name in names)
    if len(result) != size:
        raise InputError(f"{what} needs {size} entries", value=list(result))
    return result


@dataclass(frozen=True)
class _Problem:
    """The validated input of :func:`least_squares`."""

    x0: np.ndarray
    names: tuple[str, ...]
    units: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    scale_vector: np.ndarray | None
    damping: MarquardtDamping | SelfAdaptingDamping


def _validated_problem(
    x0: Sequence[float] | np.ndarray,
    *,
    bounds: tuple[Any, Any],
    method: str,
    x_scale: Sequence[float] | np.ndarray | float | None,
    max_iterations: int,
    tolerances: Mapping[str, float],
    parameter_names: Sequence[str] | None,
    parameter_units: Sequence[str] | None,
    options: Mapping[str, float] | None,
) -> _Problem:
    """The checked start, names, units, bounds, scale and damping rule (InputError if not)."""
    if method not in METHODS:
        raise InputError(f"method must be one of {METHODS}", value=method)
    x = np.asarray(x0, dtype=np.float64).reshape(-1).copy()
    n = x.size
    if n == 0 or not np.all(np.isfinite(x)):
        raise InputError("x0 must be a non-empty array of finite numbers", value=x.tolist())
    names = _validate_names(parameter_names, n, "x", "parameter_names")
    units = (
        ("",) * n
        if parameter_units is None
        else _validate_names(parameter_units, n, "", "parameter_units")
    )
    if len(bounds) != 2:
        raise InputError("bounds must be a pair (lower, upper)", value=bounds)
    lower = _as_vector("lower bound", bounds[0], n)
    upper = _as_vector("upper bound", bounds[1], n)
    if np.any(np.isnan(lower)) or np.any(np.isnan(upper)) or np.any(lower >= upper):
        raise InputError(
            "each lower bound must be below its upper bound",
            value=(lower.tolist(), upper.tolist()),
        )
    outside = np.flatnonzero((x < lower) | (x > upper))
    if outside.size:
        j = int(outside[0])
        raise InputError(
            f"x0 is outside the bounds [{lower[j]}, {upper[j]}] for {names[j]}",
            value=float(x[j]),
        )
    scale_vector = None
    if x_scale is not None:
        scale_vector = _as_vector("x_scale", x_scale, n)
        if not np.all(np.isfinite(scale_vector) & (scale_vector > 0.0)):
            raise InputError("x_scale must be positive and finite", value=scale_vector.tolist())
    if int(max_iterations) < 1:
        raise InputError("max_iterations must be at least 1", value=max_iterations)
    for tol_name, tol in tolerances.items():
        if not (tol >= 0.0 and math.isfinite(tol)):
            raise InputError(f"{tol_name} must be a finite number >= 0", value=tol)
    merged = dict(_OPTION_DEFAULTS[method])
    for key, value in (options or {}).items():
        if key not in merged:
            raise InputError(
                f"unknown option for method {method!r}; known: {sorted(merged)}", value=key
            )
        merged[key] = float(value)
    damping = (
        MarquardtDamping(merged, scale_vector)
        if method == "lm"
        else SelfAdaptingDamping(merged, scale_vector)
    )
    return _Problem(x, names, units, lower, upper, scale_vector, damping)


@dataclass
class _Iterate:
    """The iteration's state: the current point, what is known there, the steps so far."""

    x: np.ndarray
    residuals: np.ndarray
    cost: float
    jacobian: np.ndarray
    jacobian_is_current: bool = True
    history: list[IterationRecord] = field(default_factory=list)
    iteration: int = 0
    status: int | None = None


def _step_status(
    *,
    accepted: bool,
    small_step: bool,
    previous_cost: float,
    cost: float,
    ratio: float | None,
    ftol: float,
    stop: bool,
    iteration: int,
    max_iterations: int,
) -> int | None:
    """The termination status after a trial step (STATUS_MESSAGES' keys), or None to go on."""
    status = None
    if accepted:
        small_reduction = (previous_cost - cost) <= ftol * previous_cost and (ratio > 0.25)
        if small_reduction and small_step:
            status = 4
        elif small_reduction:
            status = 2
        elif small_step:
            status = 3
    elif small_step:
        status = 3
    if status is None and stop:
        status = -1
    if status is None and not accepted and iteration >= max_iterations:
        status = 0
    return status


def _iterate(
    state: _Iterate,
    problem: _Problem,
    *,
    evaluate: Evaluator,
    jacobian_at: Jacobians,
    max_iterations: int,
    ftol: float,
    xtol: float,
    gtol: float,
    callback: Callable[[IterationRecord], bool | None] | None,
    bar: Any,
) -> None:
    """The damped Gauss-Newton iteration (module notes) on ``state`` until it has a status."""
    damping, lower, upper = problem.damping, problem.lower, problem.upper
    n = state.x.size
    while state.status is None:
        x, residuals, cost, jacobian = state.x, state.residuals, state.cost, state.jacobian
        gradient = jacobian.T @ residuals
        scale = damping.scale(jacobian)
        at_lower = (x <= lower) & (gradient > 0.0)
        at_upper = (x >= upper) & (gradient < 0.0)
        free = ~(at_lower | at_upper)
        gradient_norm = damping.gradient_norm(jacobian, residuals, gradient, free)
        if gradient_norm <= gtol:
            state.status = 1
            break
        if state.iteration >= max_iterations:
            state.status = 0
            break
        scaled_jacobian = jacobian[:, free] / scale[free]
        u, singular, vt = np.linalg.svd(scaled_jacobian, full_matrices=False)
        projected_residuals = u.T @ residuals
        residual_norm = math.sqrt(2.0 * cost)
        scaled_gradient_norm = float(np.linalg.norm(scaled_jacobian.T @ residuals))
        x_norm = float(np.linalg.norm(scale * x))
        while True:
            lam = damping.value(residual_norm, scaled_gradient_norm)
            if not (lam < _DAMPING_LIMIT):
                state.status = -2
                break
            z = -(vt.T @ (singular * projected_residuals / (singular**2 + lam)))
            step = np.zeros(n)
            step[free] = z / scale[free]
            trial = np.clip(x + step, lower, upper)
            step = trial - x
            step_norm = float(np.linalg.norm(scale * step))
            predicted = -(2.0 * float(gradient @ step) + float(np.sum((jacobian @ step) ** 2)))
            state.iteration += 1
            trial_residuals = evaluate(trial) if predicted > 0.0 else None
            if trial_residuals is None:
                trial_cost = None
                ratio = None
            else:
                trial_cost = 0.5 * float(trial_residuals @ trial_residuals)
                ratio = (cost - trial_cost) / (0.5 * predicted)
            damping.update(ratio if predicted > 0.0 else -1.0)
            accepted = ratio is not None and ratio > damping.p0
            if accepted:
                state.x, state.residuals, state.cost = trial, trial_residuals, trial_cost
                state.jacobian_is_current = False
            record = IterationRecord(
                iteration=state.iteration,
                x=state.x.copy(),
                cost=state.cost,
                trial_cost=trial_cost,
                step_norm=step_norm,
                damping=lam,
                gradient_norm=gradient_norm,
                ratio=ratio,
                accepted=accepted,
            )
            state.history.append(record)
            bar.update(1)
            bar.set_postfix(cost=f"{state.cost:.4g}", damping=f"{lam:.2g}", refresh=False)
            try:
                stop = bool(callback(record)) if callback is not None else False
            except StopIteration:
                stop = True
            state.status = _step_status(
                accepted=accepted,
                small_step=step_norm <= xtol * (xtol + x_norm),
                previous_cost=cost,
                cost=state.cost,
                ratio=ratio,
                ftol=ftol,
                stop=stop,
                iteration=state.iteration,
                max_iterations=max_iterations,
            )
            if state.status is not None or accepted:
                break
        if state.status is None:
            try:
                state.jacobian = jacobian_at(state.x, state.residuals)
                state.jacobian_is_current = True
            except ConvergenceError:
                state.status = -3


def _result(
    state: _Iterate,
    problem: _Problem,
    *,
    evaluate: Evaluator,
    jacobian_at: Jacobians,
    method: str,
) -> FitResult:
    """The :class:`FitResult` of a finished iteration: the Jacobian at its point (where not
    yet evaluated) for the covariance, the status message and the counts."""
    if not state.jacobian_is_current and state.status != -3:
        try:
            state.jacobian = jacobian_at(state.x, state.residuals)
            state.jacobian_is_current = True
        except ConvergenceError:
            state.status = -3
    covariance, errors, correlation = (
        covariance_from_jacobian(state.jacobian, state.cost)
        if state.jacobian_is_current
        else (None, None, None)
    )
    status = state.status
    return FitResult(
        x=state.x,
        parameter_names=problem.names,
        parameter_units=problem.units,
        cost=state.cost,
        residuals=state.residuals,
        jacobian=state.jacobian,
        success=status > 0,
        status=status,
        message=STATUS_MESSAGES[status],
        iterations=state.iteration,
        nfev=evaluate.nfev,
        njev=jacobian_at.njev,
        covariance=covariance,
        standard_errors=errors,
        correlation=correlation,
        r_squared=None,
        rmse=float(np.sqrt(np.mean(state.residuals**2))),
        history=state.history,
        method=method,
        lower_bounds=problem.lower,
        upper_bounds=problem.upper,
    )


def least_squares(
    fun: Callable[[np.ndarray], np.ndarray],
    x0: Sequence[float] | np.ndarray,
    *,
    jac: Callable[[np.ndarray], np.ndarray] | None = None,
    bounds: tuple[Any, Any] = (-np.inf, np.inf),
    method: str = "lm",
    x_scale: Sequence[float] | np.ndarray | float | None = None,
    max_iterations: int = 200,
    ftol: float = 1e-8,
    xtol: float = 1e-8,
    gtol: float = 1e-8,
    callback: Callable[[IterationRecord], bool | None] | None = None,
    progress: bool = False,
    parameter_names: Sequence[str] | None = None,
    parameter_units: Sequence[str] | None = None,
    options: Mapping[str, float] | None = None,
) -> FitResult:
    """Minimize 0.5 * sum(fun(x)**2) subject to lower <= x <= upper.

    Args:
        fun: Residuals, ``fun(x) -> (m,)``. It may raise :class:`RejectStep` (or return
            non-finite values) to refuse a trial point; the engine then damps harder.
        x0: Initial parameters, shape (n,); must lie within the bounds.
        jac: Jacobian of the residuals, ``jac(x) -> (m, n)`` (analytic or FE sensitivities),
            or None for forward finite differences.
        bounds: (lower, upper), scalars or arrays of n; ``-inf``/``inf`` for none.
        method: "lm" (Levenberg-Marquardt, Marquardt scaling) or "salm" (Tong et al.'s
            self-adapting LM).
        x_scale: Characteristic scale of each parameter, shape (n,) or scalar. When given,
            the damping uses D = 1/x_scale in place of the method's own scaling.
        max_iterations: Maximum number of trial steps (each costs one evaluation of ``fun``).
        ftol: Stop when an accepted step reduced the cost by less than ``ftol * cost``.
        xtol: Stop when the scaled step is shorter than ``xtol * (xtol + ||D x||)``.
        gtol: Stop when the gradient measure falls below ``gtol`` ("lm": the largest cosine
            between the residuals and a Jacobian column; "salm": ||J^T r||_2, Algorithm 1's
            epsilon).
        callback: Called after every trial step with its :class:`IterationRecord`; return
            True (or raise StopIteration) to stop (status -1).
        progress: Show a tqdm progress bar with the cost and damping.
        parameter_names: One name per parameter (default x0, x1, ...).
        parameter_units: One unit per parameter (default "").
        options: Method constants: "lm": initial_damping (1e-3), p0 (1e-4); "salm": theta
            (0.5), c (1e-8), p0 (1e-4), eta0 (1.0).

    Returns:
        The :class:`FitResult`. ``r_squared`` is None (there is no data); ``rmse`` is the root
        mean square of the residuals.

    Raises:
        InputError: Invalid arguments, ``x0`` outside the bounds, or a model that is not
            defined (refused or non-finite) at ``x0``.
        ConvergenceError: The Jacobian could not be evaluated at ``x0`` (non-finite analytic
            Jacobian, or finite differences refused on both sides). Later such a failure
            ends the fit with status -3 and the best point so far.
    """
    problem = _validated_problem(
        x0,
        bounds=bounds,
        method=method,
        x_scale=x_scale,
        max_iterations=max_iterations,
        tolerances={"ftol": ftol, "xtol": xtol, "gtol": gtol},
        parameter_names=parameter_names,
        parameter_units=parameter_units,
        options=options,
    )
    x = problem.x0
    evaluate = Evaluator(fun, None)
    residuals = evaluate(x)
    if residuals is None:
        raise InputError("the model is not defined (refused or non-finite) at x0", value=x.tolist())
    evaluate.residual_count = residuals.size
    jacobian_at = Jacobians(
        jac,
        evaluate,
        lower=problem.lower,
        upper=problem.upper,
        scale_vector=problem.scale_vector,
    )
    cost = 0.5 * float(residuals @ residuals)
    state = _Iterate(x=x, residuals=residuals, cost=cost, jacobian=jacobian_at(x, residuals))

    from tqdm.auto import tqdm

    bar = tqdm(
        total=int(max_iterations),
        desc=f"least squares ({method})",
        unit="step",
        disable=not progress,
        leave=False,
    )
    try:
        _iterate(
            state,
            problem,
            evaluate=evaluate,
            jacobian_at=jacobian_at,
            max_iterations=max_iterations,
            ftol=ftol,
            xtol=xtol,
            gtol=gtol,
            callback=callback,
            bar=bar,
        )
    finally:
        bar.close()
    return _result(state, problem, evaluate=evaluate, jacobian_at=jacobian_at, method=method)


def _residual_factor(
    y: np.ndarray, weights: Any, objective: str, relative_floor: float | None
) -> np.ndarray:
    """The factor of each residual of :func:`fit_curve`: its weight over the data value
    (``"relative"``, floored by ``relative_floor``) or over 1 (``"absolute"``)."""
    if weights is None:
        w = np.ones_like(y)
    else:
        w = np.asarray(weights, dtype=np.float64).reshape(-1)
        if w.shape != y.shape:
            raise InputError(f"weights need {y.size} entries", value=w.size)
        if not np.all(np.isfinite(w) & (w > 0.0)):
            bad = int(np.flatnonzero(~(np.isfinite(w) & (w > 0.0)))[0])
            raise InputError(
                f"weights must be positive and finite (index {bad})", value=float(w[bad])
            )
    if objective == "absolute":
        divisor = np.ones_like(y)
    elif objective == "relative":
        if relative_floor is None:
            threshold = 1e-6 * float(np.max(np.abs(y)))
            small = np.flatnonzero(np.abs(y) <= threshold)
            if small.size:
                raise InputError(
                    f"relative objective: data value at index {int(small[0])} is (near) zero; "
                    "select a data window away from zero or set relative_floor",
                    value=float(y[small[0]]),
                )
            divisor = y.copy()
        else:
            if not (relative_floor > 0.0 and math.isfinite(relative_floor)):
                raise InputError("relative_floor must be positive", value=relative_floor)
            divisor = np.where(y < 0.0, -1.0, 1.0) * np.maximum(np.abs(y), relative_floor)
    else:
        raise InputError("objective must be 'absolute' or 'relative'", value=objective)
    return w / divisor


def fit_curve(
    model: Callable[[np.ndarray], np.ndarray],
    p0: Sequence[float] | np.ndarray,
    y_data: Sequence[float] | np.ndarray,
    *,
    objective: str = "absolute",
    weights: Sequence[float] | np.ndarray | None = None,
    jac: Callable[[np.ndarray], np.ndarray] | None = None,
    bounds: tuple[Any, Any] = (-np.inf, np.inf),
    method: str = "lm",
    parameter_names: Sequence[str] | None = None,
    parameter_units: Sequence[str] | None = None,
    relative_floor: float | None = None,
    x_scale: Sequence[float] | np.ndarray | float | None = None,
    max_iterations: int = 200,
    ftol: float = 1e-8,
    xtol: float = 1e-8,
    gtol: float = 1e-8,
    callback: Callable[[IterationRecord], bool | None] | None = None,
    progress: bool = False,
    options: Mapping[str, float] | None = None,
) -> FitResult:
    """Fit model predictions to data with an absolute or a relative error objective.

    Residuals: ``w * (model(p) - y)`` ("absolute", the needle-indentation study's Eq. 4) or
    ``w * (model(p) - y) / y`` ("relative", Ahn & Kim Eq. 7 and the needle-indentation
    study's Eq. 5, the objective Abaqus uses). Relative residuals are undefined where the
    data are zero; by default any |y_i| below 1e-6 * max|y| is an InputError (select a data
    window, e.g. strain > 0.05 as the needle-indentation study does). With
    ``relative_floor`` set, the divisor is instead sign(y) * max(|y|, relative_floor),
    documented in the result's ``objective``.

    Args:
        model: Predictions, ``model(p) -> (m,)``; may raise :class:`RejectStep`.
        p0: Initial parameters, shape (n,).
        y_data: Measured values, shape (m,).
        objective: "absolute" or "relative".
        weights: Positive weights, shape (m,) (default 1).
        jac: d model / d p, ``jac(p) -> (m, n)``, or None for finite differences. The engine
            applies the weights and the relative scaling itself.
        bounds, method, x_scale, max_iterations, ftol, xtol, gtol, callback, progress, options: As
            in :func:`least_squares`.
        parameter_names, parameter_units: Names and SI units for the result.
        relative_floor: Smallest |y| used as a divisor for the relative objective, in the
            units of ``y``; None raises on near-zero data instead.

    Returns:
        The :class:`FitResult`, with ``fitted`` (model at the solution), ``r_squared`` and
        ``rmse`` of the fitted curve against the data (unweighted, in data units; R² is None
        for constant data), and the covariance of the parameters for the chosen objective.

    Raises:
        InputError: Invalid data, weights or objective, near-zero data with a relative
            objective, or a model that returns the wrong number of values.
    """
    y = np.asarray(y_data, dtype=np.float64).reshape(-1)
    if y.size == 0 or not np.all(np.isfinite(y)):
        raise InputError("y_data must be a non-empty array of finite numbers")
    factor = _residual_factor(y, weights, objective, relative_floor)

    def predictions(p: np.ndarray) -> np.ndarray:
        values = np.asarray(model(p), dtype=np.float64).reshape(-1)
        if values.size != y.size:
            raise InputError(
                f"the model returned {values.size} predictions for {y.size} data points"
            )
        return values

    def residual(p: np.ndarray) -> np.ndarray:
        return factor * (predictions(p) - y)

    def residual_jacobian(p: np.ndarray) -> np.ndarray:
        return factor[:, None] * np.asarray(jac(p), dtype=np.float64)

    result = least_squares(
        residual,
        p0,
        jac=None if jac is None else residual_jacobian,
        bounds=bounds,
        method=method,
        x_scale=x_scale,
        max_iterations=max_iterations,
        ftol=ftol,
        xtol=xtol,
        gtol=gtol,
        callback=callback,
        progress=progress,
        parameter_names=parameter_names,
        parameter_units=parameter_units,
        options=options,
    )
    fitted = y + result.residuals / factor
    result.fitted = fitted
    result.objective = objective
    result.rmse = rmse(y, fitted)
    try:
        result.r_squared = r_squared(y, fitted)
    except InputError:
        result.r_squared = None
    return result
