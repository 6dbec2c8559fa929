"""The shared argparse types of warptissue/cli/_args.py: SI numbers or numbers with units."""

from __future__ import annotations

import argparse

import pytest

from warptissue.cli._args import (
    length_m,
    nonnegative_length_m,
    positive_int,
    positive_length_m,
    positive_number,
    quantity,
)


@pytest.mark.parametrize(
    ("parse", "text", "value"),
    [
        (length_m, "0.001", 1e-3),
        (length_m, "-2mm", -2e-3),
        (positive_length_m, "1mm", 1e-3),
        (positive_length_m, "500 um", 5e-4),
        (nonnegative_length_m, "0", 0.0),
        (quantity("force"), "3mN", 3e-3),
        (quantity("force"), "3", 3.0),  # a plain number is in SI units (newtons)
        (quantity("stiffness", positive=True), "2N/mm", 2e3),
        (positive_number, "1.2", 1.2),
        (positive_int, "7", 7),
    ],
)
def test_values_in_si_units(parse, text, value):
    assert parse(text) == pytest.approx(value)


@pytest.mark.parametrize(
    ("parse", "text", "message"),
    [
        (positive_length_m, "0mm", "must be positive"),
        (nonnegative_length_m, "-1mm", "must not be negative"),
        (length_m, "1 N", "unknown unit; use one of m, mm, um"),
        (length_m, "inf", "not a finite number"),
        (positive_number, "1mm", "not a number"),
        (positive_int, "2.5", "not an integer"),
        (positive_int, "0", "must be positive"),
    ],
)
def test_bad_values_are_argparse_errors_quoting_the_text(parse, text, message):
    with pytest.raises(argparse.ArgumentTypeError, match=message) as error:
        parse(text)
    assert repr(text) in str(error.value)
