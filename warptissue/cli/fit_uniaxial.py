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
With ``--usd PATH`` the best model by R² is also written as a USD material layer (nearly
incompressible: bulk modulus K = --bulk-modulus-ratio x the initial shear modulus).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
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

    from warptissue.fit.hyperelastic import HomogeneousTest, fit_hyperelastic
    from warptissue.io import atomic_path, read_experiment_csv, write_json
    from warptissue.report import comparison_table

    names = _model_names(args.model)
    if args.min_strain is not None and not (
        math.isfinite(args.min_strain) and 0.0 <= args.min_strain < 1.0
    ):
        raise InputError("--min-strain must be a nominal strain in [0, 1)", value=args.min_strain)
    if args.usd is not None:
        if args.usd.suffix != ".usda":
            raise InputError("--usd must name a .usda file", path=args.usd)
        if not args.bulk_modulus_ratio > 1.0:
            raise InputError("--bulk-modulus-ratio must be > 1", value=args.bulk_modulus_ratio)
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
    out_dir = _output_folder(args)
    rows, files, fits = [], {}, {}
    for name in names:
        fit = fit_hyperelastic(
            name, test, objective=args.objective, min_strain=args.min_strain, method=args.method
        )
        summary = fit.result.to_dict()
        files[name] = _write_model_outputs(args, out_dir, name, fit, summary, record)
        rows.append(
            {
                **fit.comparison_row(),
                "model": name,
                "identified": summary["identified"],
                "parameters": summary["parameters"],
                "warnings": summary["warnings"],
            }
        )
        fits[name] = fit
        if not fit.result.success:
            print(f"warptissue: warning: {name}: {fit.result.message}", file=sys.stderr)
        for message in summary["warnings"]:
            print(f"warptissue: warning: {name}: {message}", file=sys.stderr)
    rows.sort(key=lambda row: -np.inf if row["r_squared"] is None else -row["r_squared"])
    table = comparison_table([_table_row(row) for row in rows])
    stem = f"{args.data.stem}_comparison"
    with atomic_path(out_dir / f"{stem}.txt") as temporary:
        temporary.write_text(table + "\n", encoding="utf-8")
    files["comparison"] = {
        "txt": out_dir / f"{stem}.txt",
        "json": write_json(out_dir / f"{stem}.json", {"models": rows}),
    }
    if args.usd is not None:
        files["usd"] = {"material": _write_best_usd(args, rows[0], fits[rows[0]["model"]])}
    if args.json:
        listing = {label: {k: str(v) for k, v in paths.items()} for label, paths in files.items()}
        print(json.dumps({"models": rows, "files": listing}, indent=2))
    else:
        print(table)
        print(f"outputs in {out_dir}")
    return 0


def _output_folder(args: argparse.Namespace) -> Path:
    """The ``--out`` folder (default ``STEM_uniaxial_fit``), created.

    Raises:
        InputError: It exists and is not a folder, or it cannot be created.
    """

    folder = args.out if args.out is not None else Path(f"{args.data.stem}_uniaxial_fit")
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
    table = {key: value for key, value in row.items() if key not in ("parameters", "warnings")}
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
    provenance = {
        "data_file": str(args.data),
        "fit": {
            "command": "warptissue fit uniaxial",
            "model": row["model"],
            "objective": args.objective,
            "loading": args.loading,
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
