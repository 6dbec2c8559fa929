"""Drucker stability of an incompressible hyperelastic model over the six standard modes
(:func:`drucker_stability`; the criterion and its derivation:
:mod:`warptissue.fit.hyperelastic`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.materials import (
    HyperelasticMaterial,
    principal_log_strains,
)

STABILITY_MODES: tuple[str, ...] = (
    "uniaxial_tension",
    "uniaxial_compression",
    "equibiaxial_tension",
    "equibiaxial_compression",
    "planar_tension",
    "planar_compression",
)
"""The six modes of the Drucker stability check."""


@dataclass(frozen=True)
class StableRange:
    """Drucker stability along one mode.

    Attributes:
        mode: One of :data:`STABILITY_MODES`.
        unstable_from_strain: Nominal strain magnitude where the material first becomes
            unstable, or None when it is stable over the whole checked range.
        checked_up_to_strain: Upper end of the checked range of nominal strain magnitude.
    """

    mode: str
    unstable_from_strain: float | None
    checked_up_to_strain: float

    @property
    def stable(self) -> bool:
        """Stable over the whole checked range."""
        return self.unstable_from_strain is None


@dataclass(frozen=True)
class StabilityReport:
    """Drucker stability over the six modes."""

    ranges: tuple[StableRange, ...]

    def __getitem__(self, mode: str) -> StableRange:
        for entry in self.ranges:
            if entry.mode == mode:
                return entry
        raise KeyError(mode)

    @property
    def stable_everywhere(self) -> bool:
        """Stable in every mode over the checked ranges."""
        return all(entry.stable for entry in self.ranges)

    @property
    def stable_up_to_strain(self) -> float | None:
        """Smallest strain at which any mode becomes unstable, or None if none does."""
        limits = [e.unstable_from_strain for e in self.ranges if not e.stable]
        return min(limits) if limits else None

    def to_dict(self) -> dict[str, Any]:
        """{mode: {"unstable_from_strain", "checked_up_to_strain"}, "stable_up_to_strain"}."""
        summary: dict[str, Any] = {
            e.mode: {
                "unstable_from_strain": e.unstable_from_strain,
                "checked_up_to_strain": e.checked_up_to_strain,
            }
            for e in self.ranges
        }
        summary["stable_up_to_strain"] = self.stable_up_to_strain
        return summary


def _is_stable(model: HyperelasticMaterial, mode: str, stretch: np.ndarray) -> np.ndarray:
    """Positive definiteness of the Hessian on the plane of trace-free log strains.

    The plane is parametrized by eliminating, point by point, the principal direction k of
    SMALLEST ambient curvature G_kk (basis e_i - e_k, e_j - e_k). Eliminating a stiff
    direction instead would bury the soft one under rounding: for Ogden with
    G = diag(c), det = c_i c_j + c_k (c_i + c_j) is then formed as (c_i + c_k)(c_j + c_k)
    - c_k^2, which cancels when c_k >> c_i, c_j.
    """
    strains = principal_log_strains(stretch, mode)
    with np.errstate(over="ignore", invalid="ignore"):
        ambient = model.principal_log_strain_hessian(strains)
        order = np.argsort(np.diagonal(ambient, axis1=1, axis2=2), axis=1)
        k, i, j = order[:, 0], order[:, 1], order[:, 2]
        rows = np.arange(strains.shape[0])

        def g(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            return ambient[rows, a, b]

        h11 = g(i, i) - 2.0 * g(i, k) + g(k, k)
        h22 = g(j, j) - 2.0 * g(j, k) + g(k, k)
        h12 = g(i, j) - g(i, k) - g(j, k) + g(k, k)
        determinant = h11 * h22 - h12 * h12
        rounding = 16.0 * np.finfo(np.float64).eps * (np.abs(h11 * h22) + h12 * h12)
        stable = (h11 > 0.0) & (determinant > rounding)
    return stable & np.isfinite(determinant)


def drucker_stability(
    model: HyperelasticMaterial,
    *,
    max_tension_strain: float = 10.0,
    max_compression_strain: float = 0.95,
    samples: int = 2000,
) -> StabilityReport:
    """Drucker stability of an incompressible model over the six standard modes.

    Scans the nominal strain magnitude from 0 to the maximum of each mode (log-spaced
    samples plus 0) and refines the first unstable point by bisection to 1e-9 relative.

    Args:
        model: The fitted model.
        max_tension_strain: Largest nominal strain checked in tension (Abaqus checks to 10).
        max_compression_strain: Largest nominal strain magnitude checked in compression (< 1).
        samples: Samples per mode before bisection.

    Returns:
        The :class:`StabilityReport` (criterion in the module Notes).
    """
    if not 0.0 < max_compression_strain < 1.0 or not max_tension_strain > 0.0:
        raise InputError(
            "need max_tension_strain > 0 and 0 < max_compression_strain < 1",
            value=(float(max_tension_strain), float(max_compression_strain)),
        )
    ranges = []
    for mode_name in STABILITY_MODES:
        mode, _, direction = mode_name.partition("_")
        sign = 1.0 if direction == "tension" else -1.0
        limit = max_tension_strain if sign > 0.0 else max_compression_strain
        strains = np.concatenate([[0.0], np.geomspace(1e-6 * limit, limit, samples)])
        stable = _is_stable(model, mode, 1.0 + sign * strains)
        if np.all(stable):
            ranges.append(StableRange(mode_name, None, limit))
            continue
        first = int(np.argmin(stable))
        if first == 0:
            ranges.append(StableRange(mode_name, 0.0, limit))
            continue
        low, high = strains[first - 1], strains[first]
        while high - low > 1e-9 * high:
            middle = 0.5 * (low + high)
            if _is_stable(model, mode, np.array([1.0 + sign * middle]))[0]:
                low = middle
            else:
                high = middle
        ranges.append(StableRange(mode_name, float(high), limit))
    return StabilityReport(tuple(ranges))
