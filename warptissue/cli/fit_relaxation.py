"""``warptissue fit relaxation`` and ``warptissue fit punch-modulus``.

``relaxation`` fits a lumped viscoelastic model (standard linear solid, Prony series of N
terms, linear or nonlinear Wiechert body) to a ``time_s,displacement_m,force_N`` record,
driven by the measured displacement history (a real ramp, not an ideal step), and writes
``STEM_MODEL.json``, ``.csv`` and ``.png``. ``punch-modulus`` fits Young's modulus to a
``displacement_m,force_N`` curve with Sneddon's flat punch (optionally corrected for a layer
of finite thickness, Hayes et al. 1972) or Hertz's sphere.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from warptissue.errors import InputError

if TYPE_CHECKING:
    from warptissue.fit import FitResult

__all__ = ["parse_model", "register_fit"]


def parse_model(text: str) -> tuple[str, int]:
    """Split a model name such as ``prony:3`` into (model, terms); InputError when unknown."""
    name, _, count = text.partition(":")
    known = ("sls", "prony", "wiechert", "wiechert-nonlinear")
    if name not in known or (count and name != "prony"):
        raise InputError(
            f"unknown model; use one of sls, prony:N, {', '.join(known[2:])}",
            column="--model",
            value=text,
        )
    if not count:
        return name, 2
    if not count.isdigit() or int(count) < 1:
        raise InputError("prony:N needs a positive integer N", column="--model", value=text)
    return name, int(count)


def register_fit(subparsers: argparse._SubParsersAction) -> None:
    """Add ``warptissue fit relaxation`` and ``warptissue fit punch-modulus``."""
    relaxation = subparsers.add_parser(
        "relaxation",
        help="fit a lumped viscoelastic model (SLS, Prony, Wiechert) to a relaxation record",
        description=__doc__.split("\n\n", 1)[1],
    )
    relaxation.add_argument("data", type=Path, help="CSV with time_s,displacement_m,force_N")
    relaxation.add_argument(
        "--model", default="sls", help="sls (default), prony:N, wiechert, wiechert-nonlinear"
    )
    relaxation.add_argument(
        "--p0",
        default=None,
        help="comma-separated initial parameters in the model's order, SI units "
        "(default: from the data; recommended for wiechert-nonlinear)",
    )
    relaxation.add_argument("--method", choices=("lm", "salm"), default="lm")
    relaxation.add_argument("--objective", choices=("absolute", "relative"), default="absolute")
    relaxation.add_argument("--out", type=Path, default=None, help="output folder")
    relaxation.add_argument("--json", action="store_true", help="print the result as JSON")
    relaxation.set_defaults(handler=run_relaxation)

    punch = subparsers.add_parser(
        "punch-modulus",
        help="Young's modulus from a force-depth curve (Sneddon flat punch or Hertz sphere)",
    )
    punch.add_argument("data", type=Path, help="CSV with displacement_m,force_N")
    punch.add_argument("--radius-m", type=float, required=True, help="punch or sphere radius")
    punch.add_argument("--poissons-ratio", type=float, default=0.5)
    punch.add_argument("--geometry", choices=("flat", "sphere"), default="flat")
    punch.add_argument(
        "--thickness-m", type=float, default=None, help="layer thickness (flat punch, Hayes)"
    )
    punch.add_argument("--out", type=Path, default=None, help="output folder")
    punch.add_argument("--json", action="store_true", help="print the result as JSON")
    punch.set_defaults(handler=run_punch_modulus)


def _finish(
    args: argparse.Namespace, result: FitResult, files: dict[str, Path], extra: dict[str, Any]
) -> int:
    """Print the summary (or JSON) and warn on an unsuccessful fit."""
    if not result.success:
        print(f"warptissue: warning: {result.message}", file=sys.stderr)
    if args.json:
        print(
            json.dumps(
                {"fit": result.to_dict(), **extra, "files": {k: str(v) for k, v in files.items()}},
                indent=2,
                default=str,
            )
        )
    else:
        print(result.summary())
        print(f"outputs in {files['json'].parent}")
    return 0


def run_relaxation(args: argparse.Namespace) -> int:
    """Fit, write JSON + CSV + PNG, print a summary (or JSON); return the exit status."""
    from warptissue.io import read_experiment_csv
    from warptissue.report import write_fit_outputs
    from warptissue.viscoelastic import fit_relaxation

    model, terms = parse_model(args.model)
    p0 = None
    if args.p0 is not None:
        try:
            p0 = [float(v) for v in args.p0.split(",")]
        except ValueError:
            raise InputError("--p0 needs comma-separated numbers", value=args.p0) from None
    record = read_experiment_csv(args.data)
    result = fit_relaxation(
        record["time_s"],
        record["displacement_m"],
        record["force_N"],
        model=model,
        terms=terms,
        p0=p0,
        method=args.method,
        objective=args.objective,
    )
    label = f"{model}{terms}" if model == "prony" else model
    details = {"data_file": str(args.data), "model": result.fitted_model.to_dict()}
    if model == "sls":
        details["seed001_eq4_printed_form"] = result.fitted_model.to_printed()
    out_dir = args.out if args.out is not None else Path(f"{args.data.stem}_relaxation_fit")
    files = write_fit_outputs(
        out_dir,
        f"{args.data.stem}_{label}",
        result,
        {
            "time_s": record["time_s"],
            "measured_force_N": record["force_N"],
            "fitted_force_N": result.fitted,
            "displacement_m": record["displacement_m"],
        },
        metadata=details,
        title=f"{args.model} fit, R^2 = "
        + ("n/a" if result.r_squared is None else f"{result.r_squared:.4f}"),
    )
    return _finish(args, result, files, {"model": details["model"]})


def run_punch_modulus(args: argparse.Namespace) -> int:
    """Fit E to a force-depth curve, write JSON + CSV + PNG; return the exit status."""
    import numpy as np

    from warptissue.io import read_experiment_csv
    from warptissue.fit.punch import fit_punch_modulus
    from warptissue.report import write_fit_outputs

    record = read_experiment_csv(
        args.data, required=("displacement_m", "force_N"), monotonic="time_s"
    )
    depth = np.abs(record["displacement_m"])
    force = np.abs(record["force_N"])
    loaded = depth > 0.0
    if np.count_nonzero(loaded) < 2:
        raise InputError(
            "needs at least two samples with non-zero depth",
            path=args.data,
            column="displacement_m",
        )
    result = fit_punch_modulus(
        depth[loaded],
        force[loaded],
        radius_m=args.radius_m,
        poissons_ratio=args.poissons_ratio,
        geometry=args.geometry,
        thickness_m=args.thickness_m,
    )
    out_dir = args.out if args.out is not None else Path(f"{args.data.stem}_punch_fit")
    details = {
        "data_file": str(args.data),
        "geometry": args.geometry,
        "radius_m": args.radius_m,
        "poissons_ratio": args.poissons_ratio,
        "thickness_m": args.thickness_m,
        "formula": "Sneddon F = 2 a E delta kappa / (1 - nu^2)"
        if args.geometry == "flat"
        else "Hertz F = 4/3 E / (1 - nu^2) sqrt(R) delta^1.5",
    }
    files = write_fit_outputs(
        out_dir,
        f"{args.data.stem}_{args.geometry}_modulus",
        result,
        {
            "displacement_m": depth[loaded],
            "measured_force_N": force[loaded],
            "fitted_force_N": result.fitted,
        },
        metadata=details,
    )
    return _finish(args, result, files, details)
