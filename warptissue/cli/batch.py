"""``warptissue batch STUDY_OR_DIR_OR_GLOB ... -o OUT``: many studies, one folder each.

A thin wrapper of :func:`warptissue.batch.run_batch`: the simulations and the indentation fits
of the study files given (files, folders of ``*.toml`` files, glob patterns), each into its
own folder under ``OUT``, with ``OUT/summary.csv``; on Dask distributed (a LocalCluster of
``--workers`` processes, or a running cluster with ``--scheduler``). See docs/batch.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from warptissue.cli._args import device, nonnegative_int, positive_int

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``batch`` command."""
    parser = subparsers.add_parser(
        "batch",
        help="run many studies (simulations and fits), one result folder each, on Dask",
        description=(
            "Run every study file given (files, folders of *.toml files, glob patterns): a "
            "study with [[data]] records and a [fit] table is an indentation fit (as 'fit "
            "indentation'), any other a simulation (as 'simulate'). Each writes its "
            "command's files to OUT/<file stem> (a stem shared by several files gets a "
            "hash of the path), then batch_done.json; OUT/summary.csv has one row per study "
            "(status, exit status, seconds, peak force or fitted parameters and R^2, "
            "warnings, error). A failed study is one line on stderr and the others go on. A "
            "rerun skips the studies whose folder holds a complete result of the same file "
            "(--force runs them again). The studies run on Dask distributed: a LocalCluster "
            "of --workers processes on this machine, or the workers of a running scheduler "
            "(--scheduler), which must see the study files and OUT at the same paths. Exit "
            "status: 0 every study succeeded, 2 bad input or usage, 5 the scheduler "
            "cannot be reached, 6 one or more studies failed (the others ran; the summary "
            "says which and why), 130 interrupted (Ctrl-C; the summary holds the studies "
            "that ended)."
        ),
    )
    parser.add_argument(
        "studies",
        nargs="+",
        metavar="STUDY_OR_DIR_OR_GLOB",
        help="study files, folders of them, or quoted glob patterns ('studies/**/*.toml')",
    )
    parser.add_argument(
        "-o", "--out", type=Path, required=True, metavar="DIR", help="the batch's output folder"
    )
    parser.add_argument(
        "--device",
        default=None,
        type=device,
        metavar="DEVICE",
        help="auto, cpu, cuda or cuda:N for every study (default: each study's solver.device)",
    )
    parser.add_argument(
        "--workers",
        type=nonnegative_int,
        default=None,
        metavar="N",
        help="worker processes of the local cluster (default: one per GPU, pinned by "
        "CUDA_VISIBLE_DEVICES, for --device cuda or auto on a machine with GPUs; else 1); 0 "
        "runs the studies in this process, one after another, without Dask",
    )
    parser.add_argument(
        "--scheduler",
        default=None,
        metavar="tcp://HOST:PORT",
        help="run on the workers of a running Dask scheduler instead of a LocalCluster",
    )
    parser.add_argument(
        "--retries",
        type=nonnegative_int,
        default=1,
        metavar="N",
        help="Dask retries of a task that raised (default 1); a task whose worker dies runs "
        "again elsewhere in any case",
    )
    parser.add_argument(
        "--together",
        type=positive_int,
        default=1,
        metavar="K",
        help="studies per task (default 1); above 1, the simulations of a task that can "
        "share launches (flat punch, elastic, quasi-static, equal [solver] settings) are "
        "solved in one batched FE run, the others alone",
    )
    parser.add_argument(
        "--force", action="store_true", help="run the studies with a complete result too"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """Handle ``warptissue batch``; returns the exit status."""
    from tqdm.auto import tqdm

    from warptissue.batch import run_batch
    from warptissue.device import quiet_warp

    quiet_warp()

    def report(outcome) -> None:
        if outcome.failed:
            named = outcome.study in outcome.error or Path(outcome.study).name in outcome.error
            where = "" if named else f"{outcome.study}: "
            tqdm.write(f"warptissue: error: {where}{outcome.error}", file=sys.stderr)

    result = run_batch(
        args.studies,
        out=args.out,
        device=args.device,
        workers=args.workers,
        scheduler=args.scheduler,
        force=args.force,
        progress=not args.quiet,
        retries=args.retries,
        together=args.together,
        on_outcome=report,
    )
    counts = len(result.outcomes), len(result.failed), len(result.skipped)
    if not args.quiet:
        plural = "" if result.workers == 1 else "s"
        ran = (
            "in this process" if result.workers == 0 else f"on {result.workers} Dask worker{plural}"
        )
        print(
            f"{counts[0]} studies ({counts[2]} skipped: complete), {counts[1]} failed, "
            f"{result.seconds:.1f} s {ran}; summary in {result.summary_path}"
        )
    if result.failed:
        print(
            f"warptissue: error: {counts[1]} of {counts[0]} studies failed "
            f"(see {result.summary_path})",
            file=sys.stderr,
        )
    return result.exit_code
