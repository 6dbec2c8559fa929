"""The ``warptissue`` command line.

Each command lives in its own module under ``warptissue.cli`` and exposes
``register(subparsers)`` for a top-level command and/or ``register_fit(subparsers)`` for a
``warptissue fit KIND`` subcommand. A module's ``register`` adds its parser and sets
``handler`` (a function taking the parsed arguments and returning an exit status). Modules
import their heavy dependencies inside the handler, so that ``warptissue --help`` stays fast.

Errors derived from :class:`warptissue.errors.WarpTissueError` become one-line messages on
stderr and the error's exit code, never a traceback; so do the system's errors about a path
(``--json`` into a folder, no permission, a full disk: exit 2). Python warnings raised under a
command (cuDSS not available, a factorization in host memory) print as the commands' own
``warptissue: warning: ...`` lines. Ctrl-C exits with 130; a
reader that closes the pipe early (``warptissue mesh check organ.vtu | head -1``) ends the
command quietly with 141, as ``SIGPIPE`` ends Unix tools (:data:`EXIT_STATUSES`).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings
from collections.abc import Sequence

from warptissue import __version__
from warptissue.errors import INTERRUPTED_EXIT_CODE, InputError, WarpTissueError

__all__ = ["EXIT_STATUSES", "build_parser", "main"]

EXIT_STATUSES: dict[int, str] = {
    0: "success",
    2: "a file or folder the system cannot read or write (a folder given as a file, a path "
    "below a file, no permission, a full disk)",
    6: "warptissue batch: one or more studies failed, the others ran (OUT/summary.csv says "
    "which and why)",
    INTERRUPTED_EXIT_CODE: "interrupted (Ctrl-C)",
    141: "the reader of standard output closed it early (a broken pipe, as in `| head`)",
}
"""Exit statuses that do not come from an error class of :mod:`warptissue.errors` (argparse's
usage errors exit with 2, as :class:`~warptissue.errors.InputError` does)."""

COMMAND_MODULES: tuple[str, ...] = (
    "warptissue.cli.fit_uniaxial",
    "warptissue.cli.field",
    "warptissue.cli.calibrate",
    "warptissue.cli.mesh",
    "warptissue.cli.export",
    "warptissue.cli.fit_relaxation",
    "warptissue.cli.fit_indentation",
    "warptissue.cli.acquire",
    "warptissue.cli.simulate",
    "warptissue.cli.batch",
)
"""Modules that add commands, in the order they appear in ``--help``."""


def build_parser() -> argparse.ArgumentParser:
    """Build the full argument parser from the command modules."""

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
    _state_exit_statuses(parser)
    return parser


STANDARD_EXIT = (
    "exit status: 0 success (warnings go to stderr), 2 bad input or usage, 3 unusable mesh, "
    "4 no convergence, 5 device, 130 interrupted, 141 broken pipe"
)
"""The exit statuses said in the ``--help`` of a command that does not state its own."""


def _state_exit_statuses(parser: argparse.ArgumentParser) -> None:
    """Give every command that runs something and says nothing of its exit statuses the
    standard list as its ``--help`` epilog (the codes of :mod:`warptissue.errors`)."""
    for action in parser._actions:
        if not isinstance(action, argparse._SubParsersAction):
            continue
        for sub in action.choices.values():
            stated = ((sub.description or "") + (sub.epilog or "")).lower()
            if sub.get_default("handler") is not None and "exit status" not in stated:
                sub.epilog = STANDARD_EXIT if not sub.epilog else f"{sub.epilog}\n{STANDARD_EXIT}"
            _state_exit_statuses(sub)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line and return the process exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            status = args.handler(args)
        sys.stdout.flush()  # a closed pipe shows here, not at the interpreter's exit
    except BrokenPipeError:
        _silence_stdout()
        return 141
    except WarpTissueError as exc:
        option = _option_of(parser, args, exc)
        message = exc if option is None else exc.for_option(option)
        print(f"warptissue: error: {message}", file=sys.stderr)
        return exc.exit_code
    except OSError as exc:  # a path the system refuses: a folder, a file below a file, ...
        print(f"warptissue: error: {_describe_os_error(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("warptissue: interrupted", file=sys.stderr)
        return INTERRUPTED_EXIT_CODE
    return 0 if status is None else int(status)


def _option_of(
    parser: argparse.ArgumentParser, args: argparse.Namespace, error: WarpTissueError
) -> str | None:
    """The option of the command that ran that an :class:`InputError` without a file is
    about, when its ``column`` is that option's name (``size_near_m`` -> ``--size-near-m``);
    else None."""
    column = getattr(error, "column", None)
    if not isinstance(error, InputError) or error.path is not None or not column:
        return None
    option = "--" + column.replace("_", "-")
    current: argparse.ArgumentParser | None = parser
    while current is not None:
        if option in current._option_string_actions:
            return option
        subparsers = [a for a in current._actions if isinstance(a, argparse._SubParsersAction)]
        chosen = getattr(args, subparsers[0].dest, None) if subparsers else None
        current = subparsers[0].choices.get(chosen) if chosen is not None else None
    return None


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Print a Python warning raised under a command as the commands' own warning lines:
    ``warptissue: warning: ...`` on stderr, one line, no source location."""
    text = " ".join(str(message).split())
    print(f"warptissue: warning: {text}", file=sys.stderr if file is None else file)


def _describe_os_error(error: OSError) -> str:
    """One line for a file-system error: the path it is about and the system's reason."""
    reason = error.strerror or str(error)
    path = error.filename2 if error.filename2 is not None else error.filename
    return reason if path is None else f"cannot use {str(path)!r}: {reason}"


def _silence_stdout() -> None:
    """Point standard output at the null device, so that the interpreter's final flush of
    what is still buffered for a closed pipe does not fail again (Python's recipe for
    ``SIGPIPE``)."""
    try:
        descriptor = sys.stdout.fileno()
    except (OSError, ValueError):  # not a file (a caller's capture): nothing will flush to it
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, descriptor)
    finally:
        os.close(devnull)


if __name__ == "__main__":
    sys.exit(main())
