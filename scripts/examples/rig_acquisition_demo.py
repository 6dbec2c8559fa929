"""Reproduce the numbers of the README's "Indentation rig" section.

Runs the simulated rig over a pty, records a ramp-and-hold ex vivo and in vivo, conditions
the records, fits a standard linear solid (warptissue.viscoelastic.fit_relaxation), and
reports the rig model's flat band, bandwidth and a fit to a simulated sine sweep. Prints a
JSON summary.

    python scripts/examples/rig_acquisition_demo.py [--out runs/rig-demo] [--quick]

``--quick`` records the in vivo ramp-and-hold at one phase of the breath instead of six
(about 15 s instead of 50 s on a 2-core CPU).
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from warptissue.acquisition import (
    PhysiologicalDisturbance,
    RampHold,
    Recorder,
    RigClient,
    RigConfig,
    RigServer,
    SimulatedRig,
)
from warptissue.acquisition.conditioning import prepare_record
from warptissue.acquisition.rig_dynamics import (
    KIM_RIG,
    fit_rig_dynamics,
    measure_frequency_response,
    plot_frequency_response,
)
from warptissue.io import read_experiment_csv, to_jsonable
from warptissue.viscoelastic import StandardLinearSolid, fit_relaxation

TRUE = (40.0, 20.0, 2.0)


def fit_sls(time_s, displacement_m, force_N) -> np.ndarray:
    """SLS parameters (k0, k_inf, tau) from warptissue.viscoelastic.fit_relaxation."""
    result = fit_relaxation(time_s, displacement_m, force_N, model="sls")
    return np.asarray(result.x, dtype=np.float64)


def acquire(path: Path, config: RigConfig, test: RampHold, *, zero: bool) -> dict:
    rig = SimulatedRig(StandardLinearSolid(*TRUE), config)
    start = time.perf_counter()
    with RigServer(rig, transport="pty") as server, RigClient(server.url) as client:
        if zero:  # not in vivo: a tare would freeze one instant of breathing into the offset
            client.zero_force()
        result = Recorder(client, path, progress=False, overwrite=True).record(test)
    wall = time.perf_counter() - start
    return {"samples": result.samples_received, "wall_s": wall, "status": result.status}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default=None, help="folder for the records (default: temp)")
    parser.add_argument("--quick", action="store_true", help="one in vivo phase instead of six")
    args = parser.parse_args()
    out = Path(args.out or tempfile.mkdtemp(prefix="rig-demo-"))
    summary: dict = {
        "true_sls": dict(zip(("k0_N_per_m", "k_inf_N_per_m", "tau_s"), TRUE, strict=True))
    }

    ex_vivo = out / "ex_vivo.csv"
    config = RigConfig(time_scale=50.0, force_offset_N=5e-3, surface_position_m=0.3e-3)
    test = RampHold(depth_m=4e-3, speed_m_per_s=8e-3, hold_s=10.0, dwell_s=0.5)
    summary["ex_vivo_acquisition"] = acquire(ex_vivo, config, test, zero=True)
    prepared = prepare_record(read_experiment_csv(ex_vivo))
    fitted = fit_sls(prepared.time_s, prepared.displacement_m, prepared.force_N)
    summary["ex_vivo_fit_error_percent"] = 100 * (fitted / TRUE - 1)
    summary["ex_vivo_contact_m"] = prepared.contact.position_m

    disturbance = PhysiologicalDisturbance(
        respiration_amplitude_N=20e-3, heartbeat_amplitude_N=5e-3
    )
    test = RampHold(depth_m=4e-3, speed_m_per_s=8e-3, hold_s=10.0, dwell_s=10.0)
    worst: dict[str, float] = {}
    phases_s = (1.4,) if args.quick else (0.0, 0.7, 1.4, 2.1, 2.8, 3.5)
    for phase_s in phases_s:  # where in the breath the ramp starts
        in_vivo = out / f"in_vivo_{phase_s:.1f}s.csv"
        config = RigConfig(
            time_scale=math.inf,
            clock_start_s=phase_s,
            surface_position_m=0.0,
            disturbance=disturbance,
        )
        summary[f"in_vivo_{phase_s:.1f}s_acquisition"] = acquire(in_vivo, config, test, zero=False)
        record = read_experiment_csv(in_vivo)
        for label, rates in (("none", None), ("notch_known", (0.25, 1.4)), ("notch_auto", "auto")):
            prepared = prepare_record(record, contact_position_m=0.0, physiological_rates_Hz=rates)
            fitted = fit_sls(prepared.time_s, prepared.displacement_m, prepared.force_N)
            error = 100 * (fitted / TRUE - 1)
            summary[f"in_vivo_{phase_s:.1f}s_fit_error_percent_{label}"] = error
            worst[label] = max(worst.get(label, 0.0), float(np.max(np.abs(error))))
    summary["in_vivo_worst_error_percent"] = worst

    rig = KIM_RIG
    summary["rig_model"] = rig.to_dict()
    summary["rig_model"]["max_deviation_0_to_5_Hz"] = float(
        np.max(np.abs(rig.frequency_response(np.linspace(0.01, 5.0, 500)) - 1))
    )
    rng = np.random.default_rng(1)
    frequencies = np.geomspace(5.0, 400.0, 24)
    measured = []
    for frequency in frequencies:
        t = np.arange(0.0, max(0.6, 40.0 / frequency), 1.0 / (100.0 * frequency))
        force_in = np.sin(2 * np.pi * frequency * t)
        force_out = rig.simulate(t, force_in)
        force_out += rng.normal(0.0, 0.005 * np.std(force_out), t.size)
        steady = t > t[-1] / 2
        measured.append(
            measure_frequency_response(t[steady], force_in[steady], force_out[steady], frequency)
        )
    start = replace(
        rig,
        link_inertia_kg_m2=rig.link_inertia_kg_m2 * 1.4,
        link_stiffness_N_m_per_rad=rig.link_stiffness_N_m_per_rad * 0.7,
        link_damping_N_m_s_per_rad=rig.link_damping_N_m_s_per_rad * 1.4,
        contact_damping_N_m_s_per_rad=rig.contact_damping_N_m_s_per_rad * 0.6,
    )
    fit = fit_rig_dynamics(frequencies, np.array(measured), initial=start)
    summary["rig_fit_error_percent"] = {
        name: 100 * (getattr(fit.model, name) / getattr(rig, name) - 1)
        for name in fit.free_parameters
    }
    summary["rig_fit_flat_band_Hz"] = fit.model.flat_band_Hz()
    summary["bode_png"] = plot_frequency_response(
        out / "rig_bode.png", fit.model, frequency_Hz=frequencies, measured=np.array(measured)
    )
    summary["records"] = str(out)
    print(json.dumps(to_jsonable(summary), indent=2))


if __name__ == "__main__":
    main()
