"""Tests of warptissue.loading: ramp-and-hold, sine and measured depth-time histories."""

from __future__ import annotations

import math

import numpy as np
import pytest

from warptissue.errors import InputError
from warptissue.loading import quasi_static_depths, ramp_hold, resample_history, sine


def test_ramp_hold_ramps_at_the_speed_then_holds_in_log_time():
    times, depths = ramp_hold(
        max_depth_m=0.004, speed_m_per_s=0.008, hold_s=100.0, ramp_steps=8, hold_steps=12
    )
    assert times.shape == depths.shape == (20,)
    ramp_s = 0.5
    np.testing.assert_allclose(times[:8], ramp_s * np.arange(1, 9) / 8)
    np.testing.assert_allclose(depths[:8], 0.008 * times[:8])  # the speed
    np.testing.assert_allclose(depths[8:], 0.004)
    offsets = times[8:] - ramp_s
    assert offsets[0] == pytest.approx(ramp_s / 8)  # first hold step ~ a ramp step
    assert offsets[-1] == pytest.approx(100.0)
    ratios = offsets[1:] / offsets[:-1]
    np.testing.assert_allclose(ratios, ratios[0])  # geometric: equal steps in log time
    assert np.all(np.diff(times) > 0)


def test_ramp_hold_short_hold_and_no_hold():
    times, _ = ramp_hold(max_depth_m=1e-3, speed_m_per_s=1e-3, hold_s=0.5, hold_steps=10)
    assert np.all(np.diff(times) > 0) and times[-1] == pytest.approx(1.5)
    times, depths = ramp_hold(max_depth_m=1e-3, speed_m_per_s=1e-3, hold_s=0.0, ramp_steps=4)
    np.testing.assert_allclose(times, [0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(depths, [2.5e-4, 5e-4, 7.5e-4, 1e-3])


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("max_depth_m", 0.0),
        ("speed_m_per_s", -1.0),
        ("hold_s", float("nan")),
        ("ramp_steps", 0),
        ("hold_steps", 2.5),
        ("max_depth_m", True),
    ],
)
def test_ramp_hold_names_a_bad_argument(key, value):
    arguments = {"max_depth_m": 1e-3, "speed_m_per_s": 1e-3, "hold_s": 10.0}
    with pytest.raises(InputError) as info:
        ramp_hold(**{**arguments, key: value})
    assert info.value.key == key
    assert key in str(info.value)


def test_quasi_static_depths_even_and_in_equal_steps_of_the_contact_radius():
    """Even: d_max k / n. Contact radius: the Hertz radius a = sqrt(R* d) of a sphere
    (Johnson 1985, sec. 4.2) grows by a_max / n at every step, for any R*."""
    even = quasi_static_depths(max_depth_m=4e-4, steps=8)
    np.testing.assert_array_equal(even, [4e-4 * (k + 1) / 8 for k in range(8)])
    depths = quasi_static_depths(max_depth_m=4e-4, steps=8, spacing="contact_radius")
    assert depths.shape == (8,) and depths[-1] == 4e-4 and np.all(np.diff(depths) > 0.0)
    for reduced_radius in (1e-4, 2.3e-3):
        radii = np.sqrt(reduced_radius * depths)
        steps = np.diff(radii, prepend=0.0)
        np.testing.assert_allclose(steps, np.sqrt(reduced_radius * 4e-4) / 8, rtol=1e-12)
    # the last step is (2 n - 1) / n^2 of the depth: 15 / 64 here, against 1 / 8 even
    assert depths[-1] - depths[-2] == pytest.approx(4e-4 * 15 / 64, rel=1e-12)
    assert quasi_static_depths(max_depth_m=1e-3, steps=1, spacing="contact_radius") == [1e-3]


@pytest.mark.parametrize(
    ("key", "value"),
    [("max_depth_m", -1e-3), ("steps", 0), ("steps", 2.0), ("spacing", "square")],
)
def test_quasi_static_depths_names_a_bad_argument(key, value):
    arguments = {"max_depth_m": 1e-3, "steps": 4, "spacing": "contact_radius"}
    with pytest.raises(InputError) as info:
        quasi_static_depths(**{**arguments, key: value})
    assert info.value.key == key


def test_sine_ramps_to_the_preload_then_oscillates_about_it():
    times, depths = sine(
        preload_depth_m=1e-3,
        amplitude_m=2e-4,
        frequency_Hz=2.0,
        cycles=3,
        preload_s=1.0,
        preload_steps=4,
        steps_per_cycle=8,
    )
    assert times.shape == (4 + 24,)
    np.testing.assert_allclose(times[:4], [0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(depths[:4], [2.5e-4, 5e-4, 7.5e-4, 1e-3])
    expected = 1e-3 + 2e-4 * np.sin(2 * math.pi * 2.0 * (times[4:] - 1.0))
    np.testing.assert_allclose(depths[4:], expected, atol=1e-15)
    assert depths.max() == pytest.approx(1.2e-3) and depths[4:].min() == pytest.approx(0.8e-3)
    assert times[-1] == pytest.approx(1.0 + 3 / 2.0)
    assert np.all(np.diff(times) > 0)


def test_sine_refuses_an_amplitude_above_the_preload():
    with pytest.raises(InputError, match="amplitude_m.*leave the specimen") as info:
        sine(preload_depth_m=1e-3, amplitude_m=1.5e-3, frequency_Hz=1, cycles=1, preload_s=1)
    assert info.value.value == 1.5e-3
    with pytest.raises(InputError, match="cycles"):
        sine(preload_depth_m=1e-3, amplitude_m=1e-4, frequency_Hz=1, cycles=0, preload_s=1)


def ramp_hold_record(*, noise_m: float = 0.0, seed: int = 0):
    """A 1 kHz record: 8 mm/s ramp to 4 mm (0.5 s), hold to 100 s; t = 0 is the contact."""
    time = np.arange(-0.2, 100.0 + 1e-9, 0.001)
    depth = np.clip(0.008 * time, 0.0, 0.004)
    depth += np.random.default_rng(seed).normal(0.0, noise_m, time.size) if noise_m else 0.0
    return time, depth


@pytest.mark.parametrize("noise_m", [0.0, 2e-6])
def test_resample_ramp_hold_record_puts_steps_on_the_ramp_and_log_spaced_in_the_hold(noise_m):
    time, depth = ramp_hold_record(noise_m=noise_m)
    times, depths = resample_history(time, depth, steps=24)
    assert abs(times.size - 24) <= 1
    assert np.all(times > 0) and np.all(np.diff(times) > 0)
    assert times[-1] == pytest.approx(100.0)
    ramp = times[times < 0.5 - 0.005]
    hold = times[times > 0.5 + 0.005]
    assert 6 <= ramp.size <= 14  # the ramp is resolved...
    # ... and the knee is a step (to the record's sampling, 1 ms, where it is noisy).
    assert np.min(np.abs(times - 0.5)) <= (1e-12 if noise_m == 0 else 0.005)
    # The hold: every decade of time since the hold began (1-10 s, 10-100 s) gets steps,
    # as equal steps in log time would give (a linear grid would put 2 in the first).
    since = hold - 0.5
    assert np.count_nonzero((since > 1) & (since <= 10)) >= 3
    assert np.count_nonzero(since > 10) >= 3
    gaps = np.diff(np.log(since))
    assert gaps.max() < 3 * gaps.min()
    # The depths are the record's, interpolated (the noise-free depth where it is clean).
    np.testing.assert_allclose(depths, np.clip(0.008 * times, 0, 0.004), atol=8 * noise_m + 1e-12)


def test_resample_keeps_the_extremes_of_a_sine_record():
    time = np.linspace(0.0, 1.0 + 4 / 1.5, 20001)
    depth = np.where(
        time < 1.0, 1e-3 * time, 1e-3 + 3e-4 * np.sin(2 * math.pi * 1.5 * (time - 1.0))
    )
    times, depths = resample_history(time, depth, steps=48)
    assert np.all(times > 0) and np.all(np.diff(times) > 0)
    peaks = 1.0 + (0.25 + 0.5 * np.arange(8)) / 1.5  # every peak and trough of 4 cycles
    for peak in peaks:
        nearest = np.min(np.abs(times - peak))
        assert nearest <= 2 * (time[1] - time[0]), peak
    assert depths.max() == pytest.approx(1.3e-3, rel=1e-6)
    assert depths.min() == pytest.approx(1e-3 * times[0], rel=1e-6)
    # The piecewise-linear history through the steps (what the FE sees) follows the record
    # to a share of the amplitude (equal depth steps are coarse in time at the extremes).
    follows = np.interp(time, np.concatenate([[0], times]), np.concatenate([[0], depths]))
    assert np.max(np.abs(follows - depth)) < 0.2 * 3e-4


def test_resample_drops_samples_before_the_contact():
    time, depth = ramp_hold_record()
    times, _ = resample_history(time, depth, steps=10)
    assert times[0] > 0.0


@pytest.mark.parametrize(
    ("time", "depth", "steps", "key", "message"),
    [
        ([0.1, 0.2, 0.2], [0, 1e-4, 2e-4], 5, "time_s", "increase strictly"),
        ([0.1, 0.3, 0.2], [0, 1e-4, 2e-4], 5, "time_s", "increase strictly"),
        ([0.1, 0.2, 0.3], [0, float("nan"), 2e-4], 5, "depth_m", "finite"),
        ([0.1, float("nan"), 0.3], [0, 1e-4, 2e-4], 5, "time_s", "finite"),
        ([0.1], [1e-4], 5, "time_s", "at least 2"),
        ([-0.1, 0.0, 0.1], [0, 0, 1e-4], 5, "time_s", "after time 0"),
        ([0.1, 0.2, 0.3], [0, 1e-4], 5, "depth_m", "length"),
        ([0.1, 0.2, 0.3], [0, 1e-4, 2e-4], 1, "steps", "at least 2"),
        ([0.1, 0.2, 0.3], [0, 1e-4, 2e-4], 4.0, "steps", "integer"),
    ],
)
def test_resample_refuses_bad_input(time, depth, steps, key, message):
    with pytest.raises(InputError, match=message) as info:
        resample_history(time, depth, steps=steps)
    assert info.value.key == key
