"""Generate the uniaxial example record ``scenes/data/phantom_uniaxial.csv`` (run from the root).

    python scripts/tools/make_uniaxial_example.py [--out scenes/data/phantom_uniaxial.csv]

The record imitates the unconfined compression test of the needle-indentation study
(docs/references.md): a block 80 mm tall with a 70 x 80 mm loaded face (A0 = 5.6e-3 m^2),
compressed by 12.7 mm at 0.4 mm/s, sampled at 10 Hz, with the study's fitted reduced
polynomial N = 2 (C10 = 600.553 Pa, C20 = 4097.45 Pa) as the material and seeded Gaussian
force noise of 0.02 N (the study's sensor resolution). Columns ``time_s``, ``displacement_m``
and ``force_N`` are magnitudes, positive in compression; a sidecar ``phantom_uniaxial.json``
records how the file was made. The file is generated, not hand-edited: change this script and
re-run it. Fit it with::

    warptissue fit uniaxial scenes/data/phantom_uniaxial.csv --area-m2 0.0056 --height-m 0.08
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from warptissue.fit.hyperelastic import HomogeneousTest
from warptissue.io import write_csv, write_json
from warptissue.materials import ReducedPolynomial

C10_PA, C20_PA = 600.553, 4097.45
"""The needle-indentation study's reduced polynomial N = 2 parameters."""
HEIGHT_M, AREA_M2 = 0.080, 5.6e-3  # 80 mm tall, 70 x 80 mm loaded face
DEPTH_M, SPEED_M_PER_S, RATE_HZ = 0.0127, 0.4e-3, 10.0
NOISE_N, SEED = 0.02, 20261125


def make_record(*, seed: int = SEED) -> dict[str, np.ndarray]:
    """The example columns: time_s, displacement_m, force_N, each shape (m,)."""
    time_s = np.arange(0.0, DEPTH_M / SPEED_M_PER_S + 1e-9, 1.0 / RATE_HZ)
    displacement_m = SPEED_M_PER_S * time_s
    test = HomogeneousTest("compression", displacement_m / HEIGHT_M, np.zeros_like(time_s))
    force_N = test.predicted_stress_Pa(ReducedPolynomial((C10_PA, C20_PA))) * AREA_M2
    force_N += np.random.default_rng(seed).normal(0.0, NOISE_N, force_N.size)
    return {
        "time_s": np.round(time_s, 6),
        "displacement_m": np.round(displacement_m, 9),
        "force_N": np.round(force_N, 5),
    }


def main() -> None:
    """Write the CSV and its sidecar."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("scenes/data/phantom_uniaxial.csv"))
    args = parser.parse_args()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_csv(args.out, make_record())
    write_json(
        args.out.with_suffix(".json"),
        {
            "description": "synthetic unconfined compression of a tissue phantom block",
            "generator": "scripts/tools/make_uniaxial_example.py",
            "material": ReducedPolynomial((C10_PA, C20_PA)).to_dict(),
            "material_source": "the needle-indentation study (reduced polynomial N = 2 fit)",
            "loading": "compression",
            "area_m2": AREA_M2,
            "height_m": HEIGHT_M,
            "speed_m_per_s": SPEED_M_PER_S,
            "sample_rate_Hz": RATE_HZ,
            "force_noise_sd_N": NOISE_N,
            "seed": SEED,
        },
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
