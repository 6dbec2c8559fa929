"""``warptissue mesh``: generate indentation specimens, check and convert mesh files.

    warptissue mesh block --width-m 0.04 --thickness-m 0.02 --probe-radius-m 0.0025 \\
        --size-near-m 5e-4 --size-far-m 4e-3 --out runs/block.vtu
    warptissue mesh disc --radius-m 0.02 ... --out runs/disc.msh
    warptissue mesh check organ.msh --json runs/organ_quality.json
    warptissue mesh convert model.inp model.vtu --unit mm   # an Abaqus file in millimetres
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from warptissue.cli._args import positive_length_m, positive_number

__all__ = ["register"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``mesh`` command and its subcommands."""
    parser = subparsers.add_parser(
        "mesh", help="generate indentation meshes, check and convert mesh files"
    )
    actions = parser.add_subparsers(dest="mesh_action", required=True, metavar="ACTION")

    for shape in ("block", "disc"):
        generate = actions.add_parser(shape, help=f"graded indentation {shape} (O-grid)")
        if shape == "block":
            generate.add_argument(
                "--width-m", type=positive_length_m, required=True, help="full width"
            )
        else:
            generate.add_argument(
                "--radius-m", type=positive_length_m, required=True, help="disc radius"
            )
            generate.add_argument(
                "--curved-side", action="store_true", help="TET10 mid nodes on the cylinder"
            )
        generate.add_argument("--thickness-m", type=positive_length_m, required=True)
        generate.add_argument("--probe-radius-m", type=positive_length_m, required=True)
        near = generate.add_mutually_exclusive_group(required=True)
        near.add_argument("--size-near-m", type=positive_length_m, help="size at the probe")
        near.add_argument(
            "--force-accuracy",
            type=positive_number,
            help="instead of --size-near-m: the relative force accuracy (0.01 is 1 %%) to "
            "choose it for, from the flat-punch benchmark's measurement (TET10)",
        )
        generate.add_argument("--size-far-m", type=positive_length_m, required=True)
        generate.add_argument("--growth", type=positive_number, default=1.2)
        generate.add_argument("--layer-max-m", type=positive_length_m, default=None)
        generate.add_argument("--element", choices=("TET10", "TET4"), default="TET10")
        generate.add_argument(
            "--mesher",
            choices=("extruded", "delaunay"),
            default="extruded",
            help="layers of split prisms, or TetGen's quality tets inside the same surface",
        )
        generate.add_argument("--full", action="store_true", help="full model, not a quarter")
        generate.add_argument("--out", type=Path, required=True, help=".vtu or .msh file")
        generate.add_argument("--json", type=Path, help="write the quality summary here")
        generate.set_defaults(handler=_generate, shape=shape)

    check = actions.add_parser("check", help="read a mesh file and report its quality")
    check.add_argument("path", type=Path, help=".vtu, .msh or .inp file")
    _add_unit(check)
    check.add_argument("--json", type=Path, help="write the quality summary here")
    check.set_defaults(handler=_check)

    convert = actions.add_parser("convert", help="convert between .vtu/.msh/.inp and .vtu/.msh")
    convert.add_argument("source", type=Path)
    convert.add_argument("target", type=Path, help="written in metres")
    _add_unit(convert)
    convert.set_defaults(handler=_convert)


FILE_UNITS_M = {"m": 1.0, "mm": 1e-3, "um": 1e-6}
"""Coordinate units a mesh file may be in, and their length in metres."""
PLAUSIBLE_EXTENT_M = 1.0
"""A mesh read as metres and larger than this across is probably in millimetres: warned."""


def _add_unit(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--unit",
        choices=tuple(FILE_UNITS_M),
        default="m",
        help="unit of the file's coordinates (default m; Abaqus and CAD files are often in mm)",
    )


def _read(path: Path, unit: str):
    """Read a mesh file in ``unit``, warning when metres look implausible."""
    import numpy as np

    from warptissue.mesh import read_mesh

    mesh = read_mesh(path, unit_m=FILE_UNITS_M[unit])
    extent = float(np.ptp(mesh.points, axis=0).max()) if mesh.node_count else 0.0
    if unit == "m" and extent > PLAUSIBLE_EXTENT_M:
        print(
            f"warptissue: warning: {path}: the mesh is {extent:.4g} m across; if its "
            "coordinates are in millimetres, add --unit mm",
            file=sys.stderr,
        )
    return mesh


def _generate(args: argparse.Namespace) -> int:
    from warptissue.mesh import (
        indentation_block,
        indentation_disc,
        near_size_choice,
        write_mesh,
    )

    if args.force_accuracy is not None:
        choice = near_size_choice(
            args.force_accuracy,
            probe_radius_m=args.probe_radius_m,
            mesher=args.mesher,
            element=args.element,
        )
        print(choice.reason())
        args.size_near_m = choice.size_near_m
    common = {
        "thickness_m": args.thickness_m,
        "probe_radius_m": args.probe_radius_m,
        "quarter": not args.full,
        "element": args.element,
        "size_near_m": args.size_near_m,
        "size_far_m": args.size_far_m,
        "growth": args.growth,
        "layer_max_m": args.layer_max_m,
        "mesher": args.mesher,
    }
    if args.shape == "block":
        mesh = indentation_block(width_m=args.width_m, **common)
    else:
        mesh = indentation_disc(radius_m=args.radius_m, curved_side=args.curved_side, **common)
    write_mesh(args.out, mesh)
    print(f"wrote {args.out}")
    return _report(mesh, args.json)


def _check(args: argparse.Namespace) -> int:
    return _report(_read(args.path, args.unit), args.json)


def _convert(args: argparse.Namespace) -> int:
    from warptissue.mesh import write_mesh

    mesh = _read(args.source, args.unit)
    write_mesh(args.target, mesh)
    print(f"wrote {args.target}: {mesh.tet_count} {mesh.element_type}, {mesh.node_count} nodes")
    return 0


def _report(mesh, json_path: Path | None) -> int:
    """Print the quality table (and write it as JSON); MeshError propagates (exit 3)."""
    from warptissue.io import write_json
    from warptissue.mesh import check_mesh

    quality = check_mesh(mesh)
    for name, value in quality.to_dict().items():
        text = f"{value:.6g}" if isinstance(value, float) else str(value)
        print(f"  {name:<22} {text}")
    sets = ", ".join(f"{name} ({len(nodes)})" for name, nodes in sorted(mesh.node_sets.items()))
    print(f"  {'node_sets':<22} {sets or 'none'}")
    if json_path is not None:
        write_json(
            json_path,
            {
                "quality": quality.to_dict(),
                "node_sets": {k: len(v) for k, v in mesh.node_sets.items()},
            },
        )
    return 0
