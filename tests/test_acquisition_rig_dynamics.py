"""Kim et al. Eq. 1: the rig's two-mass model, checked against its equations of motion."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from warptissue.acquisition.rig_dynamics import (
    KIM_RIG,
    RigDynamics,
    fit_rig_dynamics,
    measure_frequency_response,
    plot_frequency_response,
)
from warptissue.errors import InputError

UNDAMPED = replace(KIM_RIG, link_damping_N_m_s_per_rad=0.0, contact_damping_N_m_s_per_rad=0.0)


def printed_eq1(s, Jm, Jl, kl, kc, N):
    """Kim et al. Eq. 1 exactly as printed."""
    return kl * kc / (Jm * Jl * s**4 + (Jm * kc + Jl * kl + N**2 * Jm * kl) * s**2 + kl * kc)


def test_undamped_model_is_the_printed_equation(rng):
    s = 1j * rng.uniform(1, 3000, 20) + rng.uniform(-50, 50, 20)
    numerator, denominator = UNDAMPED.transfer_function()
    ours = np.polyval(numerator, s) / np.polyval(denominator, s)
    expected = printed_eq1(s, 1.0e-5, 2.0e-3, 80.0, 4000.0, 6.0)
    np.testing.assert_allclose(ours, expected, rtol=1e-12)
    assert UNDAMPED.frequency_response(0.0) == pytest.approx(1.0)


def test_poles_are_the_natural_frequencies_of_the_mass_spring_system():
    _, denominator = UNDAMPED.transfer_function()
    poles = np.roots(denominator)
    pole_frequencies = np.sort(np.abs(poles.imag))[::2] / (2 * np.pi)
    np.testing.assert_allclose(pole_frequencies, UNDAMPED.natural_frequencies_Hz(), rtol=1e-9)


@pytest.mark.parametrize("frequency_Hz", [5.0, 30.0, 150.0, 400.0])
def test_transfer_function_matches_time_integration(frequency_Hz):
    """Integrate the equations of motion (M, C, K state space) under a sine and measure the
    steady gain and phase; they equal G(i w)."""
    step = 1.0 / (200.0 * frequency_Hz)
    time = np.arange(0.0, max(1.0, 60.0 / frequency_Hz), step)
    force_in = np.sin(2 * np.pi * frequency_Hz * time)
    force_out = KIM_RIG.simulate(time, force_in)
    steady = time > time[-1] / 2
    measured = measure_frequency_response(
        time[steady], force_in[steady], force_out[steady], frequency_Hz
    )
    expected = complex(KIM_RIG.frequency_response(frequency_Hz))
    assert abs(measured / expected - 1) < 2e-3


def test_kim_et_al_conclusion_flat_below_30_Hz_far_above_5_Hz_stimuli():
    rig = KIM_RIG
    flat = rig.flat_band_Hz()
    assert 30.0 <= flat <= 35.0
    # The definition holds on either side of the reported edge.
    below = rig.frequency_response(np.linspace(0.01, 0.999 * flat, 2000))
    assert np.all(np.abs(np.abs(below) - 1) <= 0.03)
    assert np.all(np.abs(np.degrees(np.angle(below))) <= 5.0)
    assert abs(abs(rig.frequency_response(1.01 * flat)) - 1) > 0.03
    # Over the 0-5 Hz stimuli the rig changes the force by less than 0.1 %.
    low = rig.frequency_response(np.linspace(0.01, 5.0, 200))
    assert np.max(np.abs(low - 1)) < 1e-3
    assert rig.natural_frequencies_Hz()[0] > 30 * 5.0
    bandwidth = rig.bandwidth_Hz()
    assert abs(rig.frequency_response(bandwidth)) == pytest.approx(1 / math.sqrt(2), rel=1e-6)
    assert bandwidth > rig.natural_frequencies_Hz()[0]


def test_fit_recovers_parameters_from_simulated_sine_sweep(rng, tmp_path):
    """Sine-by-sine sweep 5-400 Hz simulated by time integration, 0.5 % output noise, fit
    from a start 40 % off: the free parameters come back within 3 %."""
    truth = KIM_RIG
    frequencies = np.geomspace(5.0, 400.0, 24)
    measured = []
    for frequency in frequencies:
        step = 1.0 / (100.0 * frequency)
        time = np.arange(0.0, max(0.6, 40.0 / frequency), step)
        force_in = np.sin(2 * np.pi * frequency * time)
        force_out = truth.simulate(time, force_in)
        force_out += rng.normal(0.0, 0.005 * np.std(force_out), time.size)
        steady = time > time[-1] / 2
        measured.append(
            measure_frequency_response(time[steady], force_in[steady], force_out[steady], frequency)
        )
    start = replace(
        truth,
        link_inertia_kg_m2=truth.link_inertia_kg_m2 * 1.4,
        link_stiffness_N_m_per_rad=truth.link_stiffness_N_m_per_rad * 0.7,
        link_damping_N_m_s_per_rad=truth.link_damping_N_m_s_per_rad * 1.4,
        contact_damping_N_m_s_per_rad=truth.contact_damping_N_m_s_per_rad * 0.6,
    )
    fit = fit_rig_dynamics(frequencies, np.array(measured), initial=start)
    assert fit.success
    for name in fit.free_parameters:
        assert getattr(fit.model, name) == pytest.approx(getattr(truth, name), rel=0.03), name
        assert fit.standard_errors[name] < 0.05 * getattr(truth, name)
    assert fit.model.flat_band_Hz() == pytest.approx(truth.flat_band_Hz(), rel=0.02)
    report = fit.to_dict()
    assert report["parameters"]["link_stiffness_N_m_per_rad"]["unit"] == "N m/rad"
    png = plot_frequency_response(
        tmp_path / "bode.png", fit.model, frequency_Hz=frequencies, measured=np.array(measured)
    )
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_fit_of_parameters_the_response_cannot_tell_apart_says_so(rng):
    """A force-to-force response fixes four combinations: freeing every parameter (a common
    scale of the inertias and stiffnesses cancels) must be reported as not identified, in
    the result and its JSON; the default four come back identified."""
    import json

    from warptissue.acquisition.rig_dynamics import PARAMETER_UNITS
    from warptissue.io import to_jsonable

    frequencies = np.geomspace(5.0, 400.0, 24)
    noise = 1.0 + 0.005 * (rng.normal(size=24) + 1j * rng.normal(size=24))  # 0.5 %
    measured = KIM_RIG.frequency_response(frequencies) * noise
    start = replace(KIM_RIG, link_inertia_kg_m2=KIM_RIG.link_inertia_kg_m2 * 1.2)
    good = fit_rig_dynamics(frequencies, measured, initial=start)
    assert good.identified and good.to_dict()["warnings"] == []
    everything = fit_rig_dynamics(frequencies, measured, initial=start, free=tuple(PARAMETER_UNITS))
    assert not everything.identified
    report = json.loads(json.dumps(to_jsonable(everything.to_dict()), allow_nan=False))
    assert report["identified"] is False and report["warnings"]


def test_invalid_parameters_and_inputs_are_rejected():
    with pytest.raises(InputError, match="link_inertia"):
        replace(KIM_RIG, link_inertia_kg_m2=-1.0)
    with pytest.raises(InputError):
        fit_rig_dynamics([1.0, 2.0], [1.0], initial=KIM_RIG)
    with pytest.raises(InputError, match="unknown"):
        fit_rig_dynamics([1.0, 2.0], [1.0, 1.0], initial=KIM_RIG, free=("mass",))
    assert isinstance(KIM_RIG, RigDynamics)
