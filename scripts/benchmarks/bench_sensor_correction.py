"""Tong et al., Table 1 on synthetic sensors: does WCFM_SVM beat every single model?

For each of ``--sessions`` simulated calibration sessions (``synthetic_sensor``, a seed
each) of ``--session-samples`` samples x 5 readings, 70 random samples train all eight
models (hyperparameters by cross-validation on those 70 only) and every other sample is
held out. Reported:

- Table 1 (MAE, the paper's MSE, MAPE) on 6 of the held-out samples of the first session,
  as in the paper's 70 / 6 split;
- over all sessions, each model's mean MAE on all its held-out samples, and for each model
  the paired difference MAE(WCFM_SVM) - MAE(model) (mean and standard error over sessions)
  and how often WCFM_SVM is better, on the whole held-out set and on the 6-sample split.

``--inputs mean`` gives every model the mean of a sample's readings instead of the readings.

    python scripts/benchmarks/bench_sensor_correction.py --sessions 30 --out runs/sensor_study
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from warptissue.acquisition.calibration import (
    CALIBRATION_MODELS,
    CalibrationData,
    evaluate_calibrations,
    fit_calibrations,
    sample_readings,
    synthetic_sensor,
)
from warptissue.io import write_csv, write_json


def mean_readings(data: CalibrationData) -> CalibrationData:
    """One reading per sample: the mean of its readings."""
    labels, force, readings = sample_readings(data)
    return CalibrationData(labels, force, readings.mean(axis=1))


def session_errors(seed: int, session_samples: int, inputs: str) -> dict:
    """Fit on 70 random samples of one session; metrics on the 6-sample split and on all
    held-out samples."""
    data = synthetic_sensor(samples=session_samples, seed=seed)
    if inputs == "mean":
        data = mean_readings(data)
    labels = np.unique(data.sample)
    order = np.random.default_rng(seed).permutation(len(labels))
    train = data.subset(np.isin(data.sample, labels[order[:70]]))
    six = data.subset(np.isin(data.sample, labels[order[70:76]]))
    held = data.subset(np.isin(data.sample, labels[order[70:]]))
    fits = fit_calibrations(train, seed=seed)
    return {
        "table1": evaluate_calibrations(fits, six),
        "held_out": evaluate_calibrations(fits, held),
        "weights": fits["WCFM_SVM"].metadata["weights"],
        "hyperparameters": {name: fit.metadata["hyperparameters"] for name, fit in fits.items()},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sessions", type=int, default=30)
    parser.add_argument("--session-samples", type=int, default=376)
    parser.add_argument("--first-seed", type=int, default=2017)
    parser.add_argument("--inputs", choices=("readings", "mean"), default="readings")
    parser.add_argument("--out", type=Path, default=Path("runs/sensor_study"))
    args = parser.parse_args()

    start = time.perf_counter()
    seeds = range(args.first_seed, args.first_seed + args.sessions)
    results = [
        session_errors(seed, args.session_samples, args.inputs)
        for seed in tqdm(seeds, desc="sessions", unit="session")
    ]
    elapsed = time.perf_counter() - start
    held_count = args.session_samples - 70

    first = results[0]["table1"]
    print(
        f"\nTable 1, session seed {args.first_seed}: 70 training / 6 held-out samples "
        f"(inputs: {args.inputs}; MSE* = 1/n sqrt(sum e^2) as Tong et al. define it)"
    )
    print(f"{'model':<11} {'MAE (N)':>9} {'MSE* (N)':>9} {'MAPE (%)':>9} {'max (N)':>9}")
    for name in CALIBRATION_MODELS:
        m = first[name]
        print(
            f"{name:<11} {m['mae_N']:9.4f} {m['mse_paper_N']:9.4f} {m['mape_percent']:9.4f} "
            f"{m['max_abs_error_N']:9.4f}"
        )

    def mae(split: str, name: str) -> np.ndarray:
        return np.array([r[split][name]["mae_N"] for r in results])

    summary = {}
    print(
        f"\n{args.sessions} sessions x {held_count} held-out samples; "
        "d = MAE(WCFM_SVM) - MAE(model), mean +- standard error over sessions"
    )
    print(
        f"{'model':<11} {'MAE (N)':>9} {'d (N)':>10} {'+-':>8} "
        f"{'WCFM better':>12} {'(6-sample split)':>17}"
    )
    for name in CALIBRATION_MODELS:
        difference = mae("held_out", "WCFM_SVM") - mae("held_out", name)
        difference_six = mae("table1", "WCFM_SVM") - mae("table1", name)
        summary[name] = {
            "held_out_mae_N": float(mae("held_out", name).mean()),
            "wcfm_svm_minus_model_mae_N": float(difference.mean()),
            "standard_error_N": float(difference.std(ddof=1) / np.sqrt(len(difference))),
            "wcfm_svm_better_fraction": float(np.mean(difference < 0)),
            "wcfm_svm_better_fraction_six": float(np.mean(difference_six < 0)),
        }
        s = summary[name]
        print(
            f"{name:<11} {s['held_out_mae_N']:9.4f} {s['wcfm_svm_minus_model_mae_N']:+10.5f} "
            f"{s['standard_error_N']:8.5f} {s['wcfm_svm_better_fraction']:12.2f} "
            f"{s['wcfm_svm_better_fraction_six']:17.2f}"
        )
    print(f"{elapsed:.0f} s for {args.sessions} sessions (fits included)")

    write_json(
        args.out / f"sensor_study_{args.inputs}.json",
        {
            "sessions": args.sessions,
            "session_samples": args.session_samples,
            "first_seed": args.first_seed,
            "inputs": args.inputs,
            "summary": summary,
            "per_session": results,
            "elapsed_s": elapsed,
        },
    )
    write_csv(
        args.out / f"sensor_study_{args.inputs}.csv",
        {"model": list(summary), **{k: [s[k] for s in summary.values()] for k in summary["bp"]}},
    )


if __name__ == "__main__":
    main()
