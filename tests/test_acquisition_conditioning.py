"""Preparing records for fitting: contact, baseline, trimming, physiological suppression."""

from __future__ import annotations

import numpy as np
import pytest
from _sls_reference import ReferenceSLS

from warptissue.acquisition import PhysiologicalDisturbance
from warptissue.acquisition.conditioning import (
    detect_contact,
    estimate_rate_Hz,
    prepare_record,
    remove_offset_and_drift,
    select_window,
    suppress_physiological,
    trim_ramp,
)
from warptissue.acquisition.simulator import trapezoid_position
from warptissue.errors import InputError

RATE = 1000.0


def approach_record(rng, *, surface_m=0.3e-3, noise_N=0.3e-3, dwell_s=0.5, hold_s=2.0):
    """A ramp from 0 to 4 mm at 8 mm/s (200 mm/s^2) after a dwell, linear tissue 40 N/m."""
    time = np.arange(0.0, dwell_s + 0.54 + hold_s, 1.0 / RATE)
    position = trapezoid_position(time - dwell_s, 4e-3, 8e-3, 0.2)
    force = 40.0 * np.clip(position - surface_m, 0.0, None) + rng.normal(0, noise_N, time.size)
    return time, position, force


def test_detect_contact_on_a_noisy_approach(rng):
    time, position, force = approach_record(rng)
    contact = detect_contact(time, position, force)
    # 40 seeds: bias -1.6 um, standard deviation 3.8 um at 0.3 mN noise (7.5 um of depth).
    assert contact.position_m == pytest.approx(0.3e-3, abs=12e-6)
    assert contact.noise_N == pytest.approx(0.3e-3, rel=0.2)
    assert position[contact.index] >= contact.position_m >= position[contact.index - 1]


def test_detect_contact_fails_clearly_without_contact(rng):
    time = np.arange(0.0, 1.0, 1e-3)
    position = np.clip(time - 0.2, 0, None) * 1e-3
    with pytest.raises(InputError, match="no contact"):
        detect_contact(time, position, rng.normal(0, 1e-4, time.size))


def test_offset_and_drift_from_both_sides_of_the_test():
    time = np.linspace(0.0, 10.0, 1001)
    load = np.where((time > 2) & (time < 8), 0.05 * np.sin(np.pi * (time - 2) / 6), 0.0)
    force = 3e-3 + 1e-4 * time + load
    unloaded = (time < 2) | (time > 8)
    corrected, offset, drift = remove_offset_and_drift(time, force, unloaded=unloaded)
    assert offset == pytest.approx(3e-3, rel=1e-9) and drift == pytest.approx(1e-4, rel=1e-9)
    np.testing.assert_allclose(corrected, load, atol=1e-12)
    # One side only: an offset, no drift (drift cannot be told from relaxation).
    _, offset, drift = remove_offset_and_drift(time, force, unloaded=time < 2)
    assert drift == 0.0 and offset == pytest.approx(np.mean(force[time < 2]))


def test_offset_under_breathing_uses_the_periodic_terms():
    time = np.arange(0.0, 3.0, 1e-3)  # less than one breath
    breathing = PhysiologicalDisturbance().force_N(time)
    force = 2e-3 + breathing
    unloaded = np.ones(time.size, dtype=bool)
    _, plain, _ = remove_offset_and_drift(time, force, unloaded=unloaded)
    _, periodic, _ = remove_offset_and_drift(
        time, force, unloaded=unloaded, periodic_rates_Hz=(0.25, 1.4), harmonics=2
    )
    assert abs(plain - 2e-3) > 2e-4
    assert periodic == pytest.approx(2e-3, abs=1e-9)


def test_trim_ramp_keeps_the_constant_speed_part_like_takacs_et_al(rng):
    """Takacs et al. keep the first 3.6 mm of a 4 mm ramp: the kept part is at constant speed,
    the deceleration is cut."""
    time, position, _ = approach_record(rng, surface_m=0.2e-3)
    keep = trim_ramp(position, contact_position_m=0.2e-3, keep_depth_m=3.6e-3)
    depth = position[keep] - 0.2e-3
    assert depth.min() >= 0 and depth.max() <= 3.6e-3 and depth.max() > 3.59e-3
    speed = np.gradient(position, time)[keep]
    np.testing.assert_allclose(speed[1:-1], 8e-3, rtol=1e-6)
    decelerating = np.gradient(position, time) < 8e-3 * 0.999
    assert not np.any(keep & decelerating & (position > 1e-3))


def test_notch_filter_commutes_with_a_linear_viscoelastic_specimen():
    """Filtering displacement and force alike keeps them an exact SLS pair: the SLS response
    to the filtered displacement equals the filtered force (to 0.5 % of the peak)."""
    time = np.arange(0.0, 30.0, 1e-3)
    displacement = trapezoid_position(time - 10.0, 4e-3, 8e-3, 0.2)
    sls = ReferenceSLS(40.0, 20.0, 2.0)
    force = sls.force_N(time, displacement)
    filtered_x, filtered_f = suppress_physiological(
        time, displacement, force, rates_Hz=(0.25, 1.4), harmonics=3
    )
    assert np.max(np.abs(filtered_x - displacement)) > 1e-5  # the filter does change it
    np.testing.assert_allclose(sls.force_N(time, filtered_x), filtered_f, atol=5e-3 * force.max())


def test_notch_filter_removes_breathing_and_heartbeat(rng):
    time = np.arange(0.0, 30.0, 1e-3)
    disturbance = PhysiologicalDisturbance().force_N(time)
    trend = 0.05 * (1 - np.exp(-time / 20.0))
    _, filtered = suppress_physiological(
        time, np.zeros_like(time), trend + disturbance, rates_Hz=(0.25, 1.4)
    )
    inner = (time > 8) & (time < 22)
    residual = filtered - trend
    assert np.std(residual[inner]) < 0.03 * np.std(disturbance[inner])
    assert np.max(np.abs(residual)) < 0.25 * np.ptp(disturbance)


def test_estimate_rate(rng):
    time = np.arange(0.0, 12.0, 1e-3)
    signal = PhysiologicalDisturbance().force_N(time) + rng.normal(0, 3e-4, time.size)
    assert estimate_rate_Hz(time, signal, (0.1, 0.7)) == pytest.approx(0.25, rel=0.01)
    assert estimate_rate_Hz(time, signal, (0.7, 3.0)) == pytest.approx(1.4, rel=0.01)


def test_prepare_record_keeps_raw_columns_and_logs_steps(rng):
    time, position, force = approach_record(rng)
    force = force + 4e-3
    record = {"time_s": time, "displacement_m": position, "force_N": force, "sequence": time}
    prepared = prepare_record(record, keep_depth_m=3.6e-3)
    assert prepared.force_offset_N == pytest.approx(4e-3, abs=1e-4)
    assert prepared.displacement_m.max() <= 3.6e-3
    columns = prepared.columns()
    np.testing.assert_array_equal(columns["raw_force_N"], force)
    assert "raw_sequence" in columns and np.isnan(columns["force_N"]).any()
    assert any("contact detected" in step for step in prepared.steps)
    summary = prepared.summary()
    assert summary["samples_raw"] == time.size > summary["samples_kept"]
    window = select_window(time, start_s=1.0, stop_s=2.0)
    assert window.sum() == 1001
    with pytest.raises(InputError, match="displacement_m"):
        prepare_record({"time_s": time, "force_N": force})


def record_columns(rng, **changes):
    time, position, force = approach_record(rng)
    columns = {"time_s": time, "displacement_m": position, "force_N": force}
    return {**columns, **changes}


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"physiological_rates_Hz": "foo"}, 'must be "auto", rates in Hz or None'),
        ({"physiological_rates_Hz": (600.0,)}, "below 0.45 times the sample rate"),
        ({"physiological_rates_Hz": (0.25,), "quality": 0.0}, "quality must be a positive"),
        ({"physiological_rates_Hz": (0.25,), "harmonics": 0}, "harmonics must be a whole"),
        ({"threshold_sigma": -1.0}, "threshold_sigma must be a positive number"),
        ({"contact_position_m": 50e-3}, "contact_position_m is not above the deepest"),
        ({"keep_depth_m": 10e-3}, "keep_depth_m lies well below the deepest point"),
        ({"window_s": (100.0, 200.0)}, "no sample left: the record spans 0 to"),
    ],
)
def test_prepare_record_refuses_options_that_cannot_work(rng, options, message):
    """Each was silently accepted (a notch above the Nyquist rate skipped, a window or a
    depth outside the record kept nothing or everything, a contact below the record made
    the whole force the offset) or raised a bare ValueError / ZeroDivisionError."""
    with pytest.raises(InputError, match=message):
        prepare_record(record_columns(rng), **options)


def test_prepare_record_names_a_non_finite_value(rng):
    time, position, force = approach_record(rng)
    force[100] = np.nan
    with pytest.raises(InputError, match=r"column 'force_N': not a finite number at sample 100"):
        prepare_record({"time_s": time, "displacement_m": position, "force_N": force})


def test_a_force_that_only_falls_is_said_to_have_the_wrong_sign(rng):
    """Compression recorded as negative: not 'the force never leaves the baseline'."""
    time, position, force = approach_record(rng)
    with pytest.raises(InputError, match="falls below the pre-contact baseline"):
        prepare_record({"time_s": time, "displacement_m": position, "force_N": -force})
