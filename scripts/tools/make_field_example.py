"""Generate the marker example ``scenes/data/slab_markers.csv`` and ``slab_forces.csv``.

    python scripts/tools/make_field_example.py [--out scenes/data]

The markers are those of the synthetic slab of ``tests/field_cases.py`` (a 12 x 8 x 3 cm
block, base fixed, 9 x 7 markers on its top face, a 3x stiff circular inclusion on a modulus
gradient, Poisson's ratio 0.30-0.35), computed with the package's linear TET4 model, with
seeded Gaussian noise of 5 micrometres per coordinate (written to the nanometre), for two
load sets at the marker left of the centre: ``A`` an oblique force (0.5, 0, -2) N and ``B``
a vertical force of 3 N. A sidecar ``slab_markers.json`` records how the files were made and
the true (E, nu) of each hexahedron (cell order of ``field_<set>_cells.csv``). The files are
generated, not hand-edited: change this script and re-run it. Fit them with::

    warptissue fit field scenes/data/slab_markers.csv --forces scenes/data/slab_forces.csv \\
        --thickness-m 0.03 --test-markers 8 --out field_out
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from warptissue.io import write_json

# The synthetic cases are a test fixture: they live in the repository's tests/ folder.
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
from field_cases import SLAB_SIZE_M, synthetic_slab, write_case_files  # noqa: E402

NOISE_M = 5e-6
"""Standard deviation of the marker noise per coordinate, metres."""
LOAD_SETS_N: dict[str, tuple[float, float, float]] = {"A": (0.5, 0.0, -2.0), "B": (0.0, 0.0, -3.0)}
"""The force at the loaded marker per load set, N."""


def main() -> None:
    """Write the marker file, the force file and the sidecar."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("scenes/data"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    cases = {
        label: synthetic_slab(noise_m=NOISE_M, force_N=force, seed=seed, device="cpu")
        for seed, (label, force) in enumerate(LOAD_SETS_N.items(), start=3)
    }
    markers_path, forces_path = write_case_files(
        args.out,
        cases,
        markers_name="slab_markers.csv",
        forces_name="slab_forces.csv",
        decimals=9,
    )
    first = next(iter(cases.values()))
    write_json(
        markers_path.with_suffix(".json"),
        {
            "description": "synthetic surface markers of a heterogeneous elastic slab",
            "generator": "scripts/tools/make_field_example.py",
            "size_m": list(SLAB_SIZE_M),
            "base": "fixed (z = 0)",
            "markers": f"{len(first.marker_reference_m)} on a 9 x 7 grid of the top face",
            "loaded_marker": f"M{first.loaded_marker + 1:03d}",
            "forces_N": {label: list(force) for label, force in LOAD_SETS_N.items()},
            "marker_noise_sd_m": NOISE_M,
            "true_field": {
                "cells": "hexahedra in the order of field_<set>_cells.csv",
                "youngs_modulus_Pa": first.youngs_modulus_Pa.tolist(),
                "poissons_ratio": first.poissons_ratio.tolist(),
            },
        },
    )
    print(f"wrote {markers_path} and {forces_path}")


if __name__ == "__main__":
    main()
