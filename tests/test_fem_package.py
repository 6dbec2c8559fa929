"""The ``warptissue.fem`` package docstring is a runnable map: its example runs and holds."""

from __future__ import annotations

import doctest

import warptissue.fem


def test_the_package_docstring_runs():
    outcome = doctest.testmod(warptissue.fem, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert outcome.attempted >= 8
    assert outcome.failed == 0
