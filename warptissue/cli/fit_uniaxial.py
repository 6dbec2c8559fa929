"""``warptissue fit uniaxial``: fit hyperelastic models to a homogeneous test record.

Reads a CSV with ``displacement_m,force_N`` (``time_s`` optional; when present it must
increase), converts it to nominal strain d / H0 and nominal stress F / A0 (magnitudes,
positive in the loading direction: for ``--loading compression`` a shortening and a
compressive force are positive), fits each model, and writes per model ``NAME.json``,
``NAME.csv`` and ``NAME.png`` plus a comparison table ranked by R² with each model's Drucker
stable range (``STEM_comparison.txt`` and ``.json``). With ``--usd PATH`` the best model by
R² is also written as a USD material layer (nearly incompressible: bulk modulus
K = --bulk-modulus-ratio x the initial shear modulus).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

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
    parser.add_argument("--area-m2", type=float, required=True, help="undeformed area A0, m^2")
    parser.add_argument("--height-m", type=float, required=True, help="undeformed height H0, m")
    parser.add_argument(
        "--model",
        default="all",
        help="neo_hookean, mooney_rivlin, reduced_polynomial:N, yeoh, ogden:N, a "
        "comma-separated list, or all (default)",
    )
    parser.add_argument("--objective", choices=("absolute", "relative"), default="absolute")
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
    )
    parser.add_argument("--method", choices=("lm", "salm"), default="lm")
    parser.add_argument("--out", type=Path, default=None, help="output folder")
    parser.add_argument(
        "--usd",
        type=Path,
        default=None,
        metavar="PATH",
        help="write the best model by R^2 as a USD material layer (.usda)",
    )
    parser.add_argument(
        "--bulk-modulus-ratio",
        type=float,
        default=1000.0,
        help="K / mu0 of the --usd material (default 1000, nu about 0.4995)",
    )
    parser.add_argument(
        "--density-kg-per-m3", type=float, default=1000.0, help="density of the --usd material"
    )
    parser.add_argument(
        "--json", action="store_true", help="print the comparison as JSON instead of a table"
    )
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """Fit, write the outputs, print the comparison; return the exit status."""
    import numpy as np

    from warptissue.errors import InputError
    from warptissue.fit.hyperelastic import HomogeneousTest, fit_hyperelastic, model_from_name
    from warptissue.io import read_experiment_csv
    from warptissue.report import comparison_table, write_comparison, write_fit_outputs

    names = ALL_MODELS if args.model == "all" else tuple(args.model.split(","))
    if args.usd is not None:
        if args.usd.suffix != ".usda":
            raise InputError("--usd must name a .usda file", path=args.usd)
        if not (np.isfinite(args.bulk_modulus_ratio) and args.bulk_modulus_ratio > 1.0):
            raise InputError("--bulk-modulus-ratio must be > 1", value=args.bulk_modulus_ratio)
    for name in names:
        model_from_name(name)
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
    )
    out_dir = args.out if args.out is not None else Path(f"{args.data.stem}_uniaxial_fit")
    rows, files, fits = [], {}, {}
    for name in names:
        fit = fit_hyperelastic(
            name, test, objective=args.objective, min_strain=args.min_strain, method=args.method
        )
        fitted_stress = test.predicted_stress_Pa(fit.model)
        window = fit.min_strain
        in_window = test.nominal_strain > window if window > 0.0 else np.ones_like(fitted_stress)
        label = name.replace(":", "_")
        r_squared = "n/a" if fit.result.r_squared is None else f"{fit.result.r_squared:.4f}"
        details = fit.to_dict()
        details.pop("fit")
        details.update(
            {
                "data_file": str(args.data),
                "area_m2": args.area_m2,
                "height_m": args.height_m,
                "loading": args.loading,
                "sign_convention": "strain and stress are magnitudes, positive in the "
                "loading direction",
            }
        )
        files[name] = write_fit_outputs(
            out_dir,
            f"{args.data.stem}_{label}",
            fit.result,
            {
                "nominal_strain": test.nominal_strain,
                "measured_nominal_stress_Pa": test.nominal_stress_Pa,
                "fitted_nominal_stress_Pa": fitted_stress,
                "displacement_m": record["displacement_m"],
                "measured_force_N": record["force_N"],
                "fitted_force_N": fitted_stress * args.area_m2,
                "in_fit_window": in_window.astype(np.float64),
            },
            metadata=details,
            title=f"{name} ({args.objective}), R^2 = {r_squared}",
        )
        rows.append({**fit.comparison_row(), "model": name})
        fits[name] = fit
        if not fit.result.success:
            print(f"warptissue: warning: {name}: {fit.result.message}", file=sys.stderr)
    rows.sort(key=lambda row: -np.inf if row["r_squared"] is None else -row["r_squared"])
    files["comparison"] = write_comparison(out_dir, f"{args.data.stem}_comparison", rows)
    if args.usd is not None:
        files["usd"] = {"material": _write_best_usd(args, rows[0], fits[rows[0]["model"]])}
    if args.json:
        listing = {label: {k: str(v) for k, v in paths.items()} for label, paths in files.items()}
        print(json.dumps({"models": rows, "files": listing}, indent=2))
    else:
        print(comparison_table(rows))
        print(f"outputs in {out_dir}")
    return 0


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
            "bulk_modulus_ratio": args.bulk_modulus_ratio,
        },
    }
    return write_material_usd(
        args.usd,
        model.with_bulk_modulus(bulk_modulus_Pa),
        provenance=provenance,
        density_kg_per_m3=args.density_kg_per_m3,
    )
