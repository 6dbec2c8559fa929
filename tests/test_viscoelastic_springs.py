"""Kim et al.'s Blatz law and parallel nonlinear springs against closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.viscoelastic import ParallelNonlinearSprings, blatz_pressure_Pa, fit_blatz


def test_blatz_small_strain_slope_is_three_gamma():
    h = 1e-6
    slope = (
        blatz_pressure_Pa(1 + h, alpha=2.5, gamma_Pa=700.0)
        - blatz_pressure_Pa(1 - h, alpha=2.5, gamma_Pa=700.0)
    ) / (2 * h)
    assert blatz_pressure_Pa(1.0, alpha=2.5, gamma_Pa=700.0) == pytest.approx(0.0, abs=1e-12)
    assert slope == pytest.approx(3 * 700.0, rel=1e-8)


def test_blatz_matches_eq3_term_by_term():
    lam, alpha, gamma = 0.8, 1.0, 2.0
    expected = gamma / 2 * (0.8 * np.exp(-0.36) - np.exp(0.25) / 0.64)
    assert blatz_pressure_Pa(lam, alpha=alpha, gamma_Pa=gamma) == pytest.approx(expected)


def test_fit_blatz_recovers_parameters(rng):
    stretch = np.linspace(0.6, 0.99, 40)
    truth = blatz_pressure_Pa(stretch, alpha=3.0, gamma_Pa=1.2e3)
    noisy = truth + rng.normal(0, 1e-3 * np.abs(truth).max(), truth.size)
    result = fit_blatz(stretch, noisy)
    assert result.parameters["alpha"] == pytest.approx(3.0, rel=0.03)
    assert result.parameters["gamma_Pa"] == pytest.approx(1.2e3, rel=0.03)


def test_parallel_springs_linear_branch_step_matches_closed_form():
    # k_j2 = 1: a'' + a' + k a = k x. After a step X,
    # a = X (1 - (s2 exp(s1 t) - s1 exp(s2 t)) / (s2 - s1)), s1, s2 the roots of s^2 + s + k.
    k1, k3, depth_mm = 0.025, 0.007, 3.0
    model = ParallelNonlinearSprings(0.002, 1.6797, ((k1, 1.0, k3),))
    time = np.linspace(0.0, 60.0, 601)
    force = model.force_N(time, np.full(time.size, depth_mm * 1e-3))
    s1, s2 = np.roots([1.0, 1.0, k1])
    position = depth_mm * (1 - (s2 * np.exp(s1 * time) - s1 * np.exp(s2 * time)) / (s2 - s1))
    expected = 0.002 * depth_mm**1.6797 + k3 * (depth_mm - position)
    np.testing.assert_allclose(force, expected, rtol=1e-6)


def test_parallel_springs_kim_et_al_liver_relaxes_to_static_spring():
    liver = ParallelNonlinearSprings(
        0.0020, 1.6797, ((0.0250, 2.2355, 0.0070), (0.080, 2.1838, 0.0005))
    )
    time = np.linspace(0.0, 400.0, 2001)
    depth = 4e-3 * np.minimum(time / 0.5, 1.0)
    force = liver.force_N(time, depth)
    assert force.argmax() == np.searchsorted(time, 0.5)  # peak at the end of the ramp
    static = 0.0020 * 4.0**1.6797  # F0(4 mm), in N
    assert np.all(np.diff(force[time > 0.5]) < 0)  # relaxes monotonically ...
    assert static < force[-1] < 1.01 * static  # ... toward the static spring (power-law tail)


def test_bad_spring_input():
    with pytest.raises(InputError):
        blatz_pressure_Pa(-0.5, alpha=1.0, gamma_Pa=1.0)
    with pytest.raises(InputError):
        ParallelNonlinearSprings(0.1, 1.0, ((1.0, 2.0),))
