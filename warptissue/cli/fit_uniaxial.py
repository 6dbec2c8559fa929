"""``warptissue fit uniaxial``: fit hyperelastic models to a homogeneous test record.

Reads a CSV with ``displacement_m,force_N`` (``time_s`` optional; when present it must
increase), converts it to nominal strain d / H0 and nominal stress F / A0 (magnitudes,
positive in the loading direction: for ``--loading compression`` a shortening and a
compressive force are positive), fits each model, and writes per model ``NAME.json``,
``NAME.csv`` and ``NAME.png`` plus a comparison table ranked by R² with each model's fitted
parameters (value, unit, standard error), whether they are identified, and its Drucker
stable range (``STEM_comparison.txt`` and ``.json``). A parameter the data do not determine
(standard error larger than its value, pinned at a bound, singular covariance) is flagged
with a ``warning:`` line on stderr and ``"identified": false``; the exit status stays 0.
With ``--usd PATH`` the best model by R² that is identified and Drucker-stable in the tested
range is also written as a USD material layer (nearly incompressible: bulk modulus K =
--bulk-modulus-ratio x the initial shear modulus). Exit status: 0 fitted (warnings on
stderr), 2 bad input or usage (one line naming the file, column or option; also --usd
where no model is identified and stable), 141 broken pipe.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from warptissue.cli._args import positive_length_m, positive_number
from warptissue.errors import InputError

__all__ = ["ALL_MODELS", "register_fit"]

ALL_MODELS: tuple[str, ...] = (
    "neo_hookean",
    "mooney_rivlin",
    "reduced_polynomial:2",
    "yeoh",
    "ogden:1",
    "ogden:2",
)
"""The models fitted by ``--model all``."""


def register_fit(subparsers: argparse._SubParsersAction) -> None:
    """Add ``warptissue fit uniaxial``."""
    parser = subparsers.add_parser(
        "uniaxial",
        help="fit hyperelastic models to a homogeneous (uniaxial, biaxial, planar) test",
        description=__doc__.split("\n\n", 1)[1],
    )
    parser.add_argument("data", type=Path, help="CSV with displacement_m,force_N [,time_s]")
    parser.add_argument(
        "--area-m2",
        type=positive_number,
        required=True,
        help="undeformed loaded area A0, m^2 (70 x 80 mm is 0.0056)",
    )
    parser.add_argument(
        "--height-m",
        type=positive_length_m,
        required=True,
        help="undeformed height (gauge length) H0: metres, or with a unit (80mm)",
    )
    parser.add_argument(
        "--model",
        default="all",
        help="neo_hookean, mooney_rivlin, reduced_polynomial:N, yeoh, ogden:N, a "
        "comma-separated list, or all (default)",
    )
    parser.add_argument(
        "--objective",
        choices=("absolute", "relative"),
        default="absolute",
        help="least squares of the stress (absolute, default) or of its relative error "
        "(the needle-indentation study's Eq. 4 and 5)",
    )
    parser.add_argument(
        "--min-strain",
        type=float,
        default=None,
        help="fit only points above this nominal strain (default 0.05 for relative, else 0)",
    )
    parser.add_argument(
        "--loading",
        choices=("compression", "tension", "equibiaxial", "planar"),
        default="compression",
        help="the test: uniaxial compression (default) or tension, equibiaxial tension, or "
        "planar tension (pure shear)",
    )
    parser.add_argument(
        "--method",
        choices=("lm", "salm"),
        default="lm",
        help="Levenberg-Marquardt (default) or Tong et al.'s self-adapting LM",
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default STEM_uniaxial_fit)"
    )
    parser.add_argument(
        "--usd",
        type=Path,
        default=None,
        metavar="PATH",
        help="write the best model by R^2 as a USD material layer (.usda)",
    )
    parser.add_argument(
        "--usd-any-model",
        action="store_true",
        help="with --usd, write the best model by R^2 even where it is not identified or "
        "not Drucker-stable in the tested range (by default the best model that is both is "
        "written, and the command says so when that is not the best by R^2)",
    )
    parser.add_argument(
        "--bulk-modulus-ratio",
        type=positive_number,
        default=1000.0,
        help="K / mu0 of the --usd material, > 1 (default 1000, nu about 0.4995)",
    )
    parser.add_argument(
        "--density-kg-per-m3",
        type=positive_number,
        default=1000.0,
        help="density of the --usd material",
    )
    parser.add_argument(
        "--json", action="store_true", help="print the comparison as JSON instead of a table"
    )
    parser.set_defaults(handler=run)
    _register_joint(subparsers)


JOINT_DESCRIPTION = """\
Fit hyperelastic models jointly to one or several homogeneous tests, each a CSV file with its
loading (--test LOADING FILE, repeated): uniaxial tension or compression, equibiaxial
tension, planar tension (pure shear). A file gives the deformation as stretch (the loading
direction's L / L0), nominal_strain, or displacement_m (with --height-m), and the stress as
nominal_stress_Pa, nominal_stress_kPa or nominal_stress_MPa (force per undeformed area), or
force_N (with displacement_m and --area-m2); magnitudes in the loading direction. Writes per
model NAME.json (the fit, each test's R^2 and RMSE, the predicted stress in every loading
over the fitted stretch range, the Drucker check) and a comparison ranked by R^2
(hyperelastic_comparison.txt and .json); prints the table, each model's error in each test
and its stress in each loading at the largest fitted stretch, tested or predicted. Warnings
on stderr (exit status 0): parameters not identified, Drucker instability in the tested
range, a loading not tested where the model predicts an absurd stress or is unstable. With
--usd the best model by R^2 that is identified and stable is written as a USD material.
Exit status: 0 fitted (warnings on stderr), 2 bad input or usage (one line naming the file,
column or option; also --usd where no model is identified and stable), 141 broken pipe."""


def _register_joint(subparsers: argparse._SubParsersAction) -> None:
    """Add ``warptissue fit hyperelastic``."""
    parser = subparsers.add_parser(
        "hyperelastic",
        help="fit hyperelastic models jointly to homogeneous tests (uniaxial, equibiaxial, "
        "planar), each file with its loading",
        description=JOINT_DESCRIPTION,
    )
    parser.add_argument(
        "--test",
        nargs=2,
        action="append",
        required=True,
        metavar=("LOADING", "FILE"),
        help="a test: its loading (tension, compression, equibiaxial or planar) and its CSV; "
        "repeat for a joint fit",
    )
    _copy_option(subparsers.choices["uniaxial"], parser, "--model")
    parser.add_argument(
        "--area-m2",
        type=positive_number,
        default=None,
        help="undeformed loaded area A0 of the files with force_N, m^2",
    )
    parser.add_argument(
        "--height-m",
        type=positive_length_m,
        default=None,
        help="undeformed gauge length H0 of the files with displacement_m (80mm)",
    )
    for option in ("--objective", "--min-strain", "--method"):
        _copy_option(subparsers.choices["uniaxial"], parser, option)
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default hyperelastic_fit)"
    )
    for option in (
        "--usd", "--usd-any-model", "--bulk-modulus-ratio", "--density-kg-per-m3", "--json",
    ):  # fmt: skip
        _copy_option(subparsers.choices["uniaxial"], parser, option)
    parser.set_defaults(handler=run_joint)


def _copy_option(source: argparse.ArgumentParser, target: argparse.ArgumentParser, option: str):
    """Give ``target`` the option ``option`` of ``source``, as it is there (one definition)."""
    action = source._option_string_actions[option]
    keywords: dict[str, Any] = {"default": action.default, "help": action.help}
    if isinstance(action, argparse._StoreTrueAction):
        keywords["action"] = "store_true"
    else:
        keywords.update(type=action.type, choices=action.choices, metavar=action.metavar)
    target.add_argument(*action.option_strings, dest=action.dest, **keywords)


def run_joint(args: argparse.Namespace) -> int:
    """Handle ``warptissue fit hyperelastic``; returns the exit status."""
    from warptissue.fit.hyperelastic import LOADINGS, read_homogeneous_test

    names = _model_names(args.model)
    _check_options(args)
    tests = []
    for loading, path in args.test:
        if loading not in LOADINGS:
            raise InputError(
                f"--test: the loading must be one of {', '.join(LOADINGS)}",
                path=path,
                value=loading,
            )
        tests.append(
            read_homogeneous_test(
                Path(path), loading=loading, area_m2=args.area_m2, height_m=args.height_m
            )
        )
    out_dir = _output_folder(args.out, Path("hyperelastic_fit"))

    def write(name: str, fit: Any, summary: dict[str, Any]) -> dict[str, Path]:
        from warptissue.io import write_json

        details = {
            **fit.to_dict(),
            "tests": fit.test_errors(),
            "predictions": fit.mode_predictions(),
            "data_files": [{"loading": loading, "file": path} for loading, path in args.test],
        }
        return {"json": write_json(out_dir / f"{name.replace(':', '_')}.json", details)}

    return _fit_models(args, names, tests, out_dir, "hyperelastic", write)


def _model_names(text: str) -> tuple[str, ...]:
    """The ``--model`` list: canonical labels (``reduced_polynomial`` -> ``:2``), in order,
    each once.

    Raises:
        InputError: An empty entry or an unknown model, naming ``--model``.
    """
    from warptissue.fit.hyperelastic import model_from_name, model_label

    if text.strip().lower() == "all":
        return ALL_MODELS
    names: list[str] = []
    for entry in text.split(","):
        spec = entry.strip().lower()
        if not spec:
            raise InputError("--model has an empty entry", value=text)
        try:
            model = model_from_name(spec)
        except InputError as exc:
            raise InputError(f"--model: {exc.message}", value=entry) from None
        label = "yeoh" if spec == "yeoh" else model_label(model)
        if label not in names:
            names.append(label)
    return tuple(names)


def run(args: argparse.Namespace) -> int:
    """Fit, write the outputs, print the comparison; return the exit status."""
    import numpy as np

    from warptissue.fit.hyperelastic import HomogeneousTest
    from warptissue.io import read_experiment_csv

    names = _model_names(args.model)
    _check_options(args)
    record = read_experiment_csv(
        args.data, required=("displacement_m", "force_N"), monotonic="time_s"
    )
    test = HomogeneousTest.from_force_displacement(
        record["displacement_m"],
        record["force_N"],
        area_m2=args.area_m2,
        height_m=args.height_m,
        loading=args.loading,
        name=args.data.stem,
        path=args.data,
    )
    largest_strain = float(np.max(test.nominal_strain))
    if args.min_strain is not None and args.min_strain >= largest_strain:
        raise InputError(
            f"--min-strain {args.min_strain:g} leaves no data: the record's largest nominal "
            f"strain is {largest_strain:.4g}",
            path=args.data,
        )
    out_dir = _output_folder(args.out, Path(f"{args.data.stem}_uniaxial_fit"))

    def write(name: str, fit: Any, summary: dict[str, Any]) -> dict[str, Path]:
        return _write_model_outputs(args, out_dir, name, fit, summary, record)

    return _fit_models(args, names, [test], out_dir, args.data.stem, write)


def _check_options(args: argparse.Namespace) -> None:
    """Refuse a bad --min-strain, --usd or --bulk-modulus-ratio before any fit."""
    if args.min_strain is not None and not (
        math.isfinite(args.min_strain) and 0.0 <= args.min_strain < 1.0
    ):
        raise InputError("--min-strain must be a nominal strain in [0, 1)", value=args.min_strain)
    if args.usd is not None:
        if args.usd.suffix != ".usda":
            raise InputError("--usd must name a .usda file", path=args.usd)
        if not args.bulk_modulus_ratio > 1.0:
            raise InputError("--bulk-modulus-ratio must be > 1", value=args.bulk_modulus_ratio)


def _fit_models(
    args: argparse.Namespace,
    names: Sequence[str],
    tests: Sequence[Any],
    out_dir: Path,
    stem: str,
    write: Callable[[str, Any, dict[str, Any]], dict[str, Path]],
) -> int:
    """Fit every model to the tests (jointly), write each model's files with ``write``, the
    comparison ranked by R^2 and the --usd material; print the table (or JSON) and the
    warnings; return the exit status (0)."""
    import numpy as np

    from warptissue.fit.hyperelastic import fit_hyperelastic
    from warptissue.io import atomic_path, write_json
    from warptissue.report import comparison_table

    rows, files, fits = [], {}, {}
    for name in names:
        fit = fit_hyperelastic(
            name, tests, objective=args.objective, min_strain=args.min_strain, method=args.method
        )
        summary = fit.result.to_dict()
        files[name] = write(name, fit, summary)
        rows.append(
            {
                **fit.comparison_row(),
                "model": name,
                "identified": summary["identified"],
                "parameters": summary["parameters"],
                "warnings": summary["warnings"],
                "tests": fit.test_errors(),
                "predictions": fit.mode_predictions(),
            }
        )
        fits[name] = fit
        if not fit.result.success:
            print(f"warptissue: warning: {name}: {fit.result.message}", file=sys.stderr)
        for message in summary["warnings"]:
            print(f"warptissue: warning: {name}: {message}", file=sys.stderr)
    rows.sort(key=lambda row: -np.inf if row["r_squared"] is None else -row["r_squared"])
    table = comparison_table([_table_row(row) for row in rows])
    with atomic_path(out_dir / f"{stem}_comparison.txt") as temporary:
        temporary.write_text(table + "\n", encoding="utf-8")
    files["comparison"] = {
        "txt": out_dir / f"{stem}_comparison.txt",
        "json": write_json(out_dir / f"{stem}_comparison.json", {"models": rows}),
    }
    if args.usd is not None:
        chosen = _exported_row(rows, fits, any_model=args.usd_any_model)
        files["usd"] = {"material": _write_best_usd(args, chosen, fits[chosen["model"]])}
    if args.json:
        listing = {label: {k: str(v) for k, v in paths.items()} for label, paths in files.items()}
        print(json.dumps({"models": rows, "files": listing}, indent=2))
    else:
        print(table)
        for row in rows:
            print(_test_lines(row))
        print(f"outputs in {out_dir}")
    return 0


def _exported_row(
    rows: Sequence[dict[str, Any]], fits: dict[str, Any], *, any_model: bool
) -> dict[str, Any]:
    """The model --usd writes: the best by R^2 that is identified and Drucker-stable in the
    tested range (said on stderr when it is not the best by R^2), or with ``any_model`` the
    best by R^2.

    Raises:
        InputError: No model is both (naming --usd and --usd-any-model).
    """
    if any_model:
        return rows[0]
    sound = [
        row
        for row in rows
        if row["identified"]
        and row["unstable_from_strain_tested_modes"] is None
        and fits[row["model"]].result.success
    ]
    if not sound:
        raise InputError(
            "no fitted model is identified and Drucker-stable in the tested range, so none is "
            "written (--usd-any-model writes the best by R^2 anyway)",
            option="--usd",
        )
    if sound[0] is not rows[0]:
        print(
            f"warptissue: warning: --usd: the best model by R^2, {rows[0]['model']}, is not "
            "identified or not Drucker-stable in the tested range; writing the best one that "
            f"is, {sound[0]['model']} (--usd-any-model writes {rows[0]['model']})",
            file=sys.stderr,
        )
    return sound[0]


def _test_lines(row: dict[str, Any]) -> str:
    """A model's error in each test and its nominal stress in each loading at the largest
    stretch of the fitted range (tested or predicted)."""
    lines = [f"{row['model']}:"]
    for test in row["tests"]:
        r2 = "n/a" if test["r_squared"] is None else f"{test['r_squared']:.5f}"
        lines.append(
            f"  {test['test']} ({test['loading']}): R^2 = {r2}, RMSE = {test['rmse_Pa']:.4g} Pa"
        )
    for entry in row["predictions"]:
        what = "tested" if entry["tested"] else "predicted"
        lines.append(
            f"  {entry['loading']} at stretch {entry['stretch'][-1]:.3g}: nominal stress "
            f"{entry['nominal_stress_Pa'][-1]:.4g} Pa ({what})"
        )
    return "\n".join(lines)


def _output_folder(out: Path | None, default: Path) -> Path:
    """The ``--out`` folder (``default`` without one), created.

    Raises:
        InputError: It exists and is not a folder, or it cannot be created.
    """

    folder = out if out is not None else default
    if folder.exists() and not folder.is_dir():
        raise InputError("--out must name a folder, not a file", path=folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--out: cannot create the folder ({exc.strerror})", path=folder) from None
    return folder


def _format_parameter(name: str, entry: dict[str, Any]) -> str:
    """``C10_Pa = 600.9 +- 0.42 Pa``: value, standard error and unit of a fitted parameter."""
    unit = entry["unit"]
    error = entry["standard_error"]
    spread = "" if error is None else f" +- {error:.2g}"
    return f"{name} = {entry['value']:.6g}{spread}{' ' + unit if unit else ''}"


def _table_row(row: dict[str, Any]) -> dict[str, Any]:
    """A comparison row for the text table: identified as yes/no, parameters as text."""
    hidden = ("parameters", "warnings", "tests", "predictions")
    table = {key: value for key, value in row.items() if key not in hidden}
    table["identified"] = "yes" if row["identified"] else "no"
    table["parameters"] = ", ".join(
        _format_parameter(name, entry) for name, entry in row["parameters"].items()
    )
    return table


def _write_model_outputs(
    args: argparse.Namespace,
    out_dir: Path,
    name: str,
    fit: Any,
    summary: dict[str, Any],
    record: Any,
) -> dict[str, Path]:
    """Write one model's JSON (fit result and metadata), CSV (every point) and PNG plot
    (:func:`warptissue.report.write_fit_outputs`: axes with units, the fitted parameters in
    the legend, large records decimated for the plot only)."""
    import numpy as np

    from warptissue.report import write_fit_outputs

    test = fit.tests[0]
    fitted_stress = test.predicted_stress_Pa(fit.model)
    in_window = test.nominal_strain > fit.min_strain if fit.min_strain > 0.0 else None
    metadata = fit.to_dict()
    metadata.pop("fit")
    metadata.update(
        {
            "data_file": str(args.data),
            "area_m2": args.area_m2,
            "height_m": args.height_m,
            "loading": args.loading,
            "sign_convention": "strain and stress are magnitudes, positive in the "
            "loading direction",
        }
    )
    r_squared = "n/a" if summary["r_squared"] is None else f"{summary['r_squared']:.5f}"
    title = f"{name} ({args.objective} objective), R² = {r_squared}"
    if not summary["identified"]:
        title += "\nparameters not identified (see the warnings)"
    return write_fit_outputs(
        out_dir,
        f"{args.data.stem}_{name.replace(':', '_')}",
        fit.result,
        {
            "nominal_strain": test.nominal_strain,
            "measured_nominal_stress_Pa": test.nominal_stress_Pa,
            "fitted_nominal_stress_Pa": fitted_stress,
            "displacement_m": record["displacement_m"],
            "measured_force_N": record["force_N"],
            "fitted_force_N": fitted_stress * args.area_m2,
            "in_fit_window": np.ones(fitted_stress.size) if in_window is None else in_window * 1.0,
        },
        metadata=metadata,
        title=title,
    )


def _write_best_usd(args: argparse.Namespace, row: dict[str, Any], fit: Any) -> Path:
    """Write the best fit as a USD material layer with the fit's quality as provenance."""
    from warptissue.usd import write_material_usd

    model = fit.model
    bulk_modulus_Pa = args.bulk_modulus_ratio * model.initial_shear_modulus_Pa
    joint = getattr(args, "test", None)
    provenance = {
        "data_file": str(args.data) if joint is None else [path for _, path in joint],
        "fit": {
            "command": f"warptissue fit {'uniaxial' if joint is None else 'hyperelastic'}",
            "model": row["model"],
            "objective": args.objective,
            "loading": args.loading if joint is None else [loading for loading, _ in joint],
            "r_squared": row["r_squared"],
            "rmse_Pa": row["rmse_Pa"],
            "status": row["status"],
            "identified": row["identified"],
            "bulk_modulus_ratio": args.bulk_modulus_ratio,
        },
    }
    return write_material_usd(
        args.usd,
        model.with_bulk_modulus(bulk_modulus_Pa),
        provenance=provenance,
        density_kg_per_m3=args.density_kg_per_m3,
    )
