"""Generate the ramp-and-hold example records ``scenes/data/liver_ramp_*.csv`` (run from the root).

    python scripts/tools/make_relaxation_example.py [--out-dir scenes/data]

Three flat-punch indentations of liver at three rates, written as the rig records them
(``time_s``, axis ``displacement_m`` from the start position, ``force_N``; positive into the
specimen): the probe rests for 2 s, moves 0.5 mm through air to the surface, indents 4 mm and
holds. The specimen is Ahn & Kim's two-term Prony series (Table 1, experiment 1: g1 = 0.348,
g2 = 0.358, tau1 = 1.376 s, tau2 = 49.369 s) with an instantaneous stiffness of 23 N/m (a
5 mm flat punch, Sneddon's F = 2 a E delta / (1 - nu^2), on a half-space of E = 6 C10 =
1725 Pa, C10 = 287.5 Pa from the same paper, nu = 0.5). The transducer adds an offset of
3 mN and seeded Gaussian noise of 0.2 mN.

- ``liver_ramp_hold.csv``: 8 mm/s ramp (0.5 s), 120 s hold, 50 Hz;
- ``liver_ramp_slow.csv``: 0.4 mm/s ramp (10 s), 60 s hold, 20 Hz;
- ``liver_ramp_medium.csv``: 2 mm/s ramp (2 s), 60 s hold, 20 Hz (to validate a joint fit).

Each has a JSON sidecar recording how it was made. The files are generated, not hand-edited:
change this script and re-run it. Fit them with::

    warptissue fit relaxation scenes/data/liver_ramp_hold.csv --model prony:2 --contact auto
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from warptissue.io import write_csv, write_json
from warptissue.viscoelastic import PronySeries

INSTANTANEOUS_STIFFNESS_N_PER_M = 23.0
G, TAU_S = (0.348, 0.358), (1.376, 49.369)
"""Ahn & Kim, Table 1, experiment 1."""
AIR_M, DEPTH_M, REST_S = 0.5e-3, 4e-3, 2.0
OFFSET_N, NOISE_N, SEED = 3e-3, 2e-4, 20261125
RECORDS = {
    "liver_ramp_hold": {"speed_m_per_s": 8e-3, "hold_s": 120.0, "sample_rate_Hz": 50.0},
    "liver_ramp_slow": {"speed_m_per_s": 0.4e-3, "hold_s": 60.0, "sample_rate_Hz": 20.0},
    "liver_ramp_medium": {"speed_m_per_s": 2e-3, "hold_s": 60.0, "sample_rate_Hz": 20.0},
}


def specimen() -> PronySeries:
    """The Prony series of the specimen, in N/m."""
    return PronySeries.from_normalized(INSTANTANEOUS_STIFFNESS_N_PER_M, G, TAU_S)


def make_record(
    *, speed_m_per_s: float, hold_s: float, sample_rate_Hz: float, seed: int
) -> dict[str, np.ndarray]:
    """One record's columns: time_s, displacement_m (axis position), force_N, shape (m,)."""
    travel = AIR_M + DEPTH_M
    duration = REST_S + travel / speed_m_per_s + hold_s
    time_s = np.arange(0.0, duration + 1e-9, 1.0 / sample_rate_Hz)
    position_m = np.clip((time_s - REST_S) * speed_m_per_s, 0.0, travel)
    depth_m = np.clip(position_m - AIR_M, 0.0, None)
    force_N = specimen().force_N(time_s, depth_m) + OFFSET_N
    force_N += np.random.default_rng(seed).normal(0.0, NOISE_N, force_N.size)
    return {
        "time_s": np.round(time_s, 6),
        "displacement_m": np.round(position_m, 9),
        "force_N": np.round(force_N, 6),
    }


def main() -> None:
    """Write the three CSV files and their sidecars."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out-dir", type=Path, default=Path("scenes/data"))
    args = parser.parse_args()
    for k, (name, loading) in enumerate(RECORDS.items()):
        path = args.out_dir / f"{name}.csv"
        write_csv(path, make_record(**loading, seed=SEED + k))
        write_json(
            path.with_suffix(".json"),
            {
                "description": "synthetic ramp-and-hold flat-punch indentation of liver; the "
                "probe starts above the surface (condition with --contact auto)",
                "generator": "scripts/tools/make_relaxation_example.py",
                "model": specimen().to_dict(),
                "model_source": "Ahn & Kim, Table 1, experiment 1 (g_i, tau_i); instantaneous "
                "stiffness of a 5 mm flat punch on E = 1725 Pa",
                "probe": "flat punch",
                "probe_radius_m": 5e-3,
                "air_gap_m": AIR_M,
                "depth_m": DEPTH_M,
                "rest_s": REST_S,
                **loading,
                "force_offset_N": OFFSET_N,
                "force_noise_sd_N": NOISE_N,
                "seed": SEED + k,
            },
        )
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
