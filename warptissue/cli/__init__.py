"""The ``warptissue`` command line.

Each command lives in its own module under ``warptissue.cli`` and exposes
``register(subparsers)`` for a top-level command and/or ``register_fit(subparsers)`` for a
``warptissue fit KIND`` subcommand. A module's ``register`` adds its parser and sets
``handler`` (a function taking the parsed arguments and returning an exit status). Modules
import their heavy dependencies inside the handler, so that ``warptissue --help`` stays fast.

Errors derived from :class:`warptissue.errors.WarpTissueError` become one-line messages on
stderr and the error's exit code, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from warptissue.errors import WarpTissueError

__all__ = ["build_parser", "main"]

COMMAND_MODULES: tuple[str, ...] = (
    "warptissue.cli.fit_uniaxial",
    "warptissue.cli.mesh",
    "warptissue.cli.export",
    "warptissue.cli.fit_relaxation",
    "warptissue.cli.acquire",
    "warptissue.cli.simulate",
)
"""Modules that add commands, in the order they appear in ``--help``."""


def build_parser() -> argparse.ArgumentParser:
    """Build the full argument parser from the command modules."""
    from warptissue import __version__

    parser = argparse.ArgumentParser(
        prog="warptissue",
        description="Soft-tissue characterization for surgical simulation.",
    )
    parser.add_argument("--version", action="version", version=f"warptissue {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    fit_parser = commands.add_parser("fit", help="fit a constitutive model to measured data")
    fit_kinds = fit_parser.add_subparsers(dest="fit_kind", required=True, metavar="KIND")
    for name in COMMAND_MODULES:
        module = importlib.import_module(name)
        if hasattr(module, "register"):
            module.register(commands)
        if hasattr(module, "register_fit"):
            module.register_fit(fit_kinds)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line and return the process exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        status = args.handler(args)
    except WarpTissueError as exc:
        print(f"warptissue: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("warptissue: interrupted", file=sys.stderr)
        return 130
    return 0 if status is None else int(status)


if __name__ == "__main__":
    sys.exit(main())
