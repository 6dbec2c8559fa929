"""Sizes of the indentation meshes' cells: graded spacings and the O-grid's rings.

Shared by the generators (:mod:`warptissue.mesh.generators`, which build the meshes) and the
size estimate (:mod:`warptissue.mesh.size`, which counts their cells before they are built),
so that the two agree without importing each other.
"""

from __future__ import annotations

import numpy as np

from warptissue.errors import InputError

INNER_SQUARE_FRACTION = 0.5
"""Half-width of the O-grid's central square over the probe radius."""


RADIAL_ASPECT = 1.25
"""Largest radial over tangential size of the O-grid's outer rings (on the x axis)."""


def require_positive(**values: float) -> None:
    """Raise InputError naming the first value that is not positive and finite.

    Args:
        **values: Name -> value (any unit).
    """
    for name, value in values.items():
        if not (np.isfinite(value) and value > 0):
            raise InputError(f"{name} must be a positive finite number", key=name, value=value)


def graded_spacing(
    length_m: float, first_m: float, largest_m: float, *, growth: float = 1.2
) -> np.ndarray:
    """Coordinates from 0 to ``length_m`` whose intervals grow geometrically up to a cap.

    The first interval is about ``first_m``; each next one is ``growth`` times the previous
    until it reaches ``largest_m``, after which intervals stay at ``largest_m``. The interval
    count is the one whose sizes, scaled uniformly to fit ``length_m`` exactly, are closest to
    the requested ones.

    Args:
        length_m: Total length, metres.
        first_m: Target size of the first interval, metres.
        largest_m: Largest interval size, metres (>= ``first_m``).
        growth: Ratio of neighbouring intervals (>= 1).

    Returns:
        Increasing coordinates, shape (count + 1,), float64, from 0 to ``length_m``.
    """
    require_positive(length_m=length_m, first_m=first_m, largest_m=largest_m)
    if largest_m < first_m:
        raise InputError(
            f"largest_m ({largest_m} m) must not be smaller than first_m ({first_m} m)",
            key="largest_m",
            value=largest_m,
        )
    if not growth >= 1.0:
        raise InputError("growth must be >= 1", key="growth", value=growth)
    ramp_count = 1 if growth == 1.0 else int(np.ceil(np.log(largest_m / first_m) / np.log(growth)))
    # Every ramp interval is >= first_m, so no more than this many can be used (a growth just
    # above 1 would otherwise ask for an astronomically long ramp).
    ramp_count = min(ramp_count, int(np.ceil(length_m / first_m)) + 1)
    ramp = np.minimum(first_m * growth ** np.arange(max(ramp_count, 1)), largest_m)
    ramp_total = np.cumsum(ramp)
    if ramp_total[-1] >= length_m:
        sizes = ramp[: int(np.searchsorted(ramp_total, length_m)) + 1]
    else:
        extra = int(np.ceil((length_m - ramp_total[-1]) / largest_m))
        sizes = np.concatenate([ramp, np.full(extra, largest_m)])
    return fit_sizes(sizes, length_m)


def fit_sizes(sizes: np.ndarray, length_m: float) -> np.ndarray:
    """Coordinates of intervals ``sizes`` (whose sum reaches ``length_m`` only with the last
    one), dropping the last interval when that fits better, scaled to end at ``length_m``."""
    if len(sizes) > 1 and abs(sizes[:-1].sum() - length_m) < abs(sizes.sum() - length_m):
        sizes = sizes[:-1]
    coordinates = np.concatenate([[0.0], np.cumsum(sizes)])
    coordinates *= length_m / coordinates[-1]
    coordinates[-1] = length_m
    return coordinates


def radial_spacing(
    inner_m: float,
    outer_m: float,
    first_m: float,
    largest_m: float,
    *,
    growth: float,
    angle_step: float,
) -> np.ndarray:
    """Radial offsets from ``inner_m`` to ``outer_m`` for rings with a fixed angular step.

    Like :func:`graded_spacing`, but the radial size at radius r also stays below
    ``RADIAL_ASPECT * r * angle_step`` (when that exceeds ``first_m``), so cells far out stay
    close to square instead of long and thin.
    """
    sizes = []
    radius, size = inner_m, first_m
    while radius < outer_m:
        sizes.append(size)
        radius += size
        cap = max(first_m, RADIAL_ASPECT * radius * angle_step)
        size = max(size, min(size * growth, largest_m, cap))
    return fit_sizes(np.array(sizes), outer_m - inner_m)


def ogrid_division(probe_radius_m: float, size_near_m: float) -> int:
    """Cells along each side of the O-grid's central square (a quarter of the probe ring has
    twice as many)."""
    return max(2, int(np.ceil(0.25 * np.pi * probe_radius_m / size_near_m)))


def ogrid_rings(
    half_extent_m: float,
    probe_radius_m: float,
    size_near_m: float,
    size_far_m: float,
    *,
    growth: float,
) -> tuple[int, np.ndarray]:
    """The O-grid's rings outside its central square.

    Returns:
        ``(inner_count, outer_fraction)``: the number of uniform rings from the square to the
        probe ring, and the increasing positions in (0, 1] of the rings from the probe ring to
        the outer boundary (1 is the boundary).
    """
    a = probe_radius_m
    n = ogrid_division(probe_radius_m, size_near_m)
    inner_count = max(1, int(round((1.0 - INNER_SQUARE_FRACTION) * a / (0.25 * np.pi * a / n))))
    outer_fraction = radial_spacing(
        a, half_extent_m, size_near_m, size_far_m, growth=growth, angle_step=0.25 * np.pi / n
    )
    return inner_count, outer_fraction[1:] / outer_fraction[-1]
