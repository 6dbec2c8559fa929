"""Wiechert models: analytic responses vs scipy.signal and solve_ivp, the exponential-spring
step response vs its closed form through the exponential integral, distributed bodies."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal
from scipy.optimize import brentq
from scipy.special import exp1

from warptissue.errors import InputError
from warptissue.viscoelastic import (
    LinearWiechert,
    NonlinearWiechert,
    line_indenter_force_N,
    quadratic_profile,
)

LINEAR_TABLE_I = LinearWiechert(4.86, 57.81, 53.32, 9987.0, 10464.0)  # Takacs et al. Table I
NONLINEAR_TABLE_I = NonlinearWiechert(2.03, 0.438, 0.102, 5073.0, 39.24, 909.9, 1522.0, 81.18)


def test_transfer_function_limits_and_step_response_match_lsim():
    numerator, denominator = LINEAR_TABLE_I.transfer_function()
    k = LINEAR_TABLE_I
    assert numerator[-1] / denominator[-1] == pytest.approx(k.k0_N_per_m)  # W(0) = k0
    assert numerator[0] / denominator[0] == pytest.approx(k.k0_N_per_m + 57.81 + 53.32)
    system = signal.lti(numerator, denominator)
    time = np.linspace(0.0, 800.0, 4001)
    _, step = signal.step(system, T=time)
    np.testing.assert_allclose(LINEAR_TABLE_I.step_response_N(time, 1.0), step, rtol=1e-8)


def test_ramp_and_hold_matches_lsim_and_hereditary_integral():
    time = np.linspace(0.0, 600.0, 30001)
    rate, hold = 4e-3 / 12.0, 12.0  # 20 mm/min to 4 mm
    displacement = rate * np.minimum(time, hold)
    analytic = LINEAR_TABLE_I.ramp_response_N(time, rate, hold_after_s=hold)
    numerator, denominator = LINEAR_TABLE_I.transfer_function()
    _, simulated, _ = signal.lsim((numerator, denominator), displacement, time, interp=True)
    np.testing.assert_allclose(analytic, simulated, rtol=0, atol=1e-7 * analytic.max())
    np.testing.assert_allclose(
        LINEAR_TABLE_I.force_N(time, displacement), analytic, rtol=1e-11, atol=1e-15
    )


def test_nonlinear_with_zero_kappa_is_the_linear_model():
    linear = LinearWiechert(3.0, 40.0, 20.0, 80.0, 400.0)
    nonlinear = NonlinearWiechert(3.0, 40.0, 20.0, 80.0, 400.0, 0.0, 0.0, 0.0)
    time = np.linspace(0.0, 30.0, 1501)
    displacement = 2e-3 * np.minimum(time / 1.5, 1.0)
    np.testing.assert_allclose(
        nonlinear.force_N(time, displacement, rtol=1e-10),
        linear.force_N(time, displacement),
        rtol=0,
        atol=1e-7 * 0.14,
    )


@pytest.mark.parametrize("method", ["LSODA", "BDF", "Radau"])
def test_nonlinear_step_matches_exponential_integral_solution(method):
    # After a step to X, each arm's stretch d obeys d' = -(K/b) d exp(kappa d); since
    # d/dt E1(kappa d) = K/b, E1(kappa d(t)) = E1(kappa X) + (K/b) t, inverted with brentq.
    model, depth = NONLINEAR_TABLE_I, 4e-3
    time = np.linspace(0.0, 60.0, 301)
    force = model.force_N(time, np.full_like(time, depth), method=method, rtol=1e-10)

    def stretch(K, b, kappa, t):
        target = exp1(kappa * depth) + K / b * t
        return brentq(lambda d: exp1(kappa * d) - target, 1e-300, depth, xtol=1e-18, rtol=1e-14)

    expected = [
        model.K0_N_per_m * depth * np.exp(model.kappa0_per_m * depth)
        + sum(
            K * d * np.exp(kappa * d)
            for K, b, kappa in (
                (model.K1_N_per_m, model.b1_N_s_per_m, model.kappa1_per_m),
                (model.K2_N_per_m, model.b2_N_s_per_m, model.kappa2_per_m),
            )
            for d in [stretch(K, b, kappa, t)]
        )
        for t in time
    ]
    np.testing.assert_allclose(force, expected, rtol=1e-6)


def test_specific_parameters_follow_table_ii():
    specific = NONLINEAR_TABLE_I.scaled(1.0 / 4e-4)  # 20 x 20 mm sample
    assert specific.K0_N_per_m == pytest.approx(5075.0)
    assert specific.K1_N_per_m == pytest.approx(1095.0)
    assert specific.K2_N_per_m == pytest.approx(255.0)
    assert specific.b1_N_s_per_m == pytest.approx(12.68e6, rel=1e-3)  # Table II: 127e6 (ERRATA)
    assert specific.kappa1_per_m == NONLINEAR_TABLE_I.kappa1_per_m


def test_distributed_uniform_profile_equals_single_body():
    time = np.linspace(0.0, 20.0, 401)
    depth = 4e-3 * np.minimum(time / 2.0, 1.0)
    half_width, length = 10e-3, 20e-3
    specific = NONLINEAR_TABLE_I.scaled(1.0 / (2 * half_width * length))
    force = line_indenter_force_N(
        specific,
        time,
        depth,
        half_width_m=half_width,
        length_m=length,
        profile=lambda y, d: np.full(y.shape, d),
        element_count=3,
    )
    np.testing.assert_allclose(force, NONLINEAR_TABLE_I.force_N(time, depth), rtol=1e-5)


def test_distributed_quadratic_profile_for_linear_springs():
    # kappa = 0: F = L * integral_{-rho}^{rho} ((|y| - rho)/rho)^2 dy * f_s(x_d) = L 2 rho/3 f_s.
    specific = NonlinearWiechert(5000.0, 1000.0, 300.0, 2e5, 4e6, 0.0, 0.0, 0.0)
    rho, length = 16e-3, 30e-3
    time = np.linspace(0.0, 3.0, 151)
    depth = 6e-3 * np.minimum(time / 0.6, 1.0)  # 10 mm/s to 6 mm
    force = line_indenter_force_N(
        specific,
        time,
        depth,
        half_width_m=25e-3,  # wider than rho: the outer elements do not move
        length_m=length,
        profile=quadratic_profile(rho),
        element_count=200,
    )
    expected = length * 2 * rho / 3 * specific.force_N(time, depth)
    np.testing.assert_allclose(force, expected, rtol=2e-4)


def test_quadratic_profile_shape_eq6_eq7():
    profile = quadratic_profile(16e-3)
    y = np.array([-20e-3, -16e-3, -8e-3, 0.0, 8e-3, 16e-3])
    np.testing.assert_allclose(profile(y, 6e-3), [0, 0, 1.5e-3, 6e-3, 1.5e-3, 0], atol=1e-18)
    slope = (profile(np.array([16e-3 - 1e-7]), 6e-3) - 0.0) / 1e-7  # Eq. 7: zero at rho
    assert abs(slope[0]) < 1e-5


def test_bad_wiechert_input():
    with pytest.raises(InputError, match="b2_N_s_per_m"):
        LinearWiechert(1.0, 1.0, 1.0, 1.0, -1.0)
    with pytest.raises(InputError):
        quadratic_profile(0.0)
    with pytest.raises(InputError, match="profile"):
        line_indenter_force_N(
            NONLINEAR_TABLE_I,
            np.array([0.0, 1.0]),
            np.array([0.0, 1e-3]),
            half_width_m=1e-2,
            length_m=1e-2,
            profile=lambda y, d: np.ones(3),
        )
