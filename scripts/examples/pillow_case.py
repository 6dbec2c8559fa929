"""Tong et al.'s two experiments on synthetic data: the memory pillow (Table 3) and the force
sensor (Table 1).

Pillow: a 50 x 30 x 10 cm block, 23 x 13 markers (299), the load at the 150th marker, the six
forces A-F of Table 2, a known smooth heterogeneous (E, nu) around Table 2's values, Gaussian
marker noise; 249 training and 50 test markers. For each set: the homogeneous linear estimate
(Eq. 13-14) and the heterogeneous field, with the test-marker errors (Table 3), E and nu maps
(Figure 5, PNG), VTU, and the E error in constrained cells.

Sensor: 76 samples of 5 readings from a synthetic sensor (nonlinear gain, temperature drift,
noise), 70 / 6 split, the eight models of Table 1.

Usage: python scripts/examples/pillow_case.py [--out runs/pillow] [--noise-m 2e-5] [--sets ABCDEF]
(about 1-2 minutes per load set on a 2-core x86_64 CPU). ``--quick`` halves the marker grid
(12 x 7 markers, 14 held out, 66 hexahedra) and runs load set F and the sensor in seconds.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from warptissue.acquisition.calibration import (
    CALIBRATION_MODELS,
    evaluate_calibrations,
    fit_calibrations,
    split_samples,
    synthetic_sensor,
)
from warptissue.field.markers import read_forces_csv, read_markers_csv
from warptissue.field.pipeline import estimate_load_set, write_load_set_outputs
from warptissue.io import write_json

# The synthetic pillow is a test fixture: it lives in the repository's tests/ folder.
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
from field_cases import synthetic_pillow, write_case_files  # noqa: E402


def pillow(
    out: Path,
    *,
    noise_m: float,
    sets: str,
    gamma: float,
    method: str,
    objective: str,
    quick: bool = False,
) -> list[dict]:
    columns, rows, test_count = (12, 7, 14) if quick else (23, 13, 50)
    pillows = {
        label: synthetic_pillow(load_set=label, columns=columns, rows=rows, noise_m=noise_m)
        for label in sets
    }
    markers_path, forces_path = write_case_files(out, pillows)
    markers, forces = read_markers_csv(markers_path), read_forces_csv(forces_path)
    table = []
    print(
        f"pillow: {columns} x {rows} markers, {columns * rows - test_count}/{test_count} split, "
        f"noise {noise_m * 1e3:.3f} mm, gamma {gamma}, {objective} objective, {method}"
    )
    print(
        " set  E0 (Pa)   nu0   linear max/mean (mm)  field max/mean (mm)  constrained "
        "E cells  max |E err| there  median |E err| all   time (s)"
    )
    for label in sets:
        start = time.perf_counter()
        result = estimate_load_set(
            markers,
            forces[label],
            load_set=label,
            thickness_m=0.10,
            test_count=test_count,
            seed=1,
            gamma=gamma,
            method=method,
            objective=objective,
            device="cpu",
            progress=False,
        )
        elapsed = time.perf_counter() - start
        write_load_set_outputs(out, result)
        truth = pillows[label].youngs_modulus_Pa
        error = np.abs(result.field.youngs_modulus_Pa / truth - 1.0)
        constrained = result.field.constrained_youngs()
        row = {
            "load_set": label,
            "E0_Pa": result.homogeneous.youngs_modulus_Pa,
            "nu0": result.homogeneous.poissons_ratio,
            "linear_max_mm": result.homogeneous_errors["max_error_m"] * 1e3,
            "linear_mean_mm": result.homogeneous_errors["mean_error_m"] * 1e3,
            "field_max_mm": result.field_errors["max_error_m"] * 1e3,
            "field_mean_mm": result.field_errors["mean_error_m"] * 1e3,
            "constrained_cells": int(constrained.sum()),
            "max_E_error_constrained": float(error[constrained].max())
            if constrained.any()
            else None,
            "median_E_error_all": float(np.median(error)),
            "iterations": result.field.fit.iterations,
            "seconds": elapsed,
        }
        table.append(row)
        worst = (
            "-"
            if row["max_E_error_constrained"] is None
            else (f"{100 * row['max_E_error_constrained']:.1f}%")
        )
        print(
            f"   {label} {row['E0_Pa']:8.1f} {row['nu0']:6.3f}   "
            f"{row['linear_max_mm']:7.3f}/{row['linear_mean_mm']:<7.3f}      "
            f"{row['field_max_mm']:7.3f}/{row['field_mean_mm']:<7.3f}     "
            f"{row['constrained_cells']:4d}/{constrained.size:<4d}          {worst:>6}            "
            f"{100 * row['median_E_error_all']:.1f}%        {elapsed:6.1f}"
        )
    return table


def sensor(out: Path) -> dict:
    data = synthetic_sensor(samples=76, seed=2017)
    train, test = split_samples(data, test_samples=6, seed=0)
    fits = fit_calibrations(train, seed=0)
    table = evaluate_calibrations(fits, test)
    print("\nsensor: 76 samples x 5 readings, 70 / 6 split (MSE* = 1/n sqrt(sum e^2), Tong et al.)")
    print(f"{'model':<11} {'MAE (N)':>9} {'MSE* (N)':>9} {'MAPE (%)':>9} {'max (N)':>9}")
    for name in CALIBRATION_MODELS:
        metrics = table[name]
        print(
            f"{name:<11} {metrics['mae_N']:9.4f} {metrics['mse_paper_N']:9.4f} "
            f"{metrics['mape_percent']:9.4f} {metrics['max_abs_error_N']:9.4f}"
        )
    fits["WCFM_SVM"].save(out / "calibration.json")
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("runs/pillow"))
    parser.add_argument("--noise-m", type=float, default=2e-5)
    parser.add_argument("--gamma", type=float, default=1e-6)
    parser.add_argument("--method", choices=("salm", "lm"), default="salm")
    parser.add_argument("--sets", default=None, help="load sets (default ABCDEF, F with --quick)")
    parser.add_argument("--objective", choices=("displacement", "force"), default="displacement")
    parser.add_argument("--skip-sensor", action="store_true")
    parser.add_argument("--quick", action="store_true", help="12 x 7 markers, load set F")
    args = parser.parse_args()
    rows = pillow(
        args.out,
        noise_m=args.noise_m,
        sets=args.sets or ("F" if args.quick else "ABCDEF"),
        gamma=args.gamma,
        method=args.method,
        objective=args.objective,
        quick=args.quick,
    )
    table = {} if args.skip_sensor else sensor(args.out)
    write_json(args.out / "pillow_case.json", {"pillow": rows, "sensor": table})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
