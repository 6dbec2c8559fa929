"""``warptissue simulate STUDY.toml``: run one indentation study and write its outputs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from warptissue.cli.export import check_usda_path

if TYPE_CHECKING:
    from warptissue.simulate import SimulationOutputs

__all__ = ["register"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``simulate`` command."""
    parser = subparsers.add_parser(
        "simulate",
        help="run the indentation simulation a study file describes",
        description=(
            "Run the indentation simulation described by a study TOML file and write "
            "force_curve.csv (time_s,displacement_m,force_N,step,newton_iterations: an "
            "indentation record that 'fit punch-modulus' and 'rig-sim --tissue curve "
            "--force-curve' read; time_s is the time of each step for a timed protocol "
            "(ramp_hold, sine, record), the step number for a quasi-static one), "
            "result.json and fields.vtu to the output folder. Exit "
            "status: 0 complete, 2 bad input, 3 bad mesh or a mesh too large for the "
            "memory (refused before it is made), 4 stopped early, 5 device missing, 130 "
            "interrupted (Ctrl-C); after 4 and 130 the outputs hold the load steps that "
            "converged."
        ),
    )
    parser.add_argument("study", type=Path, metavar="STUDY.toml", help="the study file")
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="DIR",
        help="output folder (default: runs/<study name>)",
    )
    parser.add_argument(
        "--device",
        default=None,
        type=_device,
        metavar="DEVICE",
        help="cpu, cuda or cuda:N (default: the study's solver.device)",
    )
    parser.add_argument("--json", action="store_true", help="print result.json to stdout when done")
    parser.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    parser.add_argument(
        "--vtu-every-step",
        action="store_true",
        help="also write fields_NNN.vtu with the displacement of every load step",
    )
    parser.add_argument(
        "--profile",
        action="store_true",
        help="time each phase of the Newton iterations (assembly, linear solver analysis, "
        "factorization and solve, line search, nonlinear elimination, sensitivities, host "
        "work) and print the table (seconds, share, ms per Newton iteration); result.json "
        "holds it as newton_profile (null without this option). On a GPU it synchronizes "
        "the device at every phase boundary, which slows the run a little",
    )
    parser.add_argument(
        "--usd",
        nargs="?",
        type=Path,
        const=True,
        default=None,
        metavar="PATH.usda",
        help="also write the mesh, material, deformed shapes and force curve as a layered USD "
        "scene: PATH.usda over PATH.asset.usda and PATH.results.usdc (default without a "
        "path: scene.usda in the output folder)",
    )
    parser.set_defaults(handler=run)


def _device(text: str) -> str:
    """A ``--device`` value: ``auto``, ``cpu``, ``cuda`` or ``cuda:N`` (others: exit 2)."""
    from warptissue.study import DEVICE_PATTERN

    if not DEVICE_PATTERN.match(text):
        raise argparse.ArgumentTypeError(f"expected cpu, cuda or cuda:N, got {text!r}")
    return text


def run(args: argparse.Namespace) -> int:
    """Handle ``warptissue simulate``; returns the exit status."""
    from warptissue.device import quiet_warp
    from warptissue.fem import SolveInterrupted
    from warptissue.simulate import run_study
    from warptissue.study import load_study

    quiet_warp()
    study = load_study(args.study)
    out_dir = args.out if args.out is not None else Path("runs") / study.name
    usd_path = out_dir / "scene.usda" if args.usd is True else args.usd
    if usd_path is not None:
        check_usda_path(usd_path, "--usd")
    try:
        outputs = run_study(
            study,
            out_dir=out_dir,
            device=args.device,
            progress=not (args.quiet or args.json),
            vtu_every_step=args.vtu_every_step,
            announce=not args.quiet,
            profile=args.profile,
        )
    except SolveInterrupted as interrupted:
        outputs = interrupted.partial_result
        if args.json:
            sys.stdout.write(outputs.files["result"].read_text(encoding="utf-8"))
        print(
            f"warptissue: interrupted: {outputs.summary['steps_converged']} converged load "
            f"steps written to {outputs.out_dir}",
            file=sys.stderr,
        )
        return outputs.exit_code
    if usd_path is not None:
        from warptissue.usd.export import export_result_dir

        outputs.files["usd"] = export_result_dir(out_dir, usd_path).root
    if args.json:
        sys.stdout.write(outputs.files["result"].read_text(encoding="utf-8"))
    elif not args.quiet:
        _print_summary(outputs)
    if args.profile and not args.json and outputs.result.timings is not None:
        print(f"where the solve's time went:\n{outputs.result.timings.table()}")
    for warning in outputs.summary["warnings"]:
        print(f"warptissue: warning: {warning}", file=sys.stderr)
    if outputs.status == "stopped_early":
        print(f"warptissue: error: stopped early: {outputs.message}", file=sys.stderr)
    return outputs.exit_code


def _print_summary(outputs: SimulationOutputs) -> None:
    curve = outputs.summary["force_curve"]
    mesh = outputs.summary["mesh"]
    print(
        f"{mesh['tet_count']} {mesh['element_type']} tets, {mesh['node_count']} nodes; "
        f"{outputs.summary['steps_converged']}/{outputs.summary['steps_requested']} load steps "
        f"in {outputs.summary['timings_s']['total']:.1f} s on {outputs.summary['device']}"
    )
    if mesh.get("size_near_reason"):
        print(mesh["size_near_reason"])
    timed = outputs.summary["study"]["protocol"].get("kind", "quasi_static") != "quasi_static"
    time_header = f" {'time_s':>11}" if timed else ""
    print(f"{'step':>4}{time_header} {'depth_m':>12} {'reaction_force_N':>17} {'newton':>6}")
    for step, time_s, depth, force, newton in zip(
        curve["step"],
        curve["time_s"],
        curve["depth_m"],
        curve["reaction_force_N"],
        curve["newton_iterations"],
        strict=True,
    ):
        time_text = f" {float(time_s):>11.4g}" if timed else ""
        print(
            f"{int(step):>4}{time_text} {float(depth):>12.4e} {float(force):>17.6e} "
            f"{int(newton):>6}"
        )
    print(f"outputs in {outputs.out_dir}: " + ", ".join(p.name for p in outputs.files.values()))
