"""``warptissue fit relaxation`` and ``warptissue fit punch-modulus``.

``relaxation`` fits a lumped viscoelastic model (standard linear solid, Prony series of N
terms, linear or nonlinear Wiechert body) to one or several ``time_s,displacement_m,force_N``
records at once (a joint fit: Takacs et al. fit a near-step and a ramp together), driven by
each measured displacement history (a real ramp, not an ideal step), and writes
``STEM_MODEL.json``, ``.csv`` and ``.png``. ``--predict`` validates the fitted model on
another record (a third rate) and writes the predicted against the measured force.
``punch-modulus`` fits Young's modulus to a ``displacement_m,force_N`` curve with Sneddon's
flat punch (optionally corrected for a layer of finite thickness, Hayes et al. 1972) or
Hertz's sphere.

Both can condition a raw record first (``--contact``, ``--offset``, ``--keep-depth``,
``--window``): detect the contact point of a probe that starts above the surface, remove the
force offset measured before contact, and trim. Implausible data (zero force, opposite signs,
depths beyond 0.1 m) end with exit status 2; implausible or unidentified results print
``warptissue: warning: ...`` lines on stderr and list them under ``warnings`` in the JSON
(exit status 0).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from warptissue.cli._args import length_m, positive_length_m, quantity
from warptissue.errors import InputError

if TYPE_CHECKING:
    import numpy as np

    from warptissue.io import ExperimentData
    from warptissue.lsq import FitResult

__all__ = ["parse_model", "register_fit"]


def parse_model(text: str) -> tuple[str, int]:
    """Split a model name such as ``prony:3`` into (model, terms); InputError when unknown."""
    name, _, count = text.partition(":")
    known = ("sls", "prony", "qlv", "wiechert", "wiechert-nonlinear")
    if name not in known or (count and name not in ("prony", "qlv")):
        raise InputError(
            f"--model: unknown model {text!r}; use one of sls, prony:N, qlv:N, "
            f"{', '.join(known[3:])}"
        )
    if not count:
        return name, 2
    if not count.isdigit() or int(count) < 1:
        raise InputError(f"--model: {name}:N needs a positive integer N (got {text!r})")
    return name, int(count)


def _contact(text: str) -> str | float:
    """``--contact``: "none", "auto" or an axis position (m, units allowed)."""
    if text in ("none", "auto"):
        return text
    try:
        return length_m(text)
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(
            f"use none, auto or a position such as 1.5mm; {exc}"
        ) from None


def _window(text: str) -> tuple[float, float]:
    """``--window START:STOP`` in seconds (units allowed)."""
    start, sep, stop = text.partition(":")
    if not sep:
        raise argparse.ArgumentTypeError(f"use START:STOP in seconds, e.g. 0:30 (got {text!r})")
    seconds = quantity("time", nonnegative=True)
    first, last = seconds(start), seconds(stop)
    if not last > first:
        raise argparse.ArgumentTypeError(f"the window must end after it starts (got {text!r})")
    return first, last


def _poissons_ratio(text: str) -> float:
    """``--poissons-ratio``: a number in (-1, 0.5]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number (got {text!r})") from None
    if not -1.0 < value <= 0.5:
        raise argparse.ArgumentTypeError(f"must lie in (-1, 0.5] (got {text!r})")
    return value


def _relative_floor(text: str) -> str | float:
    """``--relative-floor``: "auto" or a force (N, units allowed)."""
    return "auto" if text == "auto" else quantity("force", positive=True)(text)


def _add_conditioning(parser: argparse.ArgumentParser) -> None:
    """The conditioning options shared by both fits."""
    group = parser.add_argument_group(
        "conditioning (warptissue.acquisition.conditioning)",
        "Applied to every record before the fit. The default uses each record as it is.",
    )
    group.add_argument(
        "--contact",
        type=_contact,
        default="none",
        metavar="none|auto|POSITION",
        help="contact point: none (default: displacement_m is already the depth), auto "
        "(detect where the force leaves the pre-contact baseline; needs at least 10 samples "
        "before the probe moves) or the axis position at contact (m, e.g. 1.5mm); depths "
        "are then measured from the contact and clipped at zero",
    )
    group.add_argument(
        "--offset",
        choices=("auto", "none"),
        default="auto",
        help="with --contact: subtract the force offset (and drift) measured where the probe "
        "carries no load (auto, default) or keep the force as recorded (none)",
    )
    group.add_argument(
        "--keep-depth",
        type=positive_length_m,
        default=None,
        metavar="DEPTH",
        help="keep only the loading ramp down to this depth below contact (m, e.g. 3.6mm; "
        "Takacs et al. keep 3.6 mm of a 4 mm ramp)",
    )
    group.add_argument(
        "--window",
        type=_window,
        default=None,
        metavar="START:STOP",
        help="keep only the samples with START <= time_s <= STOP (s)",
    )


def register_fit(subparsers: argparse._SubParsersAction) -> None:
    """Add ``warptissue fit relaxation`` and ``warptissue fit punch-modulus``."""
    _register_relaxation(subparsers)
    _register_punch_modulus(subparsers)


def _register_relaxation(subparsers: argparse._SubParsersAction) -> None:
    """Add ``warptissue fit relaxation``."""
    relaxation = subparsers.add_parser(
        "relaxation",
        help="fit a lumped viscoelastic model (SLS, Prony, Wiechert) to one or several "
        "relaxation records",
        description="Fit a lumped viscoelastic model (standard linear solid, Prony series of "
        "N terms, linear or nonlinear Wiechert body) to one record, or to several at once (a "
        "joint fit, as Takacs et al. fit a near-step and a ramp), driven by each measured "
        "displacement history. Writes STEM_MODEL.json, .csv and .png. Implausible data "
        "(zero force, opposite signs, depths beyond 0.1 m) end with exit status 2; "
        "unidentified parameters and implausible results print 'warptissue: warning:' lines "
        "on stderr and are listed under 'warnings' in the JSON (exit status 0).",
    )
    relaxation.add_argument(
        "data",
        type=Path,
        nargs="+",
        help="CSV file(s) with time_s,displacement_m,force_N; several files are fitted jointly",
    )
    relaxation.add_argument(
        "--model",
        default="sls",
        help="sls (default), prony:N, qlv:N (quasi-linear viscoelasticity with an exponential "
        "elastic force, Ahn & Kim's stage (i); one ramp-and-hold record), wiechert, "
        "wiechert-nonlinear",
    )
    relaxation.add_argument(
        "--gauge-length-m",
        type=positive_length_m,
        default=None,
        metavar="L0",
        help="the record is a tensile or compressive test of a specimen of this gauge length "
        "(m, e.g. 80mm): displacements up to MAX_NOMINAL_STRAIN (10) gauge lengths are "
        "plausible (an indentation's limit is 0.1 m)",
    )
    relaxation.add_argument(
        "--max-displacement-m",
        type=positive_length_m,
        default=None,
        metavar="D",
        help="the largest plausible displacement (m, e.g. 150mm), overriding the "
        "indentation's 0.1 m and --gauge-length-m",
    )
    relaxation.add_argument(
        "--p0",
        default=None,
        help="comma-separated initial parameters in the model's order, SI units "
        "(default: from the data; recommended for wiechert-nonlinear)",
    )
    relaxation.add_argument(
        "--method",
        choices=("lm", "salm"),
        default="lm",
        help="lm: Levenberg-Marquardt (default); salm: Tong et al.'s self-adapting LM",
    )
    relaxation.add_argument(
        "--objective",
        choices=("absolute", "relative"),
        default="absolute",
        help="absolute: force residuals (N); relative: residuals divided by the measured force",
    )
    relaxation.add_argument(
        "--relative-floor",
        type=_relative_floor,
        default="auto",
        metavar="auto|FORCE",
        help="relative objective: smallest |force| used as a divisor, so that a record that "
        "starts at zero force can be fitted (N, e.g. 1mN; auto: the share "
        "warptissue.lsq.engine.RELATIVE_FLOOR_SHARE of the largest |force|)",
    )
    relaxation.add_argument(
        "--predict",
        type=Path,
        action="append",
        default=[],
        metavar="CSV",
        help="predict this record (same columns, same conditioning) with the fitted model and "
        "write CSVSTEM_MODEL_prediction.csv/.png with R^2 and RMSE; may be repeated",
    )
    _add_conditioning(relaxation)
    relaxation.add_argument("--out", type=Path, default=None, help="output folder")
    relaxation.add_argument("--json", action="store_true", help="print the result as JSON")
    relaxation.set_defaults(handler=run_relaxation)


def _register_punch_modulus(subparsers: argparse._SubParsersAction) -> None:
    """Add ``warptissue fit punch-modulus``."""
    punch = subparsers.add_parser(
        "punch-modulus",
        help="Young's modulus from a force-depth curve (Sneddon flat punch or Hertz sphere)",
        description="Fit Young's modulus to a displacement_m,force_N curve with Sneddon's "
        "flat punch (optionally corrected for a layer of finite thickness bonded to a rigid "
        "base, Hayes et al. 1972, for radius/thickness up to 16) or Hertz's sphere. Writes "
        "STEM_GEOMETRY_modulus.json, .csv and .png.",
    )
    punch.add_argument("data", type=Path, help="CSV with displacement_m,force_N")
    punch.add_argument(
        "--radius-m",
        type=positive_length_m,
        required=True,
        help="punch or sphere radius (m, or with a unit: 1mm)",
    )
    punch.add_argument(
        "--poissons-ratio",
        type=_poissons_ratio,
        default=0.5,
        help="Poisson's ratio of the tissue, in (-1, 0.5] (default 0.5: incompressible)",
    )
    punch.add_argument("--geometry", choices=("flat", "sphere"), default="flat")
    punch.add_argument(
        "--thickness-m",
        type=positive_length_m,
        default=None,
        help="layer thickness for the flat punch's Hayes correction (m, or 10mm); "
        "radius/thickness at most 16",
    )
    _add_conditioning(punch)
    punch.add_argument("--out", type=Path, default=None, help="output folder")
    punch.add_argument("--json", action="store_true", help="print the result as JSON")
    punch.set_defaults(handler=run_punch_modulus)


@dataclass
class _Record:
    """A record ready for fitting, and what conditioning did to it."""

    path: Path
    time_s: np.ndarray
    displacement_m: np.ndarray
    force_N: np.ndarray
    conditioned: bool
    conditioning: dict[str, Any] = field(default_factory=dict)


_OPTION_FLAGS = {
    "contact": "--contact",
    "offset": "--offset",
    "keep_depth_m": "--keep-depth",
    "window_s": "--window",
}
"""How conditioning errors name the options on the command line."""


def _named(exc: InputError, path: Path) -> InputError:
    """``exc`` with ``path`` as its file when it names none."""
    if exc.path is not None:
        return exc
    return InputError(exc.message, path=path, line=exc.line, column=exc.column, value=exc.value)


def _condition(
    data: ExperimentData, path: Path, args: argparse.Namespace, *, has_time: bool
) -> _Record:
    """Apply ``--contact/--offset/--keep-depth/--window`` to one record."""
    from warptissue.acquisition.conditioning import condition_for_fit

    columns = {name: data[name] for name in ("displacement_m", "force_N")}
    if has_time:
        columns["time_s"] = data["time_s"]
    try:
        record = condition_for_fit(
            columns,
            contact=args.contact,
            offset=args.offset,
            keep_depth_m=args.keep_depth,
            window_s=args.window,
            option_names=_OPTION_FLAGS,
        )
    except InputError as exc:
        raise _named(exc, path) from None
    return _Record(
        path,
        record.time_s,
        record.displacement_m,
        record.force_N,
        record.conditioned,
        record.summary,
    )


def _read(path: Path, args: argparse.Namespace, *, required: tuple[str, ...]) -> _Record:
    """Read, validate and condition one record."""
    from warptissue.io import read_experiment_csv

    data = read_experiment_csv(path, required=required, monotonic="time_s")
    return _condition(data, path, args, has_time="time_s" in data.columns)


def _print_warnings(messages: list[str]) -> None:
    for message in messages:
        print(f"warptissue: warning: {message}", file=sys.stderr)


def _finish(
    args: argparse.Namespace,
    result: FitResult,
    files: dict[str, Path],
    extra: dict[str, Any],
    lines: list[str] | None = None,
) -> int:
    """Print the summary (or JSON) and the warnings; exit status 0."""
    from warptissue.lsq.plausibility import convergence_warnings

    stopped = convergence_warnings(result)
    messages = stopped + [m for m in result.all_warnings if m not in stopped]
    _print_warnings(messages)
    if args.json:
        print(
            json.dumps(
                {"fit": result.to_dict(), **extra, "files": {k: str(v) for k, v in files.items()}},
                indent=2,
                default=str,
            )
        )
    else:
        print(result.summary(warnings=False))
        for line in lines or []:
            print(line)
        print(f"outputs in {files['json'].parent}")
    return 0


def _floor(args: argparse.Namespace, records: list[_Record]) -> float | None:
    """The relative objective's floor (N), or None for the absolute objective."""
    import numpy as np

    from warptissue.lsq.engine import RELATIVE_FLOOR_SHARE

    if args.objective != "relative":
        return None
    if args.relative_floor != "auto":
        return float(args.relative_floor)
    peak = max(float(np.max(np.abs(r.force_N))) for r in records)
    return RELATIVE_FLOOR_SHARE * peak if peak > 0 else None


def _predict(
    args: argparse.Namespace, result: FitResult, out_dir: Path, label: str
) -> tuple[list[dict[str, Any]], dict[str, Path], list[str]]:
    """Predict every ``--predict`` record; write its CSV and PNG; R^2 and RMSE."""
    from warptissue.io import write_csv
    from warptissue.lsq.metrics import r_squared, rmse
    from warptissue.report import plot_fit

    reports, files, lines = [], {}, []
    for path in args.predict:
        record = _read(path, args, required=("time_s", "displacement_m", "force_N"))
        predicted = result.fitted_model.force_N(record.time_s, record.displacement_m)
        name = f"{path.stem}_{label}_prediction"
        csv_path = write_csv(
            out_dir / f"{name}.csv",
            {
                "time_s": record.time_s,
                "displacement_m": record.displacement_m,
                "measured_force_N": record.force_N,
                "predicted_force_N": predicted,
            },
        )
        try:
            r2 = r_squared(record.force_N, predicted)
        except InputError:
            r2 = None
        error = rmse(record.force_N, predicted)
        png_path = plot_fit(
            out_dir / f"{name}.png",
            record.time_s,
            record.force_N,
            predicted,
            xlabel="time (s)",
            ylabel="force (N)",
            title=f"{path.name} predicted by the {args.model} fit, R^2 = "
            + ("n/a" if r2 is None else f"{r2:.4f}"),
            fitted_label="predicted",
            log_x=True,
        )
        files[f"prediction_csv:{path.name}"] = csv_path
        files[f"prediction_png:{path.name}"] = png_path
        reports.append(
            {
                "data_file": str(path),
                "r_squared": r2,
                "rmse_N": error,
                "conditioning": record.conditioning,
                "csv": str(csv_path),
                "png": str(png_path),
            }
        )
        lines.append(
            f"prediction of {path}: R^2 = {'n/a' if r2 is None else f'{r2:.6f}'}, "
            f"RMSE = {error:.6g} N"
        )
    return reports, files, lines


def _displacement_limit(args: argparse.Namespace) -> float:
    """The largest plausible displacement of the declared test, m: --max-displacement-m, else
    MAX_NOMINAL_STRAIN gauge lengths of a specimen (--gauge-length-m), else an indentation's
    MAX_INDENTATION_DEPTH_M."""
    from warptissue.fit.hyperelastic import MAX_NOMINAL_STRAIN
    from warptissue.lsq.plausibility import MAX_INDENTATION_DEPTH_M

    if args.max_displacement_m is not None:
        return args.max_displacement_m
    if args.gauge_length_m is not None:
        return MAX_NOMINAL_STRAIN * args.gauge_length_m
    return MAX_INDENTATION_DEPTH_M


def _fit_qlv(
    args: argparse.Namespace,
    records: list[_Record],
    terms: int,
    p0: list[float] | None,
    limit_m: float,
) -> FitResult:
    """``--model qlv:N``: :func:`warptissue.viscoelastic.fitting.fit_qlv` on the one record,
    with the per-record statistics the other models give; ``limit_m``: the largest plausible
    displacement (:func:`_displacement_limit`).

    Raises:
        InputError: Several records, the relative objective, or a record the fit refuses
            (no hold), naming the file.
    """
    from warptissue.lsq.metrics import r_squared, rmse
    from warptissue.viscoelastic.fitting import fit_qlv

    if len(records) != 1:
        raise InputError(
            "qlv fits one ramp-and-hold record (Ahn & Kim's stage (i)): give one file",
            option="--model",
            value=args.model,
        )
    if args.objective != "absolute":
        raise InputError("qlv fits the absolute force residuals", option="--objective")
    (record,) = records
    try:
        result = fit_qlv(
            record.time_s, record.displacement_m, record.force_N, terms=terms, p0=p0,
            method=args.method, max_displacement_m=limit_m,
        )  # fmt: skip
    except InputError as exc:
        raise _named(exc, record.path) from None
    result.record_rmse_N = [rmse(record.force_N, result.fitted)]
    result.record_r_squared = [r_squared(record.force_N, result.fitted)]
    return result


def run_relaxation(args: argparse.Namespace) -> int:
    """Fit, write JSON + CSV + PNG, print a summary (or JSON); return the exit status."""
    import numpy as np

    from warptissue.report import write_fit_outputs
    from warptissue.viscoelastic import RelaxationRecord, fit_relaxation_joint

    model, terms = parse_model(args.model)
    p0 = None
    if args.p0 is not None:
        try:
            p0 = [float(v) for v in args.p0.split(",")]
        except ValueError:
            raise InputError(f"--p0 needs comma-separated numbers (got {args.p0!r})") from None
    records = [
        _read(path, args, required=("time_s", "displacement_m", "force_N")) for path in args.data
    ]
    floor = _floor(args, records)
    limit = _displacement_limit(args)
    if model == "qlv":
        result = _fit_qlv(args, records, terms, p0, limit)
    else:
        result = fit_relaxation_joint(
            [
                RelaxationRecord(
                    r.time_s,
                    r.displacement_m,
                    r.force_N,
                    source=str(r.path),
                    conditioned=r.conditioned,
                    max_displacement_m=limit,
                )  # fmt: skip
                for r in records
            ],
            model=model,
            terms=terms,
            p0=p0,
            method=args.method,
            objective=args.objective,
            relative_floor=floor,
        )
    label = f"{model}{terms}" if model in ("prony", "qlv") else model
    stem = args.data[0].stem + ("_joint" if len(records) > 1 else "")
    details: dict[str, Any] = {
        "data_files": [str(p) for p in args.data],
        "model": result.fitted_model.to_dict()
        if model != "qlv"
        else {"model": "qlv", **result.parameters},
        "objective": args.objective,
        "relative_floor_N": floor,
        "conditioning": [r.conditioning for r in records],
        "records": [
            {"data_file": str(r.path), "rmse_N": e, "r_squared": q, "samples": int(r.time_s.size)}
            for r, e, q in zip(records, result.record_rmse_N, result.record_r_squared, strict=True)
        ],
    }
    if model == "sls":
        details["kim_et_al_eq4_printed_form"] = result.fitted_model.to_printed()
    out_dir = args.out if args.out is not None else Path(f"{stem}_relaxation_fit")
    columns: dict[str, Any] = {
        "time_s": np.concatenate([r.time_s for r in records]),
        "measured_force_N": np.concatenate([r.force_N for r in records]),
        "fitted_force_N": result.fitted,
        "displacement_m": np.concatenate([r.displacement_m for r in records]),
    }
    if len(records) > 1:
        columns["record"] = np.repeat(np.arange(len(records)), [r.time_s.size for r in records])
    predictions, prediction_files, lines = _predict(args, result, out_dir, label)
    if predictions:
        details["predictions"] = predictions
    files = write_fit_outputs(
        out_dir,
        f"{stem}_{label}",
        result,
        columns,
        metadata=details,
        title=f"{args.model} fit, R^2 = "
        + ("n/a" if result.r_squared is None else f"{result.r_squared:.4f}"),
        log_x=True,
        group_column="record" if len(records) > 1 else None,
        group_names=[r.path.name for r in records],
    )
    files.update(prediction_files)
    extra = {"model": details["model"], "records": details["records"]}
    if predictions:
        extra["predictions"] = predictions
    return _finish(args, result, files, extra, lines)


def run_punch_modulus(args: argparse.Namespace) -> int:
    """Fit E to a force-depth curve, write JSON + CSV + PNG; return the exit status."""
    import numpy as np

    from warptissue.fit.punch import fit_punch_modulus
    from warptissue.lsq.plausibility import check_indentation_record, elastic_curve_warnings
    from warptissue.report import write_fit_outputs

    record = _read(args.data, args, required=("displacement_m", "force_N"))
    # The signs as recorded (opposite signs are refused there), then their magnitudes: a
    # rig that records pushing as negative force and depth fits as one that records both
    # as positive.
    data_warnings = check_indentation_record(
        record.displacement_m, record.force_N, path=args.data, conditioned=record.conditioned
    )
    depth = np.abs(record.displacement_m)
    force = np.abs(record.force_N)
    data_warnings += elastic_curve_warnings(depth, force)
    loaded = depth > 0.0
    if np.count_nonzero(loaded) < 2:
        raise InputError(
            "needs at least two samples with non-zero depth",
            path=args.data,
            column="displacement_m",
        )
    try:
        result = fit_punch_modulus(
            depth[loaded],
            force[loaded],
            radius_m=args.radius_m,
            poissons_ratio=args.poissons_ratio,
            geometry=args.geometry,
            thickness_m=args.thickness_m,
        )
    except InputError as exc:
        raise _named(exc, args.data) from None
    result.warnings.extend(f"{args.data}: {m}" for m in data_warnings)
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
        "conditioning": record.conditioning,
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
