"""``warptissue simulate STUDY.toml``: run one indentation study and write its outputs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

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
            "force_curve.csv, result.json and fields.vtu to the output folder. Exit status: "
            "0 complete, 2 bad input, 3 bad mesh, 4 stopped early (partial outputs are "
            "written), 5 device missing."
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
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """Handle ``warptissue simulate``; returns the exit status."""
    import warp as wp

    from warptissue.simulate import run_study
    from warptissue.study import load_study

    _silence_warp_info(wp)
    study = load_study(args.study)
    out_dir = args.out if args.out is not None else Path("runs") / study.name
    outputs = run_study(
        study,
        out_dir=out_dir,
        device=args.device,
        progress=not (args.quiet or args.json),
        vtu_every_step=args.vtu_every_step,
    )
    if args.json:
        sys.stdout.write(outputs.files["result"].read_text(encoding="utf-8"))
    elif not args.quiet:
        _print_summary(outputs)
    if not outputs.completed:
        print(f"warptissue: error: stopped early: {outputs.message}", file=sys.stderr)
    return outputs.exit_code


def _silence_warp_info(wp) -> None:
    """Keep Warp's start-up and module-load notes off stdout (``--json`` prints only JSON)."""
    if hasattr(wp, "LOG_WARNING"):  # Warp >= 1.19 replaced config.quiet with log levels
        wp.config.log_level = wp.LOG_WARNING
    else:
        wp.config.quiet = True


def _print_summary(outputs: SimulationOutputs) -> None:
    curve = outputs.summary["force_curve"]
    mesh = outputs.summary["mesh"]
    print(
        f"{mesh['tet_count']} {mesh['element_type']} tets, {mesh['node_count']} nodes; "
        f"{outputs.summary['steps_converged']}/{outputs.summary['steps_requested']} load steps "
        f"in {outputs.summary['timings_s']['total']:.1f} s on {outputs.summary['device']}"
    )
    print(f"{'step':>4} {'depth_m':>12} {'reaction_force_N':>17} {'newton':>6}")
    for step, depth, force, newton in zip(
        curve["step"],
        curve["depth_m"],
        curve["reaction_force_N"],
        curve["newton_iterations"],
        strict=True,
    ):
        print(f"{int(step):>4} {float(depth):>12.4e} {float(force):>17.6e} {int(newton):>6}")
    print(f"outputs in {outputs.out_dir}: " + ", ".join(p.name for p in outputs.files.values()))
