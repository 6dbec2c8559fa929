"""``warptissue fit field``: heterogeneous linear elastic field from surface markers.

Tong et al.: the markers' grid becomes a block of hexahedra (5 tets each, base fixed), each
hexahedron with its own (E, nu). Per load set, markers are split into training and test
markers, the homogeneous linear estimate (Eq. 13-14) and the heterogeneous field
are estimated, and both are evaluated on the test markers (Table 3). Writes per load set
``field_<set>.json``, ``field_<set>_cells.csv``, ``field_<set>_test_markers.csv``,
``field_<set>.png`` (E, nu and error-bound maps) and ``field_<set>.vtu``, plus
``field_summary.csv``.
Each cell's E and nu come with an error bound (the bound on the Tikhonov regularization's
bias, for a true field within --alpha-deviation and --nu-deviation of the homogeneous
estimate, plus 2 standard errors); a cell's E counts as constrained when its resolution is at
least 0.9 and its bound at most 10%. Implausible data or results (a unit likely off, strains
beyond linear elasticity, no convergence, parameters not identified, no constrained cell) are
reported as ``warning:`` lines on stderr and in the JSON; the exit status stays 0. Bad input
(a file, a value, markers moving against the force) is one line on stderr, exit status 2.
With ``--usd PATH`` each load set's mesh is also written as a USD scene: the heterogeneous
(E, nu) per tet as the uniform primvars ``tissue:youngsModulus`` (Pa) and
``tissue:poissonsRatio`` of the TetMesh (and per face of the surface Mesh), the hexahedron
(group) of each tet as its ``materialRegion`` subset, and, bound as the one physics material
for simulators that read a single one, the homogeneous linear estimate (E0, nu0). One load
set writes PATH; several write ``STEM_<set>.usda`` beside it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from warptissue.cli._args import (
    nonnegative_int,
    positive_int,
    positive_length_m,
    positive_number,
)
from warptissue.errors import InputError

__all__ = ["register_fit"]


def register_fit(subparsers: argparse._SubParsersAction) -> None:
    """Add ``warptissue fit field``."""
    parser = subparsers.add_parser(
        "field",
        help="estimate a heterogeneous (E, nu) field from surface markers (Tong et al.)",
        description=__doc__.split("\n\n", 1)[1],
    )
    parser.add_argument(
        "markers", type=Path, help="CSV: [load_set,]marker,x0_m,y0_m,z0_m,x1_m,y1_m,z1_m"
    )
    parser.add_argument(
        "--forces", type=Path, required=True, help="CSV: [load_set,]marker,fx_N,fy_N,fz_N"
    )
    parser.add_argument(
        "--thickness-m",
        type=positive_length_m,
        required=True,
        help="block thickness below the markers, m (or with a unit: 30mm)",
    )
    parser.add_argument(
        "--layers", type=positive_int, default=1, help="hexahedra through the thickness"
    )
    parser.add_argument(
        "--test-markers", type=positive_int, default=50, help="markers held out for evaluation"
    )
    parser.add_argument(
        "--seed",
        type=nonnegative_int,
        default=0,
        help="seed of the train/test split (an integer >= 0)",
    )
    parser.add_argument("--objective", choices=("displacement", "force"), default="displacement")
    parser.add_argument(
        "--gamma", type=positive_number, default=1e-5, help="Tikhonov weight (Eq. 6), > 0"
    )
    parser.add_argument("--method", choices=("salm", "lm"), default="salm")
    parser.add_argument("--max-iterations", type=positive_int, default=60)
    parser.add_argument(
        "--alpha-deviation",
        type=positive_number,
        default=None,
        metavar="FRACTION",
        help="assumed largest relative deviation of the true alpha = E/((1+nu)(1-2nu)) from "
        "the homogeneous estimate in any cell, for the error bounds (default: the fitted "
        "field's largest deviation)",
    )
    parser.add_argument(
        "--nu-deviation",
        type=positive_number,
        default=None,
        metavar="NU",
        help="assumed largest deviation of the true nu from the homogeneous estimate in any "
        "cell (default: the fitted field's largest deviation)",
    )
    parser.add_argument(
        "--load-set", action="append", default=None, help="only this load set (repeatable)"
    )
    parser.add_argument("--device", default="cpu", help="Warp device (cpu, cuda:0)")
    parser.add_argument("--out", type=Path, default=Path("field_out"), help="output folder")
    parser.add_argument(
        "--usd",
        type=Path,
        default=None,
        metavar="PATH",
        help="write the mesh, the per-tet (E, nu) field and the homogeneous estimate as a "
        "USD scene (.usda)",
    )
    parser.add_argument(
        "--density-kg-per-m3",
        type=positive_number,
        default=1000.0,
        help="density of the --usd material",
    )
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """Handle ``warptissue fit field``."""
    from tqdm import tqdm

    from warptissue.field.estimation import CONSTRAINED_YOUNGS_ERROR
    from warptissue.field.markers import read_forces_csv, read_markers_csv
    from warptissue.field.pipeline import estimate_load_set, write_load_set_outputs
    from warptissue.io import write_csv

    if args.usd is not None and args.usd.suffix != ".usda":
        raise InputError("--usd must name a .usda file", path=args.usd)
    markers = read_markers_csv(args.markers)
    forces = read_forces_csv(args.forces)
    load_sets = _checked_load_sets(args, markers, forces)
    rows = []
    for label in tqdm(load_sets, desc="load sets", unit="set"):
        result = estimate_load_set(
            markers,
            forces[label],
            load_set=label,
            thickness_m=args.thickness_m,
            layers=args.layers,
            test_count=args.test_markers,
            seed=args.seed,
            objective=args.objective,
            gamma=args.gamma,
            method=args.method,
            max_iterations=args.max_iterations,
            alpha_deviation=args.alpha_deviation,
            nu_deviation=args.nu_deviation,
            device=args.device,
        )
        write_load_set_outputs(args.out, result)
        if args.usd is not None:
            usd_path = args.usd
            if len(load_sets) > 1:
                usd_path = args.usd.with_name(f"{args.usd.stem}_{label}.usda")
            _write_usd(usd_path, args, result)
        rows.append(result)
    write_csv(
        args.out / "field_summary.csv",
        {
            "load_set": [r.load_set for r in rows],
            "homogeneous_E_Pa": [r.homogeneous.youngs_modulus_Pa for r in rows],
            "homogeneous_nu": [r.homogeneous.poissons_ratio for r in rows],
            "homogeneous_max_error_m": [r.homogeneous_errors["max_error_m"] for r in rows],
            "homogeneous_mean_error_m": [r.homogeneous_errors["mean_error_m"] for r in rows],
            "field_max_error_m": [r.field_errors["max_error_m"] for r in rows],
            "field_mean_error_m": [r.field_errors["mean_error_m"] for r in rows],
            "constrained_youngs_cells": [int(r.field.constrained_youngs().sum()) for r in rows],
            "cells": [len(r.field.alpha_Pa) for r in rows],
            "warnings": [len(r.warnings) for r in rows],
        },
    )
    print(
        f"{'set':>4} {'E0 (Pa)':>10} {'nu0':>6}  linear max/mean (mm)  field max/mean (mm)"
        f"  E within {100 * CONSTRAINED_YOUNGS_ERROR:g}% (cells)"
    )
    for r in rows:
        linear = r.homogeneous_errors
        field = r.field_errors
        constrained = f"{int(r.field.constrained_youngs().sum())} of {len(r.field.alpha_Pa)}"
        print(
            f"{r.load_set:>4} {r.homogeneous.youngs_modulus_Pa:10.5g} "
            f"{r.homogeneous.poissons_ratio:6.3f}  "
            f"{linear['max_error_m'] * 1e3:9.3f}/{linear['mean_error_m'] * 1e3:<9.3f}  "
            f"{field['max_error_m'] * 1e3:9.3f}/{field['mean_error_m'] * 1e3:<9.3f}  "
            f"{constrained:>20}"
        )
    for r in rows:
        for message in r.warnings:
            print(f"warptissue: warning: load set {r.load_set}: {message}", file=sys.stderr)
    print(f"wrote {args.out}")
    return 0


def _checked_load_sets(args: argparse.Namespace, markers: Any, forces: dict) -> list[str]:
    """The load sets to fit (``--load-set``, else every one of the markers' file), each with
    markers and a non-zero force on known markers; a warning for forces without markers."""
    load_sets = list(dict.fromkeys(args.load_set or markers.load_sets))
    for label in load_sets:
        if label not in markers.load_sets:
            raise InputError(
                f"load set {label!r} is not in the file, which has {', '.join(markers.load_sets)}",
                path=args.markers,
            )
        if label not in forces:
            raise InputError(
                f"no force for load set {label!r}; the file has {', '.join(forces)}",
                path=args.forces,
            )
        if not any(vector.any() for vector in forces[label].values()):
            raise InputError(
                f"load set {label!r} has no applied force (all forces are zero)",
                path=args.forces,
            )
        unknown = [marker for marker in forces[label] if marker not in markers.markers]
        if unknown:
            raise InputError(
                f"load set {label!r}: force on marker {unknown[0]!r}, which is not in "
                f"{args.markers}",
                path=args.forces,
            )
    for label in forces:
        if label not in markers.load_sets:
            print(
                f"warptissue: warning: {args.forces}: load set {label!r} has forces but no "
                f"markers in {args.markers}; it is not fitted",
                file=sys.stderr,
            )
    return load_sets


def _write_usd(path: Path, args: argparse.Namespace, result: Any) -> None:
    """The load set's mesh with the per-tet (E, nu) field, bound to the homogeneous linear
    estimate (the single material for simulators that read one), with fit provenance."""
    import numpy as np

    from warptissue.materials import LinearElastic
    from warptissue.usd import write_simulation_usd

    homogeneous = result.homogeneous
    mesh = result.grid.mesh
    group = mesh.tet_regions
    youngs = result.field.youngs_modulus_Pa[group]
    nu = result.field.poissons_ratio[group]
    volume_m3 = mesh.volumes()
    provenance = {
        "data_file": str(args.markers),
        "forces_file": str(args.forces),
        "fit": {
            "command": "warptissue fit field",
            "load_set": result.load_set,
            "material": "homogeneous linear estimate (Tong et al., Eq. 13-14)",
            "homogeneous_test_max_error_m": result.homogeneous_errors["max_error_m"],
            "homogeneous_test_mean_error_m": result.homogeneous_errors["mean_error_m"],
            "field_test_max_error_m": result.field_errors["max_error_m"],
            "field_test_mean_error_m": result.field_errors["mean_error_m"],
            "per_cell_field": f"field_{result.load_set}_cells.csv",
            "material_field": "heterogeneous estimate per tet: primvars:tissue:youngsModulus, "
            "primvars:tissue:poissonsRatio; group = materialRegion subset (hexahedron)",
            "field_volume_mean_youngs_modulus_Pa": float(np.average(youngs, weights=volume_m3)),
            "field_volume_mean_poissons_ratio": float(np.average(nu, weights=volume_m3)),
        },
    }
    write_simulation_usd(
        path,
        mesh,
        material=LinearElastic(homogeneous.youngs_modulus_Pa, homogeneous.poissons_ratio),
        provenance=provenance,
        density_kg_per_m3=args.density_kg_per_m3,
        material_field={"youngs_modulus_Pa": youngs, "poissons_ratio": nu},
    )
