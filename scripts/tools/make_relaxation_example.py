"""Generate the ramp-and-hold example records ``scenes/data/liver_ramp_*.csv`` (run from the root).

    python scripts/tools/make_relaxation_example.py [--out-dir scenes/data] [--quick]

Three flat-punch indentations of liver at three rates, made by the forward FE of
``scenes/liver_fit.toml`` (its mesh, probe and boundary) and written as the rig records them
(``time_s``, axis ``displacement_m`` from the start position, ``force_N``; positive into the
specimen): the probe rests for 2 s, moves 0.5 mm through air to the surface, indents 4 mm and
holds. The specimen is quasi-linear viscoelastic (:class:`warptissue.materials.Viscoelastic`):
neo-Hookean C10 = 287.5 Pa (K = 575 kPa, nearly incompressible) with Ahn & Kim's two-term
Prony series (Table 1, experiment 1: g1 = 0.348, g2 = 0.358, tau1 = 1.376 s,
tau2 = 49.369 s). The FE runs each history time-stepped from the contact
(:func:`warptissue.loading.ramp_hold`: equal steps on the ramp, log-spaced in the hold); the
force at each rig sample is the FE force interpolated linearly in time (below 0.1 mN of
interpolation error at these steps, half the noise). The transducer adds an offset of 3 mN
and seeded Gaussian noise of 0.2 mN.

- ``liver_ramp_hold.csv``: 8 mm/s ramp (0.5 s), 120 s hold, 50 Hz;
- ``liver_ramp_slow.csv``: 0.4 mm/s ramp (10 s), 60 s hold, 20 Hz;
- ``liver_ramp_medium.csv``: 2 mm/s ramp (2 s), 60 s hold, 20 Hz (to validate a joint fit).

Each has a JSON sidecar recording how it was made (``truth``: the FE material). The files are
generated, not hand-edited: change this script and re-run it (about a minute on two CPU
cores). ``--quick`` makes only the first record and writes its first 10 s (for the tests:
the same numbers as the shipped file). Fit them with::

    warptissue fit indentation scenes/liver_fit.toml
    warptissue fit relaxation scenes/data/liver_ramp_hold.csv --model prony:2 --contact auto
"""

from __future__ import annotations

import argparse
import dataclasses
import tomllib
from pathlib import Path

import numpy as np

from warptissue.io import write_csv, write_json
from warptissue.loading import ramp_hold
from warptissue.materials import Viscoelastic, material_from_dict
from warptissue.study import study_from_dict

STUDY = Path(__file__).resolve().parents[2] / "scenes" / "liver_fit.toml"
"""The study whose mesh, probe, boundary and solver make the records."""
C10_PA, BULK_MODULUS_PA = 287.5, 575e3
"""Ahn & Kim's C10 (Table 2); K = 1000 mu (nearly incompressible)."""
G, TAU_S = (0.348, 0.358), (1.376, 49.369)
"""Ahn & Kim, Table 1, experiment 1."""
AIR_M, DEPTH_M, REST_S = 0.5e-3, 4e-3, 2.0
OFFSET_N, NOISE_N, SEED = 3e-3, 2e-4, 20261125
QUICK_S = 10.0
"""``--quick`` writes the samples up to this time (s) of the first record."""
RAMP_STEPS, HOLD_STEPS = 16, 64
"""FE time steps of each record: equal on the ramp, log-spaced in the hold."""
RECORDS = {
    "liver_ramp_hold": {"speed_m_per_s": 8e-3, "hold_s": 120.0, "sample_rate_Hz": 50.0},
    "liver_ramp_slow": {"speed_m_per_s": 0.4e-3, "hold_s": 60.0, "sample_rate_Hz": 20.0},
    "liver_ramp_medium": {"speed_m_per_s": 2e-3, "hold_s": 60.0, "sample_rate_Hz": 20.0},
}


def specimen() -> Viscoelastic:
    """The FE material of the records: neo-Hookean with Ahn & Kim's Prony series."""
    elastic = material_from_dict(
        {"model": "neo_hookean", "C10_Pa": C10_PA, "bulk_modulus_Pa": BULK_MODULUS_PA}
    )
    return Viscoelastic(elastic, g=G, tau_s=TAU_S)


def forward_study():
    """``scenes/liver_fit.toml`` without its records and fit, with :func:`specimen`."""
    data = tomllib.loads(STUDY.read_text(encoding="utf-8"))
    for key in ("data", "fit"):
        data.pop(key, None)
    data["material"] = specimen().to_dict()
    study = study_from_dict(data, path=STUDY)
    return dataclasses.replace(study, material=specimen())


def fe_curve(
    study, mesh, *, speed_m_per_s: float, hold_s: float
) -> tuple[np.ndarray, np.ndarray, dict]:
    """The FE force of a ramp to DEPTH_M at ``speed_m_per_s`` and a hold, from the contact.

    Returns:
        ``(times_s, force_N, run)``: the FE step times (s, from the contact) and forces (N),
        shape (S,), with (0, 0) prepended; ``run`` describes the FE run.
    """
    from warptissue.fem import simulate_indentation
    from warptissue.simulate import build_problem

    times, depths = ramp_hold(
        max_depth_m=DEPTH_M,
        speed_m_per_s=speed_m_per_s,
        hold_s=hold_s,
        ramp_steps=RAMP_STEPS,
        hold_steps=HOLD_STEPS,
    )
    result = simulate_indentation(
        build_problem(study, mesh),
        depths,
        times_s=times,
        device="cpu",
        progress=False,
        options=study.solver.options,
        strict=True,
    )
    run = {"steps": int(times.size), "ramp_steps": RAMP_STEPS, "hold_steps": HOLD_STEPS}
    return (
        np.concatenate([[0.0], result.times_s]),
        np.concatenate([[0.0], result.reaction_force_N]),
        run,
    )


def make_record(
    study,
    mesh,
    *,
    speed_m_per_s: float,
    hold_s: float,
    sample_rate_Hz: float,
    seed: int,
) -> tuple[dict[str, np.ndarray], dict]:
    """One record's columns (time_s, displacement_m: axis position, force_N; shape (m,)) and
    how its FE run was made."""
    travel = AIR_M + DEPTH_M
    contact_s = REST_S + AIR_M / speed_m_per_s
    duration = REST_S + travel / speed_m_per_s + hold_s
    time_s = np.arange(0.0, duration + 1e-9, 1.0 / sample_rate_Hz)
    position_m = np.clip((time_s - REST_S) * speed_m_per_s, 0.0, travel)
    fe_time, fe_force, run = fe_curve(study, mesh, speed_m_per_s=speed_m_per_s, hold_s=hold_s)
    force_N = np.interp(time_s - contact_s, fe_time, fe_force, left=0.0) + OFFSET_N
    force_N += np.random.default_rng(seed).normal(0.0, NOISE_N, force_N.size)
    columns = {
        "time_s": np.round(time_s, 6),
        "displacement_m": np.round(position_m, 9),
        "force_N": np.round(force_N, 6),
    }
    return columns, run


def sidecar(loading: dict, run: dict, mesh, seed: int) -> dict:
    """The JSON sidecar of one record: what made it."""
    return {
        "description": "synthetic ramp-and-hold flat-punch indentation of liver made by the "
        "forward FE; the probe starts above the surface (condition with --contact auto)",
        "generator": "scripts/tools/make_relaxation_example.py",
        "truth": specimen().to_dict(),
        "model_source": "Ahn & Kim: C10 = 287.5 Pa (Table 2), two-term Prony series of "
        "Table 1, experiment 1 (g_i, tau_i)",
        "fe": {
            "study": "scenes/liver_fit.toml",
            "nodes": int(mesh.node_count),
            "element": "TET10",
            **run,
        },
        "probe": "flat punch",
        "probe_radius_m": 5e-3,
        "air_gap_m": AIR_M,
        "depth_m": DEPTH_M,
        "rest_s": REST_S,
        **loading,
        "force_offset_N": OFFSET_N,
        "force_noise_sd_N": NOISE_N,
        "seed": seed,
    }


def main() -> None:
    """Write the three CSV files and their sidecars."""
    from warptissue.device import quiet_warp
    from warptissue.simulate import build_mesh

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out-dir", type=Path, default=Path("scenes/data"))
    parser.add_argument(
        "--quick", action="store_true", help="only the first record's first 10 s (tests)"
    )
    args = parser.parse_args()
    quiet_warp()
    study = forward_study()
    mesh = build_mesh(study)
    for k, (name, loading) in enumerate(RECORDS.items()):
        path = args.out_dir / f"{name}.csv"
        if args.quick and k > 0:
            break
        columns, run = make_record(study, mesh, **loading, seed=SEED + k)
        if args.quick:  # the same FE run and noise; only the first 10 s written
            kept = columns["time_s"] <= QUICK_S
            columns = {name: values[kept] for name, values in columns.items()}
        write_csv(path, columns)
        write_json(path.with_suffix(".json"), sidecar(loading, run, mesh, SEED + k))
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
