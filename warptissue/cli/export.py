"""``warptissue export``: write a simulation's results (or a study's specimen) as USD."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from warptissue.errors import InputError

__all__ = ["check_usda_path", "register"]


def check_usda_path(path: Path, option: str) -> None:
    """Refuse, before any work, a USD root layer path that is not ``.usda`` or whose folder
    cannot be made (a file stands where a folder must be).

    Raises:
        InputError: Naming the option and the path.
    """

    if path.suffix != ".usda":
        raise InputError(f"{option} takes the root layer's path, a .usda file", path=path)
    folder = path.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise InputError(f"{option}: {folder} is a file, not a folder", path=path)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``export`` command."""
    parser = subparsers.add_parser(
        "export",
        help="write simulation results or a study's specimen as a USD scene",
        description=(
            "Write a 'warptissue simulate' output folder (result.json, fields.vtu, optional "
            "fields_NNN.vtu) or a study TOML (specimen and material, no results) as a layered "
            "USD scene: NAME.usda (root), NAME.asset.usda and, with results, "
            "NAME.results.usdc; with --trainer, the specimen as a trainer's asset with a "
            "calibrated physics material. The scene is validated after writing. Exit status: "
            "0 valid, 1 validation findings, 2 bad input, 4 a calibration run that did not "
            "converge."
        ),
    )
    parser.add_argument("source", type=Path, help="a simulate output folder or a study .toml")
    parser.add_argument("--out", type=Path, required=True, help="root layer to write (.usda)")
    parser.add_argument(
        "--density",
        dest="density_kg_per_m3",
        type=float,
        default=None,
        help="mass density written as physics:density, kg/m^3 (default 1000; with --over, "
        "the asset's)",
    )
    parser.add_argument(
        "--over",
        type=Path,
        metavar="ASSET.usda",
        help=(
            "layer the run over this organ's USD asset (the one its [specimen] mesh named, "
            "not refined) instead of writing its own asset layer"
        ),
    )
    parser.add_argument(
        "--trainer",
        action="store_true",
        help=(
            "write the specimen as a trainer's asset: the whole body on linear tets, with "
            "physics:youngsModulus and physics:poissonsRatio calibrated so that those tets "
            "(NVIDIA Newton's VBD) reproduce the locking-free force of the study's probes, "
            "and particle sizes for contact; the source is a study .toml or a fit output "
            "folder. Without it the physics material holds the tissue's true small-strain "
            "E and nu (for simulators with locking-free elements)"
        ),
    )
    parser.add_argument(
        "--max-tets",
        type=int,
        default=None,
        metavar="N",
        help="with --trainer: the most tets of the trainer's mesh (a coarser mesh is made)",
    )
    parser.add_argument(
        "--device", default="cpu", help="with --trainer: Warp device of the calibration"
    )
    parser.add_argument("--json", action="store_true", help="print the written paths as JSON")
    parser.set_defaults(handler=run_export)


def run_export(args: argparse.Namespace) -> int:
    """Handle ``warptissue export``."""
    from warptissue.usd import validate_stage
    from warptissue.usd.export import export_result_dir, export_study, export_trainer

    source: Path = args.source
    check_usda_path(args.out, "--out")
    if not source.exists():
        raise InputError("no such simulate output folder or study file", path=source)
    if args.over is not None and not (source.is_dir() and args.over.is_file()):
        raise InputError(
            "--over layers a simulate output folder over an existing USD asset",
            path=args.over,
            key="--over",
        )
    if args.max_tets is not None and not args.trainer:
        raise InputError("--max-tets needs --trainer", key="--max-tets", value=args.max_tets)
    calibration = None
    if args.trainer:
        from warptissue.device import quiet_warp

        quiet_warp()
        if args.over is not None:
            raise InputError("--trainer writes its own asset: no --over", key="--over")
        density = 1000.0 if args.density_kg_per_m3 is None else args.density_kg_per_m3
        paths, calibration = export_trainer(
            source, args.out, max_tets=args.max_tets, density_kg_per_m3=density, device=args.device
        )
    elif source.is_dir():
        paths = export_result_dir(
            source, args.out, density_kg_per_m3=args.density_kg_per_m3, over=args.over
        )
    elif source.suffix == ".toml" and source.is_file():
        density = 1000.0 if args.density_kg_per_m3 is None else args.density_kg_per_m3
        paths = export_study(source, args.out, density_kg_per_m3=density)
    else:
        raise InputError("expected a simulate output folder or a study .toml file", path=source)
    findings = validate_stage(paths.root)
    written = {
        "root": str(paths.root),
        "asset": str(paths.asset),
        "results": None if paths.results is None else str(paths.results),
        "findings": findings,
    }
    if calibration is not None:
        written["trainer"] = calibration.to_dict()
    if args.json:
        print(json.dumps(written, indent=2))
    else:
        if calibration is not None:
            print("\n".join(calibration.report_lines()))
        layers = ", ".join(str(p) for p in (paths.root, paths.asset, paths.results) if p)
        print(f"wrote {layers}; {len(findings)} validation findings")
        for finding in findings:
            print(f"  {finding}")
    return 1 if findings else 0
