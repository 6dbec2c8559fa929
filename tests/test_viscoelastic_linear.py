"""Linear lumped models against closed forms and independent ODE integration (scipy)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from warptissue.errors import InputError
from warptissue.viscoelastic import (
    NotARelaxationWarning,
    PronySeries,
    QuasiLinearViscoelastic,
    StandardLinearSolid,
    exponential_elastic_force,
)


def ramp_and_hold(ramp_time_s, depth_m, total_s, dt_s):
    time = np.arange(0.0, total_s + 0.5 * dt_s, dt_s)
    return time, depth_m * np.minimum(time / ramp_time_s, 1.0)


def test_sls_ramp_and_hold_matches_closed_form():
    sls = StandardLinearSolid(12.0, 5.0, 0.8)
    ramp_s, depth = 0.3, 2e-3
    # Irregular sampling that hits the ramp end exactly: the update is exact for any spacing.
    time = np.unique(np.concatenate([np.linspace(0, ramp_s, 7), np.geomspace(0.31, 6.0, 40)]))
    x = depth * np.minimum(time / ramp_s, 1.0)
    v, k_e, k_m, tau = depth / ramp_s, 5.0, 7.0, 0.8
    during = k_e * v * time + k_m * v * tau * (1 - np.exp(-time / tau))
    peak_arm = k_m * v * tau * (1 - np.exp(-ramp_s / tau))
    after = k_e * depth + peak_arm * np.exp(-(time - ramp_s) / tau)
    expected = np.where(time <= ramp_s, during, after)
    np.testing.assert_allclose(sls.force_N(time, x), expected, rtol=1e-12, atol=1e-15)


def test_prony_matches_ode_integration_for_smooth_input():
    prony = PronySeries(3.0, (4.0, 2.5), (0.2, 3.0))
    time = np.linspace(0.0, 5.0, 5001)
    amplitude, omega = 1e-3, 2.3

    def x_dot(t):
        return amplitude * (omega * np.cos(omega * t) + 0.4)

    def rhs(t, q):  # Maxwell-arm forces: dq_i/dt = k_i x' - q_i / tau_i
        k = np.array(prony.branch_stiffness_N_per_m)
        tau = np.array(prony.relaxation_times_s)
        return k * x_dot(t) - q / tau

    solution = solve_ivp(rhs, (0, 5), [0.0, 0.0], t_eval=time, rtol=1e-11, atol=1e-14)
    x = amplitude * (np.sin(omega * time) + 0.4 * time)
    expected = prony.equilibrium_stiffness_N_per_m * x + solution.y.sum(axis=0)
    # Piecewise-linear sampling of a smooth input: O(dt^2) difference only.
    np.testing.assert_allclose(prony.force_N(time, x), expected, rtol=0, atol=1e-8)


def test_step_at_first_sample_gives_relaxation_function():
    prony = PronySeries(1.0, (2.0, 3.0), (0.5, 4.0))
    time = np.linspace(0, 10, 101)
    force = prony.force_N(time, np.full_like(time, 2e-3))
    np.testing.assert_allclose(force, 2e-3 * prony.relaxation_N_per_m(time), rtol=1e-13)


def test_prony_normalized_round_trip_ahn_kim_table1():
    # Ahn & Kim Table 1, experiment 1; Eq. 6 (g_i = k_i / G0), Eq. 5 with the sign fixed.
    prony = PronySeries.from_normalized(100.0, (0.348, 0.358), (1.376, 49.369))
    assert prony.instantaneous_stiffness_N_per_m == pytest.approx(100.0)
    assert prony.g == pytest.approx((0.348, 0.358))
    assert prony.equilibrium_stiffness_N_per_m == pytest.approx(100.0 * (1 - 0.348 - 0.358))
    t = np.array([0.0, 1.0, 30.0, 1e4])
    eq5 = 100.0 * (1 - 0.348 * (1 - np.exp(-t / 1.376)) - 0.358 * (1 - np.exp(-t / 49.369)))
    np.testing.assert_allclose(prony.relaxation_N_per_m(t), eq5, rtol=1e-14)


def test_from_printed_reproduces_eq4_and_warns():
    k1, k2, b = 8.0, 7.0, 130.0  # Kim et al.: 0.008 N/mm, 0.007 N/mm, 0.130 s N/mm in SI
    with pytest.warns(NotARelaxationWarning):
        sls = StandardLinearSolid.from_printed(k1, k2, b)
    t = np.linspace(0, 0.5, 11)
    printed = k1 * (1 - (1 - k2 / k1) * np.exp(-(b / k1) * t))
    np.testing.assert_allclose(sls.relaxation_N_per_m(t), printed, rtol=1e-14)
    assert not sls.is_relaxation
    assert sls.to_printed() == pytest.approx({"k1_N_per_m": k1, "k2_N_per_m": k2, "b_N_s_per_m": b})
    with pytest.raises(InputError):
        sls.to_prony()


def test_sls_equals_one_term_prony():
    sls = StandardLinearSolid(9.0, 4.0, 1.5)
    time, x = ramp_and_hold(0.4, 1e-3, 5.0, 0.01)
    np.testing.assert_allclose(sls.force_N(time, x), sls.to_prony().force_N(time, x), rtol=1e-13)


def test_qlv_with_linear_elastic_is_prony_and_converges_for_nonlinear():
    g, tau = (0.3, 0.2), (0.5, 20.0)
    time, x = ramp_and_hold(1.0, 4e-3, 40.0, 0.05)
    linear = QuasiLinearViscoelastic(g, tau, lambda d: 250.0 * d)
    expected = PronySeries.from_normalized(250.0, g, tau).force_N(time, x)
    np.testing.assert_allclose(linear.force_N(time, x, substeps=1), expected, rtol=1e-12)

    def elastic(d):
        return exponential_elastic_force(d, scale_N=0.05, rate_per_m=600.0)

    qlv = QuasiLinearViscoelastic(g, tau, elastic)
    fine = qlv.force_N(time, x, substeps=64)
    error_4 = np.max(np.abs(qlv.force_N(time, x, substeps=4) - fine))
    error_8 = np.max(np.abs(qlv.force_N(time, x, substeps=8) - fine))
    assert error_4 < 1e-4 * np.max(fine)
    assert 3.0 < error_4 / error_8 < 5.0  # second order
    # The hold tail relaxes to (1 - sum g) F_e(depth) from an independent ODE integration.
    rhs_k = np.array(g)

    def rhs(t, q):
        rate = 4e-3 / 1.0 if t < 1.0 else 0.0
        slope = 0.05 * 600.0 * np.exp(600.0 * min(t, 1.0) * 4e-3)
        return rhs_k * slope * rate - q / np.array(tau)

    sol = solve_ivp(rhs, (0, 40), [0.0, 0.0], t_eval=time, rtol=1e-10, atol=1e-13, max_step=0.01)
    reference = (1 - sum(g)) * elastic(x) + sol.y.sum(axis=0)
    np.testing.assert_allclose(fine, reference, rtol=0, atol=2e-5 * np.max(fine))


@pytest.mark.parametrize(
    ("time", "x"),
    [([0.0, 1.0, 1.0], [0, 1, 2]), ([0.0, 1.0], [0.0, np.nan]), ([0.0, 1.0], [0.0])],
)
def test_bad_histories_are_rejected(time, x):
    with pytest.raises(InputError):
        StandardLinearSolid(2.0, 1.0, 1.0).force_N(np.array(time), np.array(x))


def test_bad_parameters_are_rejected():
    with pytest.raises(InputError, match="relaxation_time_s"):
        StandardLinearSolid(2.0, 1.0, 0.0)
    with pytest.raises(InputError):
        PronySeries(1.0, (1.0,), (1.0, 2.0))
    with pytest.raises(InputError):
        PronySeries.from_normalized(1.0, (0.7, 0.6), (1.0, 2.0))


def test_parameter_errors_name_the_parameter_and_print_plain_numbers():
    from warptissue.fit.punch import flat_punch_modulus_Pa
    from warptissue.viscoelastic import LinearWiechert

    for build in (
        lambda: StandardLinearSolid(np.float64(-1.0), 5.0, 1.0),
        lambda: LinearWiechert(1.0, 2.0, 3.0, 4.0, np.float64(-5.0)),
        lambda: flat_punch_modulus_Pa(0.01, 1e-4, radius_m=np.float64(-1e-3), poissons_ratio=0.3),
    ):
        with pytest.raises(InputError) as error:
            build()
        text = str(error.value)
        assert "np.float64" not in text and "column" not in text
        assert "(got -" in text
