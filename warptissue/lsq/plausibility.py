"""Plausibility checks of indentation data and fitted values: sign, magnitude, units.

A fit converges on whatever it is given: an all-zero force, forces of the wrong sign, or
displacements written in millimetres in a ``displacement_m`` column all give a fit that looks
fine. These checks say so. Data that cannot be an indentation in SI units raise an
:class:`~warptissue.errors.InputError` (exit status 2 on the command line); data or results
that are merely unusual return warning messages, which the fits append to
:attr:`warptissue.lsq.FitResult.warnings` (a ``warning:`` line and the JSON ``warnings`` key).

The limits are module constants, documented on the fitting page of the docs.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from warptissue.errors import InputError

if TYPE_CHECKING:
    from warptissue.lsq.result import FitResult

__all__ = [
    "INDENTATION_STIFFNESS_RANGE_N_PER_M",
    "MAX_INDENTATION_DEPTH_M",
    "MAX_INDENTATION_FORCE_N",
    "SOFT_TISSUE_MODULUS_RANGE_PA",
    "check_indentation_record",
    "convergence_warnings",
    "elastic_curve_warnings",
    "fit_quality_warnings",
    "modulus_warnings",
    "stiffness_warnings",
]

MAX_INDENTATION_DEPTH_M = 0.1
"""Largest plausible indentation depth (m): a deeper record is refused (mm written as m?)."""

MAX_INDENTATION_FORCE_N = 100.0
"""Largest plausible indentation force (N): a larger one is warned about (mN written as N?)."""

SOFT_TISSUE_MODULUS_RANGE_PA = (10.0, 1.0e8)
"""Range of plausible Young's moduli of soft tissue (Pa); outside it a fit warns."""

INDENTATION_STIFFNESS_RANGE_N_PER_M = (1.0e-3, 1.0e7)
"""Range of plausible indentation stiffnesses (N/m) of a lumped model; outside it a fit warns."""


def _g(value: float) -> str:
    return f"{float(value):.4g}"


def check_indentation_record(
    displacement_m: np.ndarray,
    force_N: np.ndarray,
    *,
    path: str | Path | None = None,
    conditioned: bool = False,
    max_displacement_m: float = MAX_INDENTATION_DEPTH_M,
) -> list[str]:
    """Refuse an implausible indentation record and list what is unusual about it.

    Args:
        displacement_m: Indentation depth (m), shape (n,), positive into the specimen.
        force_N: Force (N), shape (n,), positive when the probe pushes in.
        path: The file the record came from, named in the messages.
        conditioned: The record went through contact detection (no "probe above the
            surface" warning then).
        max_displacement_m: The largest plausible displacement, m: an indentation's
            :data:`MAX_INDENTATION_DEPTH_M` by default; a test of a specimen allows more.

    Returns:
        Warning messages (no "warning:" prefix): a force above
        :data:`MAX_INDENTATION_FORCE_N`, and a force that stays near zero over the first part
        of the displacement (the probe started above the surface; condition the record).

    Raises:
        InputError: The force or the displacement is zero throughout, the displacement
            exceeds :data:`MAX_INDENTATION_DEPTH_M` (units?), or force and displacement have
            opposite signs at the force peak.
    """
    x = np.asarray(displacement_m, dtype=np.float64).reshape(-1)
    f = np.asarray(force_N, dtype=np.float64).reshape(-1)
    peak_force = float(np.max(np.abs(f))) if f.size else 0.0
    deepest = float(np.max(np.abs(x))) if x.size else 0.0
    if peak_force == 0.0:
        raise InputError(
            "the force is zero throughout: nothing to fit", path=path, column="force_N"
        )
    if deepest == 0.0:
        raise InputError(
            "the displacement is zero throughout: nothing to fit",
            path=path,
            column="displacement_m",
        )
    if deepest > max_displacement_m:
        test = "an indentation" if max_displacement_m == MAX_INDENTATION_DEPTH_M else "the test"
        raise InputError(
            f"the largest displacement is {_g(deepest)} m, implausible for {test} "
            f"(more than {_g(max_displacement_m)} m): is the column in millimetres? "
            "Convert it to metres (a specimen's tensile or compressive test: give its gauge "
            "length, --gauge-length-m, or the limit, --max-displacement-m)",
            path=path,
            column="displacement_m",
        )
    peak = int(np.argmax(np.abs(f)))
    depth_at_peak = x[peak] if x[peak] != 0.0 else x[int(np.argmax(np.abs(x)))]
    if f[peak] * depth_at_peak < 0.0:
        raise InputError(
            f"force and displacement have opposite signs at the force peak ({_g(f[peak])} N at "
            f"{_g(depth_at_peak)} m): use one sign convention for both (positive when the "
            "probe pushes in)",
            path=path,
            column="force_N",
        )
    warnings: list[str] = []
    if peak_force > MAX_INDENTATION_FORCE_N:
        warnings.append(
            f"the peak force is {_g(peak_force)} N, more than {_g(MAX_INDENTATION_FORCE_N)} N: "
            "is the force column in millinewtons?"
        )
    if not conditioned:
        depth = np.abs(x)
        rise = np.abs(f - np.median(f[:5]))  # from the first level: an offset is no load
        unloaded = rise <= 0.02 * float(np.max(rise))
        loaded = np.flatnonzero(~unloaded)
        free_depth = float(np.max(depth[: loaded[0]])) if loaded.size and loaded[0] > 0 else 0.0
        if free_depth > 0.05 * deepest:
            warnings.append(
                f"the force stays near zero over the first {_g(free_depth)} m of displacement "
                f"({_g(100 * free_depth / deepest)} % of the deepest point): the probe was "
                "probably above the surface; condition the record (--contact auto)"
            )
    return warnings


def elastic_curve_warnings(depth_m: np.ndarray, force_N: np.ndarray) -> list[str]:
    """A warning when an elastic force-depth fit is given a hold (a relaxing force).

    More than a fifth of the samples within 0.5 % of the deepest point, over which the force
    changes by more than 5 % of its peak, is a hold: an elastic formula averages the
    relaxation into one modulus. Fit the loading ramp instead (``--keep-depth``).
    """
    depth = np.abs(np.asarray(depth_m, dtype=np.float64).reshape(-1))
    force = np.asarray(force_N, dtype=np.float64).reshape(-1)
    if depth.size == 0:
        return []
    held = depth >= 0.995 * float(np.max(depth))
    peak = float(np.max(np.abs(force)))
    if held.mean() <= 0.2 or peak == 0.0:
        return []
    change = float(np.ptp(force[held]))
    if change <= 0.05 * peak:
        return []
    return [
        f"{100 * held.mean():.0f} % of the samples hold the deepest point while the force "
        f"changes by {100 * change / peak:.0f} % of its peak (relaxation): an elastic fit "
        "averages it; fit the loading ramp (--keep-depth)"
    ]


def fit_quality_warnings(result: FitResult) -> list[str]:
    """A warning when the fitted curve explains less than the data's mean (R^2 < 0)."""
    if result.r_squared is not None and result.r_squared < 0.0:
        return [
            f"R^2 = {result.r_squared:.4g} < 0: the fitted model is worse than a constant; "
            "check the sign and units of the data and the model choice"
        ]
    return []


def convergence_warnings(result: FitResult) -> list[str]:
    """A warning when the engine stopped without converging (its iteration limit, no
    acceptable step): the parameters are the best it reached, not a solution."""
    if result.success:
        return []
    return [f"the fit did not converge: {result.message} ({result.iterations} iterations)"]


def modulus_warnings(modulus_Pa: float, *, name: str = "youngs_modulus_Pa") -> list[str]:
    """A warning when a Young's modulus is outside :data:`SOFT_TISSUE_MODULUS_RANGE_PA`."""
    low, high = SOFT_TISSUE_MODULUS_RANGE_PA
    if low <= modulus_Pa <= high:
        return []
    return [
        f"{name} = {_g(modulus_Pa)} Pa is outside the plausible range of soft tissue "
        f"[{_g(low)}, {_g(high)}] Pa: check the units of the data and the probe geometry"
    ]


def stiffness_warnings(parameters: dict[str, float], units: Sequence[str]) -> list[str]:
    """A warning when the largest stiffness (N/m) of a lumped model is implausible.

    Args:
        parameters: Fitted parameter name to value (``FitResult.parameters``).
        units: The parameters' units, in the same order.

    Returns:
        One message when the largest parameter in N/m lies outside
        :data:`INDENTATION_STIFFNESS_RANGE_N_PER_M`, else none.
    """
    stiffness = [v for v, u in zip(parameters.values(), units, strict=True) if u == "N/m"]
    if not stiffness:
        return []
    largest = max(stiffness)
    low, high = INDENTATION_STIFFNESS_RANGE_N_PER_M
    if low <= largest <= high:
        return []
    return [
        f"the largest stiffness is {_g(largest)} N/m, outside the plausible range "
        f"[{_g(low)}, {_g(high)}] N/m of an indentation: check the units of the data"
    ]
