"""Parameter rules shared by the material tables and the fits: the Prony keys and the
bounds of the parameters that must be positive."""

from __future__ import annotations

import re
from collections.abc import Sequence

import numpy as np

PRONY_KEY = re.compile(r"^(g|tau)(\d+)(_s)?$")
"""What looks like a Prony key of a material table: ``g<i>`` (dimensionless) or ``tau<i>_s``
(s), and their near misses (``tau1``, ``g1_s``) that the table reader names in its error;
:func:`prony_term` tells the keys themselves."""


def prony_term(name: str) -> tuple[str, int] | None:
    """The Prony term that a parameter or material-table key names.

    Args:
        name: A key, e.g. ``g2`` (a dimensionless coefficient) or ``tau2_s`` (a time, s).

    Returns:
        ``("g" | "tau", i)`` with the term's number i (from 1), or None for any other name.
    """
    match = PRONY_KEY.match(name)
    if match is None or (match.group(1) == "tau") != (match.group(3) == "_s"):
        return None
    return match.group(1), int(match.group(2))


POSITIVE_MODULI: tuple[str, ...] = (
    "C10_Pa",
    "shear_modulus_Pa",
    "youngs_modulus_Pa",
    "bulk_modulus_Pa",
)
"""The moduli that a fit keeps at or above 0 (:func:`positive_bounds`), Pa."""


def positive_bounds(
    names: Sequence[str], lower: np.ndarray, upper: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Bounds tightened where a parameter must be positive, whatever the model's box says.

    The moduli of :data:`POSITIVE_MODULI` and the Prony times ``tau<i>_s`` get lower bound
    0; the Prony coefficients ``g<i>`` lie in [0, 1].

    Args:
        names: Parameter names, shape (n,).
        lower: Lower bounds in their units, shape (n,).
        upper: Upper bounds, shape (n,).

    Returns:
        (lower, upper), new arrays of shape (n,).
    """
    lower, upper = np.array(lower, dtype=np.float64), np.array(upper, dtype=np.float64)
    for j, name in enumerate(names):
        term = prony_term(name)
        if name in POSITIVE_MODULI or (term is not None and term[0] == "tau"):
            lower[j] = max(lower[j], 0.0)
        elif term is not None:
            lower[j] = max(lower[j], 0.0)
            upper[j] = min(upper[j], 1.0)
    return lower, upper
