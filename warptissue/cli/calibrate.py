"""``warptissue calibrate-sensor``: fit a force-sensor correction (Tong et al., WCFM_SVM).

Reads calibration readings (``sample,force_N,signal_V``; ``sample`` groups repeated readings
of one applied force), holds out ``--test-samples`` samples (the paper: 70 / 6), fits the
single models (polynomial, BP network, SVR, LSSVM; hyperparameters by cross-validation on
the training samples) and the combinations (CFM_SVM, CFM_LSSVM, WCFM_LSSVM, WCFM_SVM), and
writes ``calibration.json`` (the chosen model, for the recorder), ``calibration_metrics.json``
and ``.csv`` (Table 1: MAE, the paper's MSE, MAPE on the test samples, each sample's force
corrected from its readings) and ``calibration.png``. Every sample needs the same number of
readings. Exit status: 0 written; 2 bad input (the file, line and column, or the option,
named), checked before any model is fitted.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from warptissue.errors import InputError

__all__ = ["register"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``warptissue calibrate-sensor``."""
    parser = subparsers.add_parser(
        "calibrate-sensor",
        help="fit a force-sensor correction (WCFM_SVM and the baselines of Tong et al.)",
        description=__doc__.split("\n\n", 1)[1],
    )
    parser.add_argument("data", type=Path, help="CSV: [sample,]force_N,signal_V")
    parser.add_argument("--model", default="WCFM_SVM", help="model saved to calibration.json")
    parser.add_argument("--test-samples", type=int, default=6, help="samples held out")
    parser.add_argument("--seed", type=int, default=0, help="seed of the split and models")
    parser.add_argument("--folds", type=int, default=5, help="cross-validation folds")
    parser.add_argument("--out", type=Path, default=Path("calibration_out"), help="folder")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """Handle ``warptissue calibrate-sensor``."""
    import numpy as np

    from warptissue.acquisition.calibration import (
        CALIBRATION_MODELS,
        evaluate_calibrations,
        fit_calibrations,
        read_calibration_csv,
        split_samples,
    )
    from warptissue.io import write_csv, write_json

    if args.model not in CALIBRATION_MODELS:
        raise InputError(
            f"--model must be one of {', '.join(CALIBRATION_MODELS)}", value=args.model
        )
    if args.folds < 2:
        raise InputError("--folds must be 2 or more", value=args.folds)
    if args.seed < 0:
        raise InputError("--seed must be zero or more", value=args.seed)
    data = read_calibration_csv(args.data)
    samples = len(np.unique(data.sample))
    if not 0 < args.test_samples < samples - 1:
        raise InputError(
            f"--test-samples must be between 1 and {samples - 2} ({args.data} has {samples} "
            "samples; at least 2 must remain to train on)",
            value=args.test_samples,
        )
    if 2 * args.folds > samples - args.test_samples:
        raise InputError(
            f"--folds must be at most {(samples - args.test_samples) // 2} (two training "
            f"samples per fold; {samples - args.test_samples} samples train)",
            value=args.folds,
        )
    _check_output_folder(args.out)
    train, test = split_samples(data, test_samples=args.test_samples, seed=args.seed)
    calibrations = fit_calibrations(train, folds=args.folds, seed=args.seed, progress=True)
    table = evaluate_calibrations(calibrations, test)
    chosen = calibrations[args.model]
    chosen.metadata.update(
        {
            "data": str(args.data),
            "test_samples": args.test_samples,
            "seed": args.seed,
            "folds": args.folds,
            "test_metrics": table[args.model],
        }
    )
    chosen.save(args.out / "calibration.json")
    write_json(args.out / "calibration_metrics.json", table)
    write_csv(
        args.out / "calibration_metrics.csv",
        {
            "model": list(table),
            "mae_N": [m["mae_N"] for m in table.values()],
            "mse_paper_N": [m["mse_paper_N"] for m in table.values()],
            "mape_percent": [m["mape_percent"] for m in table.values()],
            "max_abs_error_N": [m["max_abs_error_N"] for m in table.values()],
        },
    )
    _plot(args.out / "calibration.png", test, calibrations)
    print(f"{'model':<11} {'MAE (N)':>9} {'MSE* (N)':>9} {'MAPE (%)':>9}")
    for name, metrics in table.items():
        print(
            f"{name:<11} {metrics['mae_N']:9.4f} {metrics['mse_paper_N']:9.4f} "
            f"{metrics['mape_percent']:9.4f}"
        )
    print("MSE* = 1/n sqrt(sum e^2), as Tong et al. define it")
    print(
        f"wrote {args.out / 'calibration.json'} ({args.model}, test samples: "
        f"{len(np.unique(test.sample))})"
    )
    return 0


def _check_output_folder(folder: Path) -> None:
    """Create ``--out`` (or find it writable) before the fits, not after."""

    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--out: cannot create the folder: {exc.strerror}", path=folder) from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError("--out: the folder is not writable", path=folder)


def _plot(path: Path, test, calibrations) -> None:
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from warptissue.acquisition.calibration import sample_readings
    from warptissue.io import atomic_path

    _, actual, readings = sample_readings(test)
    order = np.argsort(actual)
    figure, axis = plt.subplots(figsize=(7, 4), constrained_layout=True)
    for index, (name, calibration) in enumerate(calibrations.items()):
        corrected = calibration.correct(readings)
        axis.plot(
            np.arange(len(actual)) + 0.08 * (index - 3.5),
            np.abs(corrected - actual)[order],
            "o-",
            label=name,
            ms=4,
        )
    axis.set_xlabel("test sample (by increasing force)")
    axis.set_ylabel("absolute error (N)")
    axis.set_title("Force correction on held-out samples (Tong et al., Figure 3)")
    axis.legend(ncol=2, fontsize=8)
    with atomic_path(path) as temporary:
        figure.savefig(temporary, dpi=120)
    plt.close(figure)
