"""The command line as a whole (``warptissue.cli``): every command states its exit statuses."""

import argparse

from warptissue.cli import STANDARD_EXIT, build_parser
from warptissue.errors import ConvergenceError, DeviceError, InputError, MeshError


def _commands(parser: argparse.ArgumentParser, prefix: str = "warptissue"):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield f"{prefix} {name}", sub
                yield from _commands(sub, f"{prefix} {name}")


def test_every_command_states_its_exit_statuses_in_its_help():
    """Before, `fit uniaxial`, `fit field`, `mesh block`, `acquire`, ... said nothing of them."""
    runnable = [
        (path, sub) for path, sub in _commands(build_parser()) if sub.get_default("handler")
    ]
    assert len(runnable) >= 13
    for path, sub in runnable:
        assert "exit status" in " ".join(sub.format_help().lower().split()), path


def test_the_standard_list_quotes_the_error_classes_codes():
    for error, words in (
        (InputError, "bad input"),
        (MeshError, "unusable mesh"),
        (ConvergenceError, "no convergence"),
        (DeviceError, "device"),
    ):
        assert f"{error.exit_code} {words}" in STANDARD_EXIT
