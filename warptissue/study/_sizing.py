"""The specimen's extent and the refined zone of its mesh under the probe."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from warptissue.indenter import Indenter

CONTACT_RADIUS_SAFETY = 1.5
"""A sphere's refined zone is this many times Hertz's contact radius sqrt(R d) at the study's
deepest depth d (at most the sphere's radius R): the finite-strain contact radius exceeds
Hertz's (+10-12 % at d/R = 0.04 on study meshes), and the zone's edge should not be where the
contact ends."""


def specimen_half_size_m(shape: str, width_m: float | None, radius_m: float | None) -> float:
    """The specimen's extent from the probe axis: half a block's width, or a disc's radius.

    Args:
        shape: ``"block"`` or ``"disc"``.
        width_m: The block's full edge length, m (block only).
        radius_m: The disc's radius, m (disc only).

    Returns:
        The half size, m.
    """
    return width_m / 2.0 if shape == "block" else radius_m


def deepest_depth_m(protocol: Any, records: Sequence[Any]) -> float:
    """The deepest depth a study asks for, m: its protocol's last depths and its
    ``[[data]]`` records' displacements (0 where it has neither).

    Args:
        protocol: The study's :class:`~warptissue.study.Protocol` (its ``depths_m``).
        records: Its :class:`~warptissue.study.DataRecord` (their ``displacement_m``).
    """
    depths = [max(protocol.depths_m, default=0.0)]
    depths += [float(np.max(record.displacement_m)) for record in records]
    return max(depths)


def mesh_probe_radius(indenter: Indenter, half_size_m: float, *, depth_m: float) -> float:
    """The radius of the specimen mesh's refined zone under the probe, m.

    The probe's radius; for a sphere, :data:`CONTACT_RADIUS_SAFETY` times Hertz's contact
    radius sqrt(R d) at the deepest depth (at most R; R itself where ``depth_m`` is 0), the
    zone the contact reaches; half the specimen's half-size for a plate without a radius or
    a wedge (whose contact widens with depth along its flanks).

    Args:
        indenter: The probe.
        half_size_m: The specimen's extent from the probe axis, m.
        depth_m: The deepest depth the study asks for, m (:func:`deepest_depth_m`).

    Returns:
        The radius, m.
    """
    if indenter.kind == "wedge" or indenter.radius_m <= 0:
        return 0.5 * half_size_m
    if indenter.kind == "sphere" and depth_m > 0.0:
        contact_m = math.sqrt(indenter.radius_m * depth_m)
        return min(indenter.radius_m, CONTACT_RADIUS_SAFETY * contact_m)
    return indenter.radius_m


def probe_outside_specimen(
    indenter: Indenter, shape: str, half_size_m: float, zone_m: float
) -> str | None:
    """Why the specimen is too small for the probe, or None where it fits.

    The probe's radius must be less than the specimen's half size (a plate's radius only
    sets the refined zone, so it is not compared), and so must the refined zone
    (:func:`mesh_probe_radius`, ``zone_m``).

    Args:
        indenter: The probe.
        shape: ``"block"`` (its half width is compared) or ``"disc"`` (its radius).
        half_size_m: The specimen's extent from the probe axis, m.
        zone_m: The refined zone's radius, m.
    """
    half = "half the width" if shape == "block" else "the radius"
    if indenter.kind != "plate" and indenter.radius_m >= half_size_m:
        return (
            f"the specimen's {half} ({half_size_m!r} m) must exceed the {indenter.kind}'s "
            f"indenter.radius_m ({indenter.radius_m!r} m)"
        )
    if half_size_m <= zone_m:
        return f"the specimen's {half} must extend beyond the probe radius {zone_m!r} m"
    return None


def near_size_too_coarse(indenter: Indenter, zone_m: float, *, depth_m: float) -> str:
    """The message for a ``size_near_m`` above the refined zone ``zone_m`` of
    :func:`mesh_probe_radius` (m), naming the zone and the values it came from: "the probe
    radius (0.001 m)" or, for a sphere whose zone is its contact's, "the sphere's refined
    zone 1.5 sqrt(R d) = 0.000335 m (R = indenter.radius_m = 0.001 m, d = the deepest depth
    = 5e-05 m)"; ``depth_m``: the deepest depth, m."""
    zone = f"the probe radius ({zone_m!r} m)"
    if indenter.kind == "sphere" and depth_m > 0.0 and zone_m < indenter.radius_m:
        zone = (
            f"the sphere's refined zone {CONTACT_RADIUS_SAFETY:g} sqrt(R d) = {zone_m:.6g} m "
            f"(R = indenter.radius_m = {indenter.radius_m!r} m, d = the deepest depth = "
            f"{depth_m!r} m)"
        )
    return f"must not exceed {zone}, or the probe is not resolved"
