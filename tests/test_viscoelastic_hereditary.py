"""Tests of warptissue.viscoelastic._hereditary: exact hereditary integrals of exponential
kernels, against their closed forms and the plain recursion."""

from __future__ import annotations

import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.viscoelastic._hereditary import (
    BLOCK_DECAY,
    exponential_hereditary_states,
    validate_history,
)


def _ramp_hold(time_s: np.ndarray, rate: float, ramp_s: float, tau: float) -> np.ndarray:
    """q(t) of h(t) = rate * min(t, ramp_s): rate tau (1 - exp(-t/tau)) on the ramp, then
    that value decaying as exp(-(t - ramp_s)/tau)."""
    on_ramp = rate * tau * -np.expm1(-np.minimum(time_s, ramp_s) / tau)
    return on_ramp * np.exp(-np.maximum(time_s - ramp_s, 0.0) / tau)


@pytest.mark.parametrize("tau", [1e-4, 0.05, 1.4, 49.5, 1e4])
def test_ramp_and_hold_equals_its_closed_form(tau):
    """Non-uniform samples with the ramp's end among them; relaxation times from far below the
    spacing (sample by sample) through many blocks to one block."""
    rng = np.random.default_rng(7)
    ramp_s = 10.0
    time_s = np.unique(np.concatenate([[0.0, ramp_s], rng.uniform(0.0, 1000.0, 4000)]))
    rate = 2e-4
    history = rate * np.minimum(time_s, ramp_s)
    (states,) = exponential_hereditary_states(time_s, history, [tau])
    expected = _ramp_hold(time_s, rate, ramp_s, tau)
    np.testing.assert_allclose(states, expected, rtol=1e-11, atol=1e-15 * rate * ramp_s)


def test_equals_the_plain_recursion_on_random_histories():
    """q_{k+1} = exp(-dt/tau) q_k + r tau (1 - exp(-dt/tau)), sample by sample, on histories
    that load and unload, start with a jump, and span up to many BLOCK_DECAY relaxation
    times: equal to rounding (absolute, against the history's total variation)."""
    rng = np.random.default_rng(3)
    for _ in range(30):
        count = int(rng.integers(2, 2000))
        time_s = np.cumsum(rng.uniform(1e-4, rng.choice([0.01, 1.0, 50.0]), count))
        history = np.cumsum(rng.normal(0.0, 1e-4, count)) + rng.normal(0.0, 1e-3)
        taus = 10.0 ** rng.uniform(-3.0, 3.0, 3)
        states = exponential_hereditary_states(time_s, history, taus)
        variation = np.abs(np.diff(history)).sum() + abs(history[0])
        for tau, row in zip(taus, states, strict=True):
            dt = np.diff(time_s)
            decay, gain = np.exp(-dt / tau), np.diff(history) / dt * tau * -np.expm1(-dt / tau)
            plain = [history[0]]
            for a, b in zip(decay, gain, strict=True):
                plain.append(a * plain[-1] + b)
            assert np.max(np.abs(row - plain)) <= 1e-13 * variation


def test_a_record_of_many_blocks_is_summed_in_blocks():
    """The decay exponent grows past BLOCK_DECAY several times; no overflow, no NaN."""
    time_s = np.linspace(0.0, 6.0 * BLOCK_DECAY, 30_001)
    history = 1e-3 * np.sin(time_s)
    (states,) = exponential_hereditary_states(time_s, history, [1.0])
    assert np.all(np.isfinite(states)) and np.max(np.abs(states)) < 1e-3


def test_one_sample_holds_its_jump():
    states = exponential_hereditary_states(np.array([0.0]), np.array([2e-3]), [1.0, 2.0])
    np.testing.assert_array_equal(states, [[2e-3], [2e-3]])


def test_a_history_that_goes_back_in_time_is_refused():
    with pytest.raises(InputError, match="increase strictly"):
        validate_history([0.0, 1.0, 1.0], [0.0, 1e-3, 2e-3], name="displacement_m")
