"""Tests of warptissue.fit's least-squares engine (LM and self-adapting LM).

References: the test problems of More, Garbow & Hillstrom (1981, ACM TOMS 7, 17-41) with their
published minima, scipy.optimize.least_squares(method="lm") (MINPACK), and
scipy.optimize.curve_fit for the parameter covariance.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.optimize
from fit_problems import (
    PROBLEMS,
    freudenstein_roth,
    meyer,
    rosenbrock,
    rosenbrock_jacobian,
)

from warptissue.errors import ConvergenceError, InputError
from warptissue.lsq import STATUS_MESSAGES, FitResult, RejectStep, fit_curve, least_squares

METHODS = ("lm", "salm")


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", sorted(PROBLEMS))
def test_more_garbow_hillstrom(name, method):
    problem = PROBLEMS[name]
    fun, x0, f_min, x_min = problem.residuals, problem.x0, problem.minimum, problem.minimizer
    result = least_squares(
        fun, x0, method=method, max_iterations=3000, ftol=1e-12, xtol=1e-12, gtol=1e-12
    )
    reference = scipy.optimize.least_squares(
        fun, x0, method="lm", ftol=1e-12, xtol=1e-12, gtol=1e-12, max_nfev=20000
    )
    assert result.success, result.message
    f = 2.0 * result.cost
    if f_min == 0.0:
        assert f < 1e-16
    else:
        assert f == pytest.approx(f_min, rel=1e-5)
        assert f == pytest.approx(2.0 * reference.cost, rel=1e-8)
    if name == "powell_singular":
        # Singular Jacobian at the minimum: x converges only like f**(1/4).
        np.testing.assert_allclose(result.x, x_min, atol=1e-4)
    else:
        np.testing.assert_allclose(result.x, x_min, rtol=1e-5, atol=1e-8)
        np.testing.assert_allclose(result.x, reference.x, rtol=1e-5, atol=1e-8)
    assert np.all(np.isfinite(result.residuals))


@pytest.mark.parametrize("method", METHODS)
def test_freudenstein_roth_global_minimum_from_a_nearby_start(method):
    result = least_squares(freudenstein_roth, [6.0, 3.0], method=method, gtol=1e-12)
    np.testing.assert_allclose(result.x, [5.0, 4.0], rtol=1e-7)


@pytest.mark.parametrize("method", METHODS)
def test_analytic_and_finite_difference_jacobians_agree(method):
    analytic = least_squares(rosenbrock, [-1.2, 1.0], jac=rosenbrock_jacobian, method=method)
    numeric = least_squares(rosenbrock, [-1.2, 1.0], method=method)
    np.testing.assert_allclose(analytic.x, [1.0, 1.0], rtol=1e-7)
    np.testing.assert_allclose(numeric.x, [1.0, 1.0], rtol=1e-7)
    assert analytic.nfev < numeric.nfev
    np.testing.assert_allclose(numeric.jacobian, rosenbrock_jacobian(numeric.x), atol=1e-5)


def exponential_data(rng):
    t = np.linspace(0.0, 4.0, 40)
    y = 3.0 * np.exp(-1.3 * t) + 0.5 + rng.normal(0.0, 0.03, t.size)
    return t, y


def exponential(t, a, b, c):
    return a * np.exp(-b * t) + c


@pytest.mark.parametrize("method", METHODS)
def test_covariance_matches_curve_fit(rng, method):
    t, y = exponential_data(rng)
    popt, pcov = scipy.optimize.curve_fit(exponential, t, y, p0=[1.0, 1.0, 0.0])

    def jac(p):
        e = np.exp(-p[1] * t)
        return np.column_stack([e, -p[0] * t * e, np.ones_like(t)])

    result = fit_curve(
        lambda p: exponential(t, *p), [1.0, 1.0, 0.0], y, jac=jac, method=method, gtol=1e-12
    )
    np.testing.assert_allclose(result.x, popt, rtol=1e-6)
    np.testing.assert_allclose(result.covariance, pcov, rtol=1e-5)
    np.testing.assert_allclose(result.standard_errors, np.sqrt(np.diag(pcov)), rtol=1e-5)
    correlation = pcov / np.outer(np.sqrt(np.diag(pcov)), np.sqrt(np.diag(pcov)))
    np.testing.assert_allclose(result.correlation, correlation, rtol=1e-5, atol=1e-9)
    fitted = exponential(t, *popt)
    r2 = 1.0 - np.sum((y - fitted) ** 2) / np.sum((y - y.mean()) ** 2)
    assert result.r_squared == pytest.approx(r2, rel=1e-9)
    assert result.rmse == pytest.approx(np.sqrt(np.mean((y - fitted) ** 2)), rel=1e-6)


def test_relative_objective_matches_curve_fit_with_sigma_equal_to_data(rng):
    t, y = exponential_data(rng)
    popt, pcov = scipy.optimize.curve_fit(exponential, t, y, p0=[1.0, 1.0, 0.0], sigma=y)
    result = fit_curve(
        lambda p: exponential(t, *p), [1.0, 1.0, 0.0], y, objective="relative", gtol=1e-12
    )
    np.testing.assert_allclose(result.x, popt, rtol=1e-5)
    np.testing.assert_allclose(result.covariance, pcov, rtol=1e-4)
    np.testing.assert_allclose(result.residuals, (result.fitted - y) / y, rtol=1e-9)


def test_weights_match_curve_fit_sigma(rng):
    t, y = exponential_data(rng)
    sigma = np.linspace(0.02, 0.08, t.size)
    popt, pcov = scipy.optimize.curve_fit(exponential, t, y, p0=[1.0, 1.0, 0.0], sigma=sigma)
    result = fit_curve(lambda p: exponential(t, *p), [1.0, 1.0, 0.0], y, weights=1.0 / sigma)
    np.testing.assert_allclose(result.x, popt, rtol=1e-5)
    np.testing.assert_allclose(result.covariance, pcov, rtol=1e-4)


@pytest.mark.parametrize("method", METHODS)
def test_bounds_are_respected_and_match_scipy(method):
    t = np.linspace(0.0, 1.0, 20)
    y = -0.3 + 2.0 * t + 0.05 * np.sin(7.0 * t)
    seen = []

    def residuals(p):
        seen.append(p.copy())
        return p[0] + p[1] * t - y

    result = least_squares(
        residuals, [1.0, 1.0], bounds=([0.0, -np.inf], [5.0, 1.7]), method=method
    )
    reference = scipy.optimize.least_squares(
        residuals, [1.0, 1.0], bounds=([0.0, -np.inf], [5.0, 1.7]), method="trf", gtol=1e-12
    )
    np.testing.assert_allclose(result.x, reference.x, atol=1e-7)
    assert result.x[0] == 0.0  # the lower bound is active; projection lands on it exactly
    assert result.success
    seen_ours = np.array(seen[: result.nfev])
    assert np.all(seen_ours[:, 0] >= 0.0) and np.all(seen_ours[:, 1] <= 1.7)


def test_finite_differences_step_inward_at_a_bound():
    def residuals(p):
        if p[0] > 1.0:
            raise AssertionError("evaluated outside the bounds")
        return np.array([p[0] - 2.0, p[1] - 3.0])

    result = least_squares(residuals, [1.0, 0.0], bounds=([-np.inf, -np.inf], [1.0, np.inf]))
    np.testing.assert_allclose(result.x, [1.0, 3.0], atol=1e-10)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("refusal", ["raise", "nan"])
def test_refused_trial_points_are_damped_and_the_fit_recovers(method, refusal):
    calls = {"count": 0}

    def residuals(x):
        calls["count"] += 1
        if 2 <= calls["count"] <= 4:
            if refusal == "raise":
                raise RejectStep("FE did not converge")
            return np.array([np.nan, 0.0])
        return rosenbrock(x)

    result = least_squares(residuals, [-1.2, 1.0], jac=rosenbrock_jacobian, method=method)
    np.testing.assert_allclose(result.x, [1.0, 1.0], rtol=1e-7)
    refused = result.history[:3]
    assert all(not r.accepted and r.trial_cost is None and r.ratio is None for r in refused)
    steps = [r.step_norm for r in refused]
    assert steps[0] > steps[1] > steps[2]
    assert np.all(np.isfinite(result.x)) and np.isfinite(result.cost)


def test_a_model_undefined_at_x0_is_an_input_error():
    def residuals(x):
        raise RejectStep

    with pytest.raises(InputError, match="not defined"):
        least_squares(residuals, [1.0])
    with pytest.raises(InputError, match="not defined"):
        least_squares(lambda x: np.array([np.inf, 1.0]), [1.0])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"method": "bfgs"}, "method"),
        ({"bounds": ([2.0, 0.0], [3.0, 5.0])}, "outside the bounds"),
        ({"bounds": (1.0, 1.0)}, "below its upper"),
        ({"x_scale": [1.0, -1.0]}, "x_scale"),
        ({"max_iterations": 0}, "max_iterations"),
        ({"gtol": -1.0}, "gtol"),
        ({"parameter_names": ["a"]}, "parameter_names"),
        ({"options": {"damping": 1.0}}, "unknown option"),
        ({"method": "salm", "options": {"eta0": 1e-9}}, "eta0 > c"),
    ],
)
def test_invalid_arguments(kwargs, match):
    with pytest.raises(InputError, match=match):
        least_squares(rosenbrock, [-1.2, 1.0], **kwargs)


def test_relative_objective_rejects_zero_data_unless_floored():
    data = np.array([0.0, 1.0, 2.0])
    with pytest.raises(InputError, match="index 0"):
        fit_curve(lambda p: p[0] * np.arange(3.0), [1.0], data, objective="relative")
    result = fit_curve(
        lambda p: p[0] * np.arange(3.0), [3.0], data, objective="relative", relative_floor=0.1
    )
    assert result.x[0] == pytest.approx(1.0, rel=1e-8)


@pytest.mark.parametrize("method", METHODS)
def test_iteration_limit_callback_and_history(method):
    limited = least_squares(meyer, [0.02, 4000.0, 250.0], method=method, max_iterations=5)
    assert limited.status == 0 and not limited.success
    assert limited.iterations == 5 and len(limited.history) == 5
    assert limited.message == STATUS_MESSAGES[0]

    seen = []

    def stop_after_three(record):
        seen.append(record)
        return len(seen) >= 3

    stopped = least_squares(rosenbrock, [-1.2, 1.0], method=method, callback=stop_after_three)
    assert stopped.status == -1 and len(stopped.history) == 3
    costs = [r.cost for r in stopped.history]
    assert costs == sorted(costs, reverse=True)
    assert stopped.cost == costs[-1]


def test_progress_bar_runs(capsys):
    result = least_squares(rosenbrock, [-1.2, 1.0], progress=True)
    assert result.success


def test_result_dict_is_json_and_has_the_agreed_keys(rng):
    t, y = exponential_data(rng)
    result = fit_curve(
        lambda p: exponential(t, *p),
        [1.0, 1.0, 0.0],
        y,
        parameter_names=["amplitude_N", "rate_per_s", "offset_N"],
        parameter_units=["N", "1/s", "N"],
    )
    assert isinstance(result, FitResult)
    summary = json.loads(json.dumps(result.to_dict(include_history=True)))
    assert set(summary["parameters"]) == {"amplitude_N", "rate_per_s", "offset_N"}
    assert summary["parameters"]["rate_per_s"]["unit"] == "1/s"
    assert summary["parameters"]["rate_per_s"]["standard_error"] > 0.0
    for key in ("r_squared", "rmse", "iterations", "status", "message", "software", "history"):
        assert key in summary
    assert "rate_per_s" in result.summary()


def test_rank_deficient_jacobian_gives_no_covariance_instead_of_nan():
    t = np.linspace(0.0, 1.0, 10)
    result = fit_curve(lambda p: (p[0] + p[1]) * t, [1.0, 1.0], 3.0 * t)
    assert result.covariance is None and result.standard_errors is None
    assert result.x.sum() == pytest.approx(3.0, rel=1e-8)
    json.dumps(result.to_dict())


@pytest.mark.parametrize("method", METHODS)
def test_x_scale_sets_the_damping_scale(method):
    problem = PROBLEMS["brown_badly_scaled"]
    result = least_squares(
        problem.residuals, problem.x0, method=method, x_scale=[1e6, 1e-6], gtol=1e-12
    )
    np.testing.assert_allclose(result.x, problem.minimizer, rtol=1e-9)


def test_a_jacobian_failure_mid_fit_returns_the_best_point_with_status_minus_3():
    calls = {"count": 0}

    def jacobian(x):
        calls["count"] += 1
        if calls["count"] == 3:
            raise RejectStep("sensitivity solve failed")
        return rosenbrock_jacobian(x)

    result = least_squares(rosenbrock, [-1.2, 1.0], jac=jacobian)
    assert result.status == -3 and not result.success
    assert result.covariance is None
    accepted = [r for r in result.history if r.accepted]
    assert len(accepted) == 2 and np.array_equal(result.x, accepted[-1].x)
    assert result.cost < 0.5 * float(np.sum(rosenbrock(np.array([-1.2, 1.0])) ** 2))


def test_a_jacobian_failure_at_x0_raises():
    with pytest.raises(ConvergenceError):
        least_squares(rosenbrock, [-1.2, 1.0], jac=lambda x: np.full((2, 2), np.inf))


def _line_data(rng, slope, noise):
    t = np.linspace(0.0, 1.0, 40)
    return t, slope * t + 3.0 + noise * rng.standard_normal(t.size)


def test_a_well_determined_fit_is_identified(rng):
    t, y = _line_data(rng, 2.0, 0.01)
    result = fit_curve(lambda p: p[0] * t + p[1], [1.0, 0.0], y, parameter_names=("a", "b"))
    assert result.identified
    assert result.identifiability == []
    summary = result.to_dict()
    assert summary["identified"] is True
    assert summary["identifiability"] == [] and summary["warnings"] == []
    assert "warning:" not in result.summary()
    assert "parameters identified: yes" in result.summary()


def test_a_parameter_pinned_at_a_bound_is_not_identified(rng):
    t, y = _line_data(rng, -2.0, 0.01)  # the data want a negative slope; the bound says >= 0
    result = fit_curve(
        lambda p: p[0] * t + p[1],
        [1.0, 0.0],
        y,
        bounds=([0.0, -np.inf], [np.inf, np.inf]),
        parameter_names=("slope_N_per_m", "offset_N"),
        parameter_units=("N/m", "N"),
    )
    assert result.success  # the engine converged, and yet:
    assert not result.identified
    (message,) = result.identifiability
    assert message.startswith("slope_N_per_m = 0 N/m is pinned at its lower bound")
    assert "warning: slope_N_per_m = 0 N/m is pinned" in result.summary()
    assert "parameters identified: NO (1 finding(s))" in result.summary(warnings=False)
    assert json.loads(json.dumps(result.to_dict()))["identified"] is False


def test_a_standard_error_larger_than_the_value_is_reported(rng):
    t, y = _line_data(rng, 0.0, 0.5)  # no slope in the data, only noise
    result = fit_curve(lambda p: p[0] * t + p[1], [1.0, 0.0], y, parameter_names=("a", "b"))
    assert result.standard_errors[0] > abs(result.x[0])
    (message,) = result.identifiability
    assert message.startswith("a = ") and "larger than its value" in message
    assert "np.float64" not in message


def test_a_singular_covariance_is_reported():
    t = np.linspace(0.0, 1.0, 20)
    result = fit_curve(lambda p: p[0] * p[1] * t, [1.0, 1.0], 3.0 * t)
    assert result.covariance is None
    assert "singular" in result.identifiability[0]
    assert not result.to_dict()["identified"]


def test_too_few_data_for_the_parameters_is_reported():
    result = fit_curve(lambda p: p[0] + p[1] * np.array([0.0, 1.0]), [0.0, 0.0], [1.0, 2.0])
    assert result.identifiability == [
        "only 2 residuals for 2 parameters: the covariance is undefined and the parameters "
        "are not identified"
    ]


def test_a_parameter_within_one_standard_error_of_a_non_zero_bound_is_reported():
    t = np.linspace(0.0, 1.0, 40)
    y = 1.2 * t + 1.0 + 0.5 * (-1.0) ** np.arange(t.size)  # slope 1.2 +- 0.28
    result = fit_curve(
        lambda p: p[0] * t + p[1],
        [2.0, 1.0],
        y,
        bounds=([1.0, -np.inf], [np.inf, np.inf]),
        parameter_names=("a", "b"),
    )
    assert result.x[0] > 1.0
    (message,) = result.identifiability
    assert "within one standard error" in message and "lower bound 1:" in message


def test_caller_warnings_follow_the_identifiability_warnings(rng):
    t, y = _line_data(rng, 2.0, 0.01)
    result = fit_curve(lambda p: p[0] * t + p[1], [1.0, 0.0], y)
    result.warnings.append("the force is negative")
    assert result.identified
    assert result.to_dict()["warnings"] == ["the force is negative"]
    assert result.summary().endswith("warning: the force is negative")
