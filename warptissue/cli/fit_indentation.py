"""``warptissue fit indentation STUDY.toml``: inverse-FE fit of a study's material to its records.

The study file (schema version 2) names the specimen, the probe, the material, the measured
records (``[[data]]``) and what to fit (``[fit]``). The command runs
:func:`warptissue.fit.indentation.fit_indentation` (the FE force and its exact sensitivities
to the free parameters, Levenberg-Marquardt over all records at once; Ahn & Kim's two-stage
method with ``--strategy two_stage``) and writes, to ``OUT`` (default
``runs/<study name>-fit``), the files of
:func:`warptissue.report.write_indentation_fit_outputs`: ``fit.json``, ``fit_curves.csv``,
``fit.png``, ``fitted_study.toml`` (which ``warptissue simulate`` runs as it is) and, with
``--usd``, ``specimen.usda``.

Ctrl-C stops the fit: the files are written from the best parameters evaluated so far, and the
command exits with 130.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from warptissue.cli import EXIT_STATUSES
from warptissue.cli._args import device
from warptissue.errors import INTERRUPTED_EXIT_CODE, ConvergenceError, InputError

if TYPE_CHECKING:
    from warptissue.fit.indentation import IndentationFit

__all__ = ["register_fit", "run", "summary"]

STRATEGIES = ("joint", "two_stage")
"""``--strategy`` values: every free parameter at once, or Ahn & Kim's two stages."""
CONTACT_POINTS = ("given", "fit")
"""``--contact-point`` values: :data:`warptissue.study.CONTACT_POINTS`."""


def register_fit(subparsers: argparse._SubParsersAction) -> None:
    """Add ``warptissue fit indentation``."""
    interrupted = EXIT_STATUSES[INTERRUPTED_EXIT_CODE]
    parser = subparsers.add_parser(
        "indentation",
        help="fit a study's material parameters to its indentation records by inverse FE",
        description=(
            "Fit the free material parameters of a study (schema version 2: [[data]] records "
            "and a [fit] table) so that the FE probe force matches every measured record at "
            "once: Levenberg-Marquardt on the exact force sensitivities of the forward FE (one "
            "forward solve per iteration, whatever the number of parameters). --strategy "
            "two_stage is Ahn & Kim's method: the Prony series of each record from its "
            "relaxation first, then the remaining parameters by inverse FE with the Prony "
            "terms fixed. With [fit] contact_point = 'fit' each record's depth offset (the "
            "recorded depth at first touch) is fitted with the material. Writes fit.json, "
            "fit_curves.csv, fit.png and fitted_study.toml (the "
            "study with the fitted material; 'warptissue simulate' runs it as it is) to the "
            "output folder. Warnings (parameters not identified, systematic residuals, a "
            "parameter at its bound) go to stderr and to fit.json. Exit status: 0 fitted "
            "(warnings on stderr), 2 bad input or usage (one line naming the file, line and "
            f"key; also a two-stage record without a hold), 3 unusable mesh, "
            f"{ConvergenceError.exit_code} the fit failed or did not converge within "
            "max_iterations, or stage (i) of the two-stage fit did not converge on a record "
            "(the files are written from the best parameters; each stage (i) finding is a "
            "warning line naming the record), "
            f"5 device, 130 {interrupted}: the files are written from the best parameters "
            "found so far, 141 broken pipe."
        ),
    )
    parser.add_argument("study", type=Path, metavar="STUDY.toml", help="the study file")
    parser.add_argument(
        "-o",
        "--out",
        type=Path,
        default=None,
        metavar="DIR",
        help="output folder (default: runs/<study name>-fit)",
    )
    parser.add_argument(
        "--usd",
        action="store_true",
        help="also write the specimen with the fitted material as a USD scene "
        "(specimen.usda over specimen.asset.usda)",
    )
    parser.add_argument(
        "--strategy",
        choices=STRATEGIES,
        default=None,
        help="joint: all free parameters at once; two_stage: Ahn & Kim (Prony terms from the "
        "relaxation, then the rest by inverse FE); default: the study's [fit] strategy",
    )
    parser.add_argument(
        "--contact-point",
        choices=CONTACT_POINTS,
        default=None,
        help="given: the records' depths count from the contact as conditioned; fit: each "
        "record's depth offset (the recorded depth at first touch) is fitted with the "
        "material; default: the study's [fit] contact_point",
    )
    parser.add_argument(
        "--device",
        default=None,
        type=device,
        metavar="DEVICE",
        help="auto, cpu, cuda or cuda:N (default: the study's solver.device)",
    )
    parser.add_argument(
        "--json", action="store_true", help="print fit.json to stdout instead of the summary"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bars or summary")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """Handle ``warptissue fit indentation``; returns the exit status."""
    from warptissue.device import quiet_warp
    from warptissue.fit.indentation import fit_indentation
    from warptissue.report import write_indentation_fit_outputs
    from warptissue.study import load_study

    quiet_warp()
    study = load_study(args.study)
    if not study.data or study.fit is None:
        missing = "[[data]] records" if not study.data else "a [fit] table"
        raise InputError(
            f"has no {missing}: a study to fit needs schema_version = 2 with [[data]] and "
            "[fit] (docs/study-files.md)",
            path=args.study,
        )
    out_dir = args.out if args.out is not None else Path("runs") / f"{study.name}-fit"
    _check_out_dir(out_dir)
    fit = fit_indentation(
        study,
        device=args.device,
        progress=not (args.quiet or args.json),
        strategy=args.strategy,
        contact_point=args.contact_point,
    )
    files = write_indentation_fit_outputs(out_dir, fit, usd=args.usd)
    if args.json:
        sys.stdout.write(files["json"].read_text(encoding="utf-8"))
    elif not args.quiet:
        print(summary(fit))
        print(f"outputs in {out_dir}: " + ", ".join(p.name for p in files.values()))
    for message in fit.warnings:
        print(f"warptissue: warning: {message}", file=sys.stderr)
    if fit.status == "interrupted":
        print(
            f"warptissue: interrupted: the outputs in {out_dir} hold the best parameters "
            "found so far",
            file=sys.stderr,
        )
    elif fit.status == "stage_one_not_converged":
        print(
            f"warptissue: error: {fit.message}; the outputs in {out_dir} hold the fit from them",
            file=sys.stderr,
        )
    elif fit.exit_code != 0:
        what = "failed" if fit.status == "failed" else f"did not converge ({fit.status})"
        print(
            f"warptissue: error: the fit {what}: {fit.message}; the outputs in {out_dir} hold "
            "the best parameters found",
            file=sys.stderr,
        )
    return fit.exit_code


def _values(parameters: dict[str, float]) -> str:
    return ", ".join(f"{name} = {float(value):.6g}" for name, value in parameters.items())


def _check_out_dir(out_dir: Path) -> None:
    """Refuse, before the fit, an output folder that cannot be made (a file stands there)."""
    folder = out_dir
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise InputError(f"--out: {folder} is a file, not a folder", path=out_dir)


def summary(fit: IndentationFit) -> str:
    """The fit as a short text table: parameters (value, standard error, unit), each record's
    R^2 and RMSE (and its fitted contact point, with ``contact_point = "fit"``), the totals,
    forward solves against forward differences, status and time."""
    result = fit.result
    errors = result.standard_errors
    lines = []
    if fit.strategy == "two_stage":
        lines.append("stage (i), Ahn & Kim: Prony series of each record's relaxation (fit_qlv)")
        for record, stage in zip(fit.records, fit.stage_one_fits, strict=False):
            r2 = "n/a" if stage.r_squared is None else f"{stage.r_squared:.5f}"
            lines.append(f"  {record.file}: {_values(stage.parameters)}, R^2 = {r2}")
        lines.append(f"  mean, fixed in stage (ii): {_values(fit.stage_one_prony)}")
        lines.append("stage (ii), inverse FE:")
    width = max([len("parameter"), *(len(n) for n in result.parameter_names)])
    lines.append(f"{'parameter':<{width}}  {'value':>13}  {'std. error':>11}  unit")
    for i, name in enumerate(result.parameter_names):
        error = "n/a" if errors is None or errors[i] is None else f"{float(errors[i]):.4g}"
        lines.append(
            f"{name:<{width}}  {float(result.x[i]):>13.6g}  {error:>11}  "
            f"{result.parameter_units[i]}".rstrip()
        )
    for record in fit.records:
        r2 = "n/a" if record.r_squared is None else f"{record.r_squared:.5f}"
        touch = ""
        if record.depth_offset_m is not None:
            error = record.depth_offset_standard_error_m
            spread = "" if error is None else f" +- {error * 1e3:.2g}"
            touch = (
                f", contact fitted at recorded depth {record.depth_offset_m * 1e3:.4g}{spread} mm"
            )
        lines.append(f"  {record.file}: R^2 = {r2}, RMSE = {record.rmse_N:.4g} N{touch}")
    r2 = "n/a" if result.r_squared is None else f"{result.r_squared:.5f}"
    unit = "" if result.objective == "relative" else " N"
    lines.append(
        f"R^2 = {r2}, RMSE = {result.rmse:.4g}{unit}, {result.iterations} iterations, "
        f"{fit.forward_solves} forward solves (forward differences: "
        f"{fit.finite_difference_solves}), {fit.strategy.replace('_', '-')}, {fit.seconds:.1f} s"
    )
    lines.append(f"status: {fit.status}: {fit.message}")
    return "\n".join(lines)
