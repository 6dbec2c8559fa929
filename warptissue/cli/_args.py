"""Shared argparse ``type=`` helpers for the command line: quantities with units, positive numbers.

A quantity option takes a plain number in SI units (``--radius-m 0.001``) or a number with a
unit suffix (``--radius-m 1mm``, ``--size-near-m 500um``), parsed by
:func:`warptissue.acquisition.protocol.parse_quantity` (the units ``acquire`` takes). A bad
value is refused by argparse with a one-line message naming the option and the value (exit 2).

Use them as ``parser.add_argument("--radius-m", type=positive_length_m)``; for another kind of
quantity (``"force"``, ``"stiffness"``, ``"time"``, ...), ``type=quantity("force")``.
Used by ``warptissue mesh``; meant for every command with quantity options (the fit commands'
punch radius and thickness included).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from warptissue.errors import InputError

__all__ = [
    "device",
    "length_m",
    "nonnegative_int",
    "nonnegative_length_m",
    "positive_int",
    "positive_length_m",
    "positive_number",
    "quantity",
]


def quantity(kind: str, *, positive: bool = False, nonnegative: bool = False) -> Callable:
    """An argparse type for a quantity: a plain number in SI units, or a number with a unit.

    Args:
        kind: The kind of quantity, one of the kinds of
            :func:`warptissue.acquisition.protocol.parse_quantity` (``"length"``, ``"speed"``,
            ``"time"``, ``"frequency"``, ``"stiffness"``, ``"force"``).
        positive: Refuse zero and negative values.
        nonnegative: Refuse negative values.

    Returns:
        A function of the option's text returning the value in SI units (float), raising
        ``argparse.ArgumentTypeError`` with a one-line message for a bad value.
    """

    def parse(text: str) -> float:
        from warptissue.acquisition.protocol import parse_quantity

        try:
            value = float(text)
        except ValueError:
            try:
                value = parse_quantity(text, kind)
            except InputError as exc:
                raise argparse.ArgumentTypeError(
                    f"{exc.message.removeprefix('value: ')} (got {text!r})"
                ) from None
        return _checked(value, text, positive=positive, nonnegative=nonnegative)

    parse.__name__ = f"{kind}_quantity"
    return parse


def _checked(value: float, text: str, *, positive: bool, nonnegative: bool) -> float:
    """``value`` if it is finite and has the requested sign, else ArgumentTypeError."""
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"not a finite number (got {text!r})")
    if positive and not value > 0:
        raise argparse.ArgumentTypeError(f"must be positive (got {text!r})")
    if nonnegative and value < 0:
        raise argparse.ArgumentTypeError(f"must not be negative (got {text!r})")
    return value


length_m = quantity("length")
"""A length in metres: ``0.001``, ``1mm``, ``500um``."""
positive_length_m = quantity("length", positive=True)
"""A length in metres, greater than zero."""
nonnegative_length_m = quantity("length", nonnegative=True)
"""A length in metres, zero or more."""


def positive_number(text: str) -> float:
    """A finite number greater than zero (no unit), for argparse ``type=``."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number (got {text!r})") from None
    return _checked(value, text, positive=True, nonnegative=False)


def positive_int(text: str) -> int:
    """An integer greater than zero, for argparse ``type=``."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer (got {text!r})") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be positive (got {text!r})")
    return value


def nonnegative_int(text: str) -> int:
    """An integer, 0 or more (a seed, a count of workers or retries), for argparse ``type=``."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer (got {text!r})") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more (got {text!r})")
    return value


def device(text: str) -> str:
    """A ``--device`` value: ``auto``, ``cpu``, ``cuda`` or ``cuda:N`` (others: exit 2)."""
    from warptissue.study import DEVICE_PATTERN

    if not DEVICE_PATTERN.match(text):
        raise argparse.ArgumentTypeError(f"expected auto, cpu, cuda or cuda:N, got {text!r}")
    return text
